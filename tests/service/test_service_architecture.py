"""Layering rules that a test can check: solver/ and mjcf/ never import web, queue, DB or
settings code; importing service/ and worker/ creates nothing (no settings, engine, app)."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FORBIDDEN = {"fastapi", "starlette", "celery", "kombu", "redis", "sqlalchemy", "alembic", "psycopg", "psycopg2",
             "pydantic_settings", "uvicorn", "httpx", "service", "worker", "multipart"}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


def test_pure_computation_packages_import_no_service_code():
    bad = {}
    for pkg in ("solver", "mjcf"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            hits = _imports(path) & FORBIDDEN
            if hits:
                bad[str(path.relative_to(ROOT))] = sorted(hits)
    assert not bad, f"solver/mjcf must stay pure computation: {bad}"


PROBE = r"""
import gc, importlib, json, pkgutil
import service, worker
names = []
for pkg in (service, worker):
    for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + "."):
        if ".migrations" in m.name:  # Alembic's env.py runs only under Alembic
            continue
        importlib.import_module(m.name)
        names.append(m.name)
from service.config import get_settings
from service.db import _ENGINES
from celery import Celery
from fastapi import FastAPI
from sqlalchemy.engine import Engine
objs = gc.get_objects()
print(json.dumps({
    "modules": names,
    "settings_cached": get_settings.cache_info().currsize,
    "engines": len(_ENGINES) + sum(isinstance(o, Engine) for o in objs),
    "celery_apps": sum(isinstance(o, Celery) and o.main != "default" for o in objs),  # Celery keeps its own "default" apps
    "fastapi_apps": sum(isinstance(o, FastAPI) for o in objs),
}))
"""


def test_importing_service_and_worker_creates_nothing():
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert "service.app" in r["modules"] and "worker.app" in r["modules"] and "service.jobs" in r["modules"]
    assert (r["settings_cached"], r["engines"], r["celery_apps"], r["fastapi_apps"]) == (0, 0, 0, 0), r
