"""docs/api.md's script against the command line doing the same work.

The script (load a trial, tutor, extrapolate to a 10° slope, validate, export, save) runs as
``python script.py``; the same work from the command line is ``motionx tutor`` then ``motionx
extrapolate --slope 10`` (which also writes the final motion's plots). Each is a fresh process
with the default settings (native code on), run alternately ``REPEATS`` times after one warm-up
of each (the compiled derivatives' cache filled); the figure is the median wall time.
"""

from __future__ import annotations

import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REPEATS = 3
TRIAL = ["data/deepmimic_humanoid3d_walk/humanoid3d_walk.txt",
         "data/deepmimic_humanoid3d_walk/humanoid3d_character.txt"]


def _script() -> str:
    return re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "api.md").read_text(), flags=re.S)[0]


def _timed(cmds: list[list[str]], cwd: Path) -> float:
    t = time.perf_counter()
    for c in cmds:
        r = subprocess.run(c, cwd=cwd, capture_output=True, text=True, timeout=1800)
        if r.returncode != 0:
            raise RuntimeError(f"{' '.join(c)} exited {r.returncode}: {r.stderr[-2000:]}")
    return time.perf_counter() - t


def run() -> dict:
    motionx = str(Path(sys.executable).with_name("motionx"))
    api, cli = [], []
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "data").symlink_to(ROOT / "data", target_is_directory=True)
        (d / "api_script.py").write_text(_script())
        for i in range(REPEATS + 1):
            t_api = _timed([[sys.executable, "api_script.py"]], d)
            out = d / f"cli{i}"
            t_cli = _timed([[motionx, "tutor", *TRIAL, "--out", str(out / "tutor.motion.json")],
                            [motionx, "extrapolate", str(out / "tutor.motion.json"), "--slope", "10", "--out",
                             str(out / "slope10"), "--quiet"]], d)
            if i:  # the first pair warms the caches
                api.append(t_api)
                cli.append(t_cli)
    a, c = statistics.median(api), statistics.median(cli)
    return {"script_s": round(a, 2), "cli_s": round(c, 2), "ratio": round(a / c, 3),
            "script_runs_s": [round(x, 2) for x in api], "cli_runs_s": [round(x, 2) for x in cli]}
