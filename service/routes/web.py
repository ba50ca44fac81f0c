"""The web page: ``GET /ui/`` (and ``GET /`` redirects there).

Plain HTML + ES modules from ``service/web/static``, no build step, no CDN. three.js comes
from npm (``service/web/node_modules/three``, installed by ``npm ci`` in ``service/web``) and
only the files the page imports are served, under ``/ui/vendor/three/``. Without
node_modules the page still works and says the 3D preview is unavailable.

These files are public (they hold no data): the page asks for an API key and sends it with
every API call. None of these routes appear in the OpenAPI document.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse, RedirectResponse

from service.problems import Problem

WEB_DIR = Path(__file__).resolve().parent.parent / "web"
STATIC_DIR = WEB_DIR / "static"
THREE_DIR = WEB_DIR / "node_modules" / "three"

#: what the page imports from the three package: the core build and the example modules
#: (GLTFLoader, OrbitControls and the utils they import)
THREE_FILES = ("build/three.module.js", "build/three.core.js")
THREE_JSM = "examples/jsm/"

MEDIA_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".svg": "image/svg+xml",
    ".png": "image/png",
}

VENDOR_CACHE = "public, max-age=3600"

router = APIRouter(include_in_schema=False)


def _file(root: Path, rel: str, cache: str) -> FileResponse:
    """``root/rel`` if it is a regular file inside ``root`` with a known type, else 404."""
    if len(rel) > 300 or any(ord(c) < 32 or ord(c) == 127 for c in rel):  # e.g. /ui/%00.js
        raise Problem(404, "no such file")
    path = (root / rel).resolve()
    media_type = MEDIA_TYPES.get(path.suffix)
    if media_type is None or not path.is_relative_to(root.resolve()) or not path.is_file():
        raise Problem(404, f"no such file: {rel}")
    return FileResponse(path, media_type=media_type, headers={"Cache-Control": cache})


@router.get("/")
def root() -> RedirectResponse:
    return RedirectResponse("/ui/", status_code=307)


@router.get("/ui")
def ui_no_slash() -> RedirectResponse:
    return RedirectResponse("/ui/", status_code=307)


@router.get("/ui/")
def index() -> FileResponse:
    return _file(STATIC_DIR, "index.html", "no-cache")


@router.get("/ui/vendor/three/{rel:path}")
def three(rel: str) -> FileResponse:
    if rel not in THREE_FILES and not (rel.startswith(THREE_JSM) and rel.endswith(".js")):
        raise Problem(404, f"no such file: three/{rel}")
    if not THREE_DIR.is_dir():
        raise Problem(404, "three.js is not installed: run `npm ci` in service/web")
    if rel in THREE_FILES:
        return _file(THREE_DIR, rel, VENDOR_CACHE)
    return _file(THREE_DIR / THREE_JSM, rel.removeprefix(THREE_JSM), VENDOR_CACHE)


@router.get("/ui/{rel:path}")
def static(rel: str) -> FileResponse:
    return _file(STATIC_DIR, rel, "no-cache")
