"""`make fuzz`: schemathesis' own command line against `motionx serve`, on SQLite and then on
PostgreSQL, every phase (examples, coverage, fuzzing, stateful: uploads followed through the
OpenAPI links to exports, reports, plots, jobs and cancels), every check, until at least
``--cases`` test cases per database. No 5xx is allowed: any failure of a check fails the run, and
so does any unhandled error in the API's log. Prints one JSON line per database and a summary.

    .venv/bin/python tests/service/fuzz.py [--cases 10000] [--db sqlite,postgresql] [--seed N]

The configuration (which schema-valid requests an operation may refuse with a documented 422)
is tests/service/schemathesis.toml, shared with the short run of `make test`
(tests/service/test_service_schemathesis.py).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import secrets
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from service.topology import (  # noqa: E402
    Proc,
    create_postgres_database,
    drop_postgres_database,
    free_port,
    motionx_cmd,
    wait_api,
)

CONFIG = Path(__file__).with_name("schemathesis.toml")
PG_ADMIN = os.environ.get("MOTIONX_TEST_PG_ADMIN", "postgresql://postgres@127.0.0.1:5432/postgres")
LOG_SIGNS = ("unhandled error on", "Exception in ASGI application", "compute process failed")


def run_schemathesis(base: str, key: str, *, max_examples: int, seed: int | None, report: Path) -> dict:
    st = Path(sys.executable).with_name("st")
    args = [str(st), "--config-file", str(CONFIG), "run", f"{base}/openapi.json", "-H", f"X-API-Key: {key}",
            "--checks", "all", "--max-examples", str(max_examples), "--workers", "1", "--request-timeout", "120",
            "--continue-on-failure", "--report", "junit", "--report-dir", str(report)]
    if seed is not None:
        args += ["--seed", str(seed)]
    t0 = time.monotonic()
    out = subprocess.run(args, capture_output=True, text=True, cwd=report)
    text = out.stdout + out.stderr
    m = re.search(r"Test cases:\s*\n\s*(\d+) generated(.*)", text)
    generated = int(m.group(1)) if m else 0
    return {"exit": out.returncode, "cases": generated, "summary": (m.group(0).strip() if m else ""),
            "seconds": round(time.monotonic() - t0, 1), "output": text}


def fuzz_database(kind: str, cases: int, seed: int | None, workdir: Path) -> dict:
    data = workdir / kind
    data.mkdir(parents=True, exist_ok=True)
    key = "fuzz-" + secrets.token_hex(8)
    env = dict(os.environ)
    env.update(MOTIONX_DATA_DIR=str(data), MOTIONX_API_KEYS=key, MOTIONX_RUNNER="local", PYTHONUNBUFFERED="1",
               MOTIONX_JOB_TIME_LIMIT_S="20", MOTIONX_LOCAL_WORKERS="1")
    env.pop("DATABASE_URL", None)
    dbname = None
    if kind == "postgresql":
        dbname = f"motionx_fuzz_{secrets.token_hex(4)}"
        env["DATABASE_URL"] = create_postgres_database(PG_ADMIN, dbname, exist_ok=False)
    port = free_port()
    api = Proc("api", motionx_cmd("serve", "--port", str(port)), env, data / "api.log").start()
    t0 = time.monotonic()
    try:
        base = f"http://127.0.0.1:{port}"
        wait_api(base, api, timeout=90)
        total, runs, ok = 0, [], True
        while total < cases:  # schemathesis counts what it generated; run again (new seed) until enough
            # about 16 cases per unit of --max-examples over the four phases (measured: 400 -> 6,763)
            max_examples = max(20, -(-(cases - total) // 16))
            r = run_schemathesis(base, key, max_examples=max_examples, seed=seed, report=data)
            runs.append({k: r[k] for k in ("exit", "cases", "summary", "seconds")})
            ok = ok and r["exit"] == 0
            if r["exit"] != 0:
                (data / "schemathesis.txt").write_text(r["output"])
            if r["cases"] == 0:
                ok = False
                (data / "schemathesis.txt").write_text(r["output"])
                break
            total += r["cases"]
            seed = None if seed is None else seed + 1
        log = api.log_text()
        bad = [s for s in LOG_SIGNS if s in log]
        return {"database": kind, "cases": total, "runs": runs, "ok": ok and not bad, "log_errors": bad,
                "seconds": round(time.monotonic() - t0, 1), "alive": api.alive(), "details": str(data)}
    finally:
        api.stop()
        if dbname:
            drop_postgres_database(PG_ADMIN, dbname)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", type=int, default=10_000, help="test cases per database (default 10000)")
    p.add_argument("--db", default="sqlite,postgresql", help="databases, comma-separated (default both)")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--keep", action="store_true", help="keep the working folder (logs, junit reports)")
    args = p.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="motionx-fuzz-"))
    results = []
    try:
        for kind in [k.strip() for k in args.db.split(",") if k.strip()]:
            res = fuzz_database(kind, args.cases, args.seed, work)
            results.append(res)
            print(json.dumps(res), flush=True)
    finally:
        if not args.keep and all(r["ok"] for r in results):
            import shutil

            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"details in {work}", file=sys.stderr)
    ok = bool(results) and all(r["ok"] for r in results)
    print(json.dumps({"ok": ok, "cases": {r["database"]: r["cases"] for r in results},
                      "seconds": {r["database"]: r["seconds"] for r in results}}))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
