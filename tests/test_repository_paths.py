"""The repository needs nothing beside it: no file refers to a folder next to the checkout
(the team's folder of trials) or to a path of the machine it was written on (a home
directory, the workspace). The trials the tests, the demo and the benchmarks use are in ``data/`` with
their origin and license notices."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKIP_DIRS = {".git", ".venv", "node_modules", "out", ".pytest_cache", ".hypothesis", "__pycache__", "build", "dist"}
# built from parts, so that this file does not match itself
PATTERNS = {
    "a folder beside the checkout": re.compile(r"\.\./" + "shared" + r"\b"),
    "a workspace path": re.compile(r"(?<![\w.])/" + "work" + r"/"),
    "root's home": re.compile(r"(?<![\w.])/" + "root" + r"/"),
    "a home directory": re.compile(r"(?<![\w.])/" + "home" + r"/[A-Za-z_][\w.-]*"),
    "a macOS home directory": re.compile(r"(?<![\w.])/" + "Users" + r"/[A-Za-z_][\w.-]*/"),
}


def repository_files() -> list[Path]:
    """The tracked files (git), or every file outside build and environment folders."""
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60).stdout
        files = [ROOT / p for p in out.decode().split("\0") if p]
        if files:
            return [p for p in files if p.is_file()]
    except (OSError, subprocess.SubprocessError):
        pass
    found = []
    for d, dirs, names in os.walk(ROOT):
        dirs[:] = [x for x in dirs if x not in SKIP_DIRS]
        found += [Path(d) / n for n in names]
    return found


def test_no_file_refers_to_the_machine_or_to_folders_beside_the_repository():
    files = repository_files()
    assert len(files) > 100 and any(p.parts[-2:] == ("data", "README.md") for p in files)
    hits = []
    for p in files:
        data = p.read_bytes()
        if b"\0" in data[:8192]:  # binary (C3D, PNG, ...)
            continue
        text = data.decode("utf-8", errors="replace")
        for what, rx in PATTERNS.items():
            for m in rx.finditer(text):
                line = text.count("\n", 0, m.start()) + 1
                hits.append(f"{p.relative_to(ROOT)}:{line}: {what}: {m.group(0)!r}")
    assert not hits, "\n".join(hits)


@pytest.mark.parametrize("text, bad", [  # paths written in parts, not to match this file
    ("see ../" + "shared/docs/SPEC.md", True),
    ("data = '/" + "work/shared/data'", True),
    ("cd /" + "root/motionx", True),
    ("ENV X=/" + "home/motionx/data", True),
    ("a ../sharedlib folder", False),
    ("https://example.org/home/page", False),  # a URL's path is not a machine path
    ("~/.local/share/motionx and /var/lib/motionx", False),
])
def test_the_patterns_find_machine_paths(text, bad):
    assert any(rx.search(text) for rx in PATTERNS.values()) == bad
