import json
import shutil
import subprocess
import sys
from pathlib import Path

import mujoco
import pytest

from solver import character as C


def motionx(*args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("name", ["halfboy", "fullbody", "capture-lower", "capture-full"])
def test_mjcf_command_writes_a_loadable_model(tmp_path, name):
    out = tmp_path / f"{name}.xml"
    r = motionx("mjcf", "--character", name, "--out", str(out))
    assert r.returncode == 0, r.stderr
    model = mujoco.MjModel.from_xml_path(str(out))
    ch = C.reference(name)
    assert model.nq == ch.n
    assert mujoco.mj_getTotalmass(model) == pytest.approx(ch.total_mass, rel=1e-9)
    names = [model.joint(i).name for i in range(model.njnt)]
    assert set(names) == set(ch.coordinate_names)


def test_check_dynamics_command_reports_json():
    r = motionx("check-dynamics", "--character", "halfboy", "--samples", "10")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert res["max_rel_err_joint"] <= 1e-9 and res["max_rel_err_root"] <= 1e-9


def test_unknown_character_is_refused():
    r = motionx("mjcf", "--character", "robot", "--out", "x.xml")
    assert r.returncode != 0
    assert "robot" in r.stderr
