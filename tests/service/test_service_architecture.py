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
    # Celery keeps its own "default" apps
    "celery_apps": sum(isinstance(o, Celery) and o.main != "default" for o in objs),
    "fastapi_apps": sum(isinstance(o, FastAPI) for o in objs),
}))
"""


def test_importing_service_and_worker_creates_nothing():
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert "service.app" in r["modules"] and "worker.app" in r["modules"] and "service.jobs" in r["modules"]
    assert (r["settings_cached"], r["engines"], r["celery_apps"], r["fastapi_apps"]) == (0, 0, 0, 0), r


# --- the package graph -----------------------------------------------------------------------
PACKAGES = ("solver", "mjcf", "service", "worker")
#: who may import whom (every import, also those inside functions): worker -> service -> solver/mjcf
ALLOWED = {"solver": set(), "mjcf": {"solver"}, "service": {"solver", "mjcf"}, "worker": {"service", "solver", "mjcf"}}


def _is_module(name: str) -> bool:
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _module_graph(depth: int) -> dict[str, set[str]]:
    """Edges between our modules, cut to their first ``depth`` name parts, from every import
    statement of every file (top-level or not, relative ones resolved)."""
    edges: dict[str, set[str]] = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if "migrations" in path.parts:
                continue
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            if is_pkg:
                parts = parts[:-1]
            for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
                if isinstance(node, ast.Import):
                    targets = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom):
                    if node.level:
                        base = parts[: len(parts) - node.level + (1 if is_pkg else 0)]
                        module = ".".join(base + ([node.module] if node.module else []))
                    else:
                        module = node.module or ""
                    # `from solver import spatial` imports the module solver.spatial, not the package's __init__
                    targets = [f"{module}.{a.name}" if _is_module(f"{module}.{a.name}") else module for a in node.names]
                else:
                    continue
                src = ".".join(parts[:depth])
                for t in targets:
                    if t.split(".")[0] in PACKAGES:
                        dst = ".".join(t.split(".")[:depth])
                        if dst != src:
                            edges.setdefault(src, set()).add(dst)
    return edges


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_package_graph_has_no_upward_import_and_no_cycle():
    edges = _module_graph(1)
    assert edges.get("service", set()) >= {"solver", "mjcf"}  # the parser sees the real imports
    upward = {src: sorted(dst - ALLOWED[src]) for src, dst in edges.items() if dst - ALLOWED[src]}
    assert not upward, f"imports against the layering worker -> service -> solver/mjcf: {upward}"
    assert not _cycles(edges)


def test_no_cycle_between_solver_and_mjcf_subpackages():
    """solver.io, solver.export, solver.contact, solver.spacetime, … and mjcf's modules form a DAG."""
    edges = {k: v for k, v in _module_graph(2).items() if k.split(".")[0] in ("solver", "mjcf")}
    assert "solver.character" in edges.get("solver.pipeline", set())  # the parser sees the real imports
    assert not _cycles(edges), _cycles(edges)


# --- the module graph --------------------------------------------------------------------------


def _our_modules() -> dict[str, Path]:
    """Every module of the four packages by its dotted name (a package by its ``__init__``)."""
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if "migrations" in path.parts:
                continue
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _import_edges(name: str, source: str, modules: set[str]) -> set[str]:
    """The modules of ours that module ``name`` imports, from every import statement (those inside
    functions too): ``from pkg import sub`` is an edge to the module ``pkg.sub`` when there is one,
    to the package ``pkg`` otherwise; relative imports resolved."""
    parts = name.split(".")
    is_pkg = name in modules and any(m.startswith(name + ".") for m in modules)
    out = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = parts[: len(parts) - node.level + (1 if is_pkg else 0)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in modules:  # an attribute of a module: the module
                t = t.rpartition(".")[0]
            if t and t != name:
                out.add(t)
    return out


def _modules_graph() -> dict[str, set[str]]:
    modules = _our_modules()
    return {name: _import_edges(name, path.read_text(), set(modules)) for name, path in modules.items()}


def test_the_module_graph_sees_every_import():
    """The parser sees imports inside functions and submodules imported from their package, and
    ``_cycles`` finds a circle hidden behind a function-level import."""
    edges = _modules_graph()
    assert "service.simulation" in edges["service.jobs"]  # ``from service.simulation import`` inside a function
    assert "service.store" in edges["service.simulation"]  # ``from service import store``
    src = "def f():\n    from service import simulation\n"
    mods = {"service", "service.store", "service.simulation"}
    fake = {**edges, "service.store": _import_edges("service.store", src, mods)}
    assert ["service.simulation", "service.store"] in _cycles(fake)


def test_no_import_cycle_between_modules():
    """No module of ours imports, even inside a function, a module that imports it back (directly
    or through others): a piece two modules share lives in a module of its own."""
    cycles = _cycles(_modules_graph())
    assert not cycles, f"import circles between modules: {cycles}"


#: the longest a module in solver/, mjcf/ or service/ may be (database migrations aside): a module
#: longer than this does more than one job
MODULE_LINES = 650


def test_no_module_does_more_than_one_job_by_its_length():
    long = {str(p.relative_to(ROOT)): n for pkg in ("solver", "mjcf", "service") for p in (ROOT / pkg).rglob("*.py")
            if "migrations" not in p.parts and (n := len(p.read_text().splitlines())) > MODULE_LINES}
    assert not long, f"modules over {MODULE_LINES} lines: {long}"
