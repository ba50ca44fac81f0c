"""What every `motionx` command promises (service/cli.py): --version, a description for every
command and a help line with its default for every option, choices as the user types them,
the main job first; every user mistake one line and exit status 2 (binary or non-JSON files,
a captured trial where a motion file is expected, a missing subject mass); no traceback when
the reader of the output goes away; `grf` takes its trial like `tutor`."""

from __future__ import annotations

import argparse
import io
import json
import shutil
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest

from service.cli import HelpFormatter, build_parser, main

MOTION_COMMANDS = {  # the commands that read a motion file, with arguments that are otherwise fine
    "validate": [],
    "extrapolate": ["--slope", "5", "--out", "{tmp}/ex"],
    "export": ["--format", "json", "--out", "{tmp}/clip.json"],
    "plot": ["--out", "{tmp}/plots"],
}


def motionx(*args, timeout: int = 300, **kw) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=timeout, **kw)


def run(*args) -> tuple[int, str, str]:
    """`motionx ARGS` in this process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:
            code = e.code
    return code, out.getvalue(), err.getvalue()


def commands(parser: argparse.ArgumentParser, prefix=()):
    """(name path, parser) of every command and subcommand."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*prefix, name), sub
                yield from commands(sub, (*prefix, name))


# --- the tool itself ---------------------------------------------------------------------


def test_version():
    r = motionx("--version")
    assert r.returncode == 0 and r.stdout.strip() == f"motionx {version('motionx')}"


def test_the_main_job_comes_first_in_the_command_list():
    r = motionx("--help")
    assert r.returncode == 0
    listed = [line.split()[0] for line in r.stdout.split("commands:")[1].splitlines()[2:] if line.startswith("    ")
              and not line.startswith("     ")]
    assert listed[:2] == ["tutor", "extrapolate"], listed
    assert {"validate", "demo", "grf", "serve", "export", "plot", "apikey", "simulate"} <= set(listed)


def test_every_command_is_described_and_every_option_has_help_with_its_default():
    parser = build_parser()
    found = list(commands(parser))
    assert len(found) >= 18
    for path, sub in found:
        name = " ".join(path)
        assert sub.description and len(sub.description) > 20, f"{name}: no description"
        fmt = HelpFormatter(prog=name)
        for a in sub._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            assert a.help, f"{name} {a.option_strings or a.dest}: no help"
            text = fmt._get_help_string(a) % {"default": a.default, "prog": name}
            if a.option_strings and a.default not in (None, False, ""):
                assert "default" in text, f"{name} {a.option_strings}: default {a.default!r} not stated: {text}"
        sub_help = sub.format_help()
        assert "{15.0" not in sub_help and "30.0}" not in sub_help, name
    # the options the first users missed, as a user reads them
    helps = {" ".join(p): " ".join(s.format_help().split()) for p, s in commands(parser)}
    assert "(default: 400)" in helps["extrapolate"]
    assert "(default: 100)" in helps["check-dynamics"] and "(default: 0)" in helps["check-dynamics"]
    assert "default: $MOTIONX_HOST or 127.0.0.1" in helps["serve"] and "8000" in helps["serve"]
    assert "--fps {15,30}" in helps["tutor"] and "default: 30 for fullbody, 15 for halfboy" in helps["tutor"]
    assert "default: fullbody" in helps["tutor"]
    # the motion files are v2, and in-place clips have their flag
    for name in ("tutor", "validate", "export", "plot"):
        assert "motion file v1" not in helps[name], name
    assert "motion file v2" in helps["tutor"] and "in-place clips" in helps["tutor"]


#: the commands that import a trial (from files, or by uploading them to the service)
IMPORTING = ("tutor", "grf", "demo")


def test_every_command_that_imports_a_trial_offers_every_importer_option():
    """Each reader option of the registry (solver.formats) is a flag of every importing command."""
    from service.cli import IMPORT_FLAGS
    from solver.formats import reader_options

    assert set(IMPORT_FLAGS) == set(reader_options())
    subs = {" ".join(p): s for p, s in commands(build_parser())}
    for name in IMPORTING:
        flags = {o for a in subs[name]._actions for o in a.option_strings}
        missing = [flag for flag, _ in IMPORT_FLAGS.values() if flag not in flags]
        assert not missing, f"motionx {name} lacks {missing}"


@pytest.mark.parametrize("args, words", [
    (["tutor", "x.bvh", "--out", "t.json", "--mass", "-3"], "--mass must be a positive finite mass in kg"),
    (["tutor", "x.bvh", "--out", "t.json", "--mass", "heavy"], "--mass must be a mass in kg, got 'heavy'"),
    (["tutor", "x.mot", "--out", "t.json", "--belt-speed", "fast"], "--belt-speed must be 'auto' or a speed"),
])
def test_importer_option_mistakes_are_one_line(args, words):
    r = motionx(*args)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("motionx: error:") and words in lines[0], \
        r.stderr


def test_usage_errors_are_one_line_and_status_2():
    for args in (["tutor"], ["extrapolate", "x.json"], ["frobnicate"], ["tutor", "x.c3d", "--out", "t.json",
                                                                        "--fps", "20"]):
        r = motionx(*args)
        assert r.returncode == 2, (args, r.stderr)
        assert "Traceback" not in r.stderr and "error:" in r.stderr.strip().splitlines()[-1]


def test_an_abbreviated_option_is_refused_not_guessed():
    """`--slop 5` is a typo, not `--slope 5`: argparse's prefix matching is off on every command."""
    code, _, err = run("extrapolate", "x.json", "--slop", "5", "--out", "x")
    assert code == 2 and "unrecognized arguments: --slop" in err
    code, _, err = run("tutor", "x.c3d", "--out", "t.json", "--char", "fullbody")
    assert code == 2 and "unrecognized arguments: --char" in err


# --- user mistakes: one clear line, status 2 ---------------------------------------------------


@pytest.fixture(scope="module")
def wrong_files(tmp_path_factory, shared_data) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("wrong")
    binary = d / "binary.json"
    binary.write_bytes(bytes(range(256)) * 8)
    (d / "text.json").write_text("frames: 1, 2, 3\n")
    return {"binary": binary, "text": d / "text.json",
            "deepmimic": shared_data / "deepmimic_humanoid3d_walk" / "humanoid3d_walk.txt",
            "c3d": shared_data / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"}


@pytest.mark.parametrize("command", sorted(MOTION_COMMANDS))
def test_a_file_that_is_not_a_motion_file_is_one_line_and_status_2(command, wrong_files, tmp_path):
    extra = [a.replace("{tmp}", str(tmp_path)) for a in MOTION_COMMANDS[command]]
    for kind, path in wrong_files.items():
        code, out, err = run(command, path, *extra)
        assert code == 2, (command, kind, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("motionx: error: "), (command, kind, err)
        assert str(path) in lines[0]
        if kind in ("binary", "text"):
            assert "is not a motion file" in lines[0] and ("binary" in lines[0] or "not JSON" in lines[0])
        else:  # a captured trial: the step that makes a motion file of it
            assert "captured trial" in lines[0] and "run `motionx tutor` first" in lines[0]
    assert not any(tmp_path.iterdir())  # nothing written


def test_binary_input_through_the_installed_command_has_no_traceback(wrong_files):
    r = motionx("validate", wrong_files["binary"])
    assert r.returncode == 2 and "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def bvh_without_mass(shared_data, tmp_path_factory) -> Path:
    from test_io_bvh import write_bvh

    d = shared_data / "deepmimic_humanoid3d_walk"
    p = tmp_path_factory.mktemp("bvh") / "walk.bvh"
    write_bvh(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt", p)  # a BVH states no mass
    return p


@pytest.mark.parametrize("command", ["tutor", "grf"])
def test_a_trial_without_mass_asks_for_the_mass_flag(command, bvh_without_mass, tmp_path):
    code, out, err = run(command, bvh_without_mass, "--out", tmp_path / "x")
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "subject mass unknown" in err and "pass --mass KG" in err and "mass=" not in err
    assert not (tmp_path / "x").exists()


def test_grf_takes_its_trial_like_tutor_and_keeps_the_older_flags(bvh_without_mass, tmp_path):
    a, b = tmp_path / "positional.csv", tmp_path / "flag.csv"
    code, out, err = run("grf", bvh_without_mass, "--mass", "45", "--out", a)
    assert code == 0, err
    assert json.loads(out)["mass_kg"] == 45.0
    code, _, err = run("grf", "--input", bvh_without_mass, "--mass", "45", "--out", b)
    assert code == 0, err
    assert a.read_text() == b.read_text()
    code, _, err = run("grf", bvh_without_mass, "--c3d", "x.c3d", "--out", b)
    assert code == 2 and "give the trial once" in err


# --- output read by a pipe that closes early ----------------------------------------------------


@pytest.mark.parametrize("args", [["mjcf", "--character", "fullbody", "--out", "-"],
                                  ["check-dynamics", "--character", "halfboy", "--samples", "2"]])
def test_a_closed_pipe_ends_quietly(args):
    """`motionx … | head`: the reader is gone before the output is written."""
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    p = subprocess.Popen([exe, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141, err  # as a process that SIGPIPE ends
    assert err == "", err


def test_grf_compare_plots_in_the_csvs_frame():
    """The CSV is in the input's ground frame: the plot names that frame's axes."""
    from service.commands.grf import input_axes
    from solver.capture import GroundFrame
    from solver.io.opensim import C_OSIM

    assert input_axes(GroundFrame(R=C_OSIM.T)) == (("x (forward)", "y (up)", "z (right)"), 1, "m")
    assert input_axes(GroundFrame(unit_m=0.001)) == (("x (forward)", "y (left)", "z (up)"), 2, "mm")
    turned = GroundFrame(R=np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]), unit_m=0.01)  # x to the right
    assert input_axes(turned) == (("x (right)", "y (forward)", "z (up)"), 2, "cm")


def test_serve_prints_a_new_api_key_alone_on_its_line(tmp_path):
    """First start without any key: the key is printed once, on a line of its own, and works."""
    import os
    import re

    import httpx

    from service.topology import Proc, free_port, motionx_cmd, wait_api

    port = free_port()
    env = {k: v for k, v in os.environ.items() if k not in ("MOTIONX_API_KEYS", "DATABASE_URL", "MOTIONX_DATABASE_URL")}
    env.update(MOTIONX_DATA_DIR=str(tmp_path), MOTIONX_LOCAL_WORKERS="1", PYTHONUNBUFFERED="1")
    api = Proc("api", motionx_cmd("serve", "--port", str(port)), env, tmp_path / "serve.log").start()
    try:
        base = f"http://127.0.0.1:{port}"
        wait_api(base, api, timeout=60)
        log = api.log_text()
        alone = [line.strip() for line in log.splitlines() if re.fullmatch(r"\s+mx_[\w-]+", line)]
        assert len(alone) == 1, log
        key = alone[0]
        assert f'curl -H "X-API-Key: {key}" {base}/jobs' in log and f"{base}/ui/#key={key}" in log
        assert httpx.get(f"{base}/jobs", headers={"X-API-Key": key}, timeout=10).status_code == 200
        assert httpx.get(f"{base}/jobs", headers={"X-API-Key": key[:-1]}, timeout=10).status_code == 401
    finally:
        api.stop()
