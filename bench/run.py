"""Run the benchmarks and write machine-readable results.

    python -m bench.run [--only SECTION ...] [--out bench/results.json]

Each section lives in its own module exposing ``run() -> dict``. Existing results of
sections not re-run are kept, so ``--only`` refreshes part of the file. Each section also
records ``machine_probe`` (``bench.machine``: a fixed IPOPT solve, independent of our code),
measured just before it: divide seconds by the probe's to compare runs across machines.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import time
from datetime import UTC, datetime
from pathlib import Path

SECTIONS = ["dynamics", "grf", "tutor", "continuation", "naturalness", "compiled", "blas", "service", "library",
            "front_door", "plots", "rig_export", "simulation", "fidelity", "moco"]


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--out", default="bench/results.json")
    p.add_argument("--only", nargs="*", default=None, choices=SECTIONS)
    args = p.parse_args()
    out = Path(args.out)
    results = json.loads(out.read_text()) if out.exists() else {}
    results.setdefault("sections", {})
    from bench.machine import probe
    from service.config import enable_native_code, get_settings

    # MUMPS on the optimized BLAS, as the service runs it (before any solve); the sections turn the
    # compiled derivatives on where they measure them
    enable_native_code(get_settings().model_copy(update={"compiled_derivatives": False}))

    for name in args.only or SECTIONS:
        speed = probe()
        t = time.perf_counter()
        mod = importlib.import_module(f"bench.{name}")
        data = mod.run()
        results["sections"][name] = {"results": data, "wall_s": round(time.perf_counter() - t, 2),
                                     "at": datetime.now(UTC).isoformat(timespec="seconds"), "machine_probe": speed}
        print(f"[bench] {name}: {json.dumps(data)[:400]}")
    results["machine"] = {"platform": platform.platform(), "python": platform.python_version(),
                          "cpus": os.cpu_count()}
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    print(f"[bench] wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
