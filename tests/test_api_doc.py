"""docs/api.md's script runs as written, and the front door is what `import solver` lists."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "api.md"


def _script() -> str:
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)
    assert blocks, "docs/api.md has no python block"
    return blocks[0]


def test_import_solver_lists_the_front_door():
    r = subprocess.run([sys.executable, "-c", "import solver, sys; print(solver.__all__); "
                        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('casadi', 'mujoco', 'mjcf')))"],
                       capture_output=True, text=True, timeout=120, check=True)
    names, heavy = r.stdout.splitlines()
    for name in ("load_trial", "make_tutor", "extrapolate", "solve_library", "validate", "export_motion", "Status",
                 "Motion", "Target", "StepControl", "Weights"):
        assert repr(name) in names
    assert heavy == "[]"  # names load on first use: `import solver` alone loads no CasADi or MuJoCo


def test_the_front_door_is_typed_for_type_checkers(tmp_path):
    """mypy sees the front door's real signatures (the TYPE_CHECKING imports), not ``Any``."""
    mypy = pytest.importorskip("mypy.api")
    (tmp_path / "use.py").write_text("import solver\nreveal_type(solver.make_tutor)\nreveal_type(solver.Target)\n")
    out, _err, _rc = mypy.run([str(tmp_path / "use.py"), "--no-incremental", "--follow-imports=silent"])
    assert "-> solver.pipeline.TutorResult" in out and "solver.axes.base.Target" in out, out


def test_front_door_names_resolve_and_unknown_names_are_refused():
    import solver

    assert sorted(solver.__all__) == sorted(solver._FRONT_DOOR)  # the static list type checkers read
    for name in solver.__all__:
        assert getattr(solver, name) is not None
    with pytest.raises(AttributeError, match="no attribute 'tutr'"):
        solver.tutr  # noqa: B018
    assert solver.Status("impasse").ok and solver.Status.CANCELED.terminal and not solver.Status.RUNNING.terminal


@pytest.mark.slow
def test_the_documented_script_runs(tmp_path):
    script = _script()
    (tmp_path / "data").symlink_to(ROOT / "data", target_is_directory=True)
    (tmp_path / "api_script.py").write_text(script)
    r = subprocess.run([sys.executable, "api_script.py"], cwd=tmp_path, capture_output=True, text=True, timeout=1200)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "tutor: succeeded" in r.stdout
    assert "walk: succeeded reached λ = 1.0" in r.stdout
    assert "plausible: True natural: True" in r.stdout, r.stdout  # verdicts; warnings may be listed

    out = tmp_path / "out" / "api"
    from solver import Motion

    tutor = Motion.load(out / "tutor.motion.json")
    assert tutor.provenance["step"] == "tutor" and tutor.report["plausible"]
    summary = json.loads((out / "slope10" / "summary.json").read_text())
    assert summary["status"] == "succeeded" and summary["lambda_reached"] == 1.0
    assert summary["target"]["slope_deg"] == 10
    files = sorted(p.name for p in (out / "slope10").glob("step_*.motion.json"))
    assert files == summary["motions"] and files[-1] == f"step_{len(files) - 1:03d}_lambda_1.0000.motion.json"
    last = Motion.load(out / "slope10" / files[-1])
    assert last.provenance["lambda"] == 1.0
    rows = (out / "slope10" / "progress.csv").read_text().splitlines()
    header = rows[0].split(",")
    assert header[:3] == ["phase", "wall_time_s", "lambda"]
    accepted = [r for r in rows[1:] if r.split(",")[header.index("accepted")] == "1"]
    assert len(accepted) == summary["accepted"] == len(files)
    assert (out / "slope10.glb").read_bytes()[:4] == b"glTF"
