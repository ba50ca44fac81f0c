"""``GET /docs``: Swagger UI from local files (swagger-ui-dist from npm, like three.js), no CDN.

Only ``swagger-ui-bundle.js``, ``swagger-ui.css`` and the icon are served, under
``/docs/static/``; the page starts Swagger UI from ``/ui/docs-init.js`` (no inline script, so
its Content-Security-Policy needs none). Without ``service/web/node_modules`` the page says how
to install it and links the OpenAPI document. Not part of the OpenAPI document itself.
"""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import FileResponse, HTMLResponse

from service.problems import Problem
from service.routes.web import VENDOR_CACHE, WEB_DIR

SWAGGER_DIR = WEB_DIR / "node_modules" / "swagger-ui-dist"
SWAGGER_FILES = {
    "swagger-ui-bundle.js": "text/javascript; charset=utf-8",
    "swagger-ui.css": "text/css; charset=utf-8",
    "favicon-32x32.png": "image/png",
}

PAGE = """<!doctype html>
<html lang="en">
<head>
  <meta charset="utf-8">
  <meta name="viewport" content="width=device-width, initial-scale=1">
  <title>motionx API</title>
  <link rel="icon" type="image/png" href="/docs/static/favicon-32x32.png">
  <link rel="stylesheet" href="/docs/static/swagger-ui.css">
</head>
<body>
  <div id="swagger-ui"></div>
  <script src="/docs/static/swagger-ui-bundle.js"></script>
  <script src="/ui/docs-init.js"></script>
</body>
</html>
"""

MISSING = """<!doctype html>
<html lang="en">
<head><meta charset="utf-8"><title>motionx API</title><link rel="icon" href="data:,"></head>
<body>
  <h1>motionx API</h1>
  <p>Swagger UI is not installed: run <code>npm ci</code> in <code>service/web</code> (<code>make</code> does).</p>
  <p>The OpenAPI document: <a href="/openapi.json">/openapi.json</a>.</p>
</body>
</html>
"""

router = APIRouter(include_in_schema=False)


@router.get("/docs")
def docs() -> HTMLResponse:
    page = PAGE if (SWAGGER_DIR / "swagger-ui-bundle.js").is_file() else MISSING
    return HTMLResponse(page, headers={"Cache-Control": "no-cache"})


@router.get("/docs/static/{name}")
def docs_static(name: str) -> FileResponse:
    media_type = SWAGGER_FILES.get(name)
    path = SWAGGER_DIR / name
    if media_type is None or not path.is_file():
        raise Problem(404, "no such file")
    return FileResponse(path, media_type=media_type, headers={"Cache-Control": VENDOR_CACHE})
