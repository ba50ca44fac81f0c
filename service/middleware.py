"""ASGI middleware: request body size limit (FastAPI has none by default)."""

from __future__ import annotations

import base64
import hashlib
import json
import re

from starlette.exceptions import HTTPException

from service.limits import clip
from service.problems import MAX_ECHO, MEDIA_TYPE


class BodyTooLarge(HTTPException):
    """Raised from ``receive``: rendered as 413 problem+json by the app's HTTP error handler."""


class BodyLimitMiddleware:
    """Refuse bodies above ``max_bytes`` with 413 problem+json — by Content-Length up
    front, or while streaming (chunked uploads) as soon as the limit is crossed."""

    def __init__(self, app, max_bytes: int) -> None:
        self.app, self.max_bytes = app, max_bytes

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        for name, value in scope.get("headers", ()):
            if name == b"content-length":
                try:
                    n = int(value)
                except ValueError:
                    return await self._reply(send, scope, 400, "invalid Content-Length")
                if n > self.max_bytes:
                    return await self._reply(send, scope, 413, self._detail())
        received = 0
        started = False

        async def limited_receive():
            nonlocal received
            msg = await receive()
            if msg["type"] == "http.request":
                received += len(msg.get("body", b""))
                if received > self.max_bytes:
                    raise BodyTooLarge(413, self._detail())
            return msg

        async def tracking_send(msg):
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except BodyTooLarge:
            if not started:
                await self._reply(send, scope, 413, self._detail())

    def _detail(self) -> str:
        return f"request body larger than the limit of {self.max_bytes} bytes"

    async def _reply(self, send, scope, status: int, detail: str) -> None:
        title = "Content Too Large" if status == 413 else "Bad Request"
        body = json.dumps({"type": "about:blank", "title": title, "status": status, "detail": detail,
                           "instance": clip(scope.get("path", ""), MAX_ECHO)}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", MEDIA_TYPE.encode()), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})


def _inline_script_hashes(html: str) -> list[str]:
    """CSP source expressions ('sha256-…') of the inline scripts of a page (its import map)."""
    out = []
    for m in re.finditer(r"<script(?![^>]*\bsrc=)[^>]*>(.*?)</script>", html, re.S):
        digest = hashlib.sha256(m.group(1).encode("utf-8")).digest()
        out.append("'sha256-" + base64.b64encode(digest).decode() + "'")
    return out


def page_csp(index_html: str | None) -> str:
    """The pages' policy: everything from the API's own origin; inline scripts only by hash
    (the import map of /ui/); images also from data: and blob: URLs (plots fetched as blobs)."""
    hashes = " ".join(_inline_script_hashes(index_html or ""))
    return ("default-src 'self'; "
            f"script-src 'self'{' ' + hashes if hashes else ''}; "
            "style-src 'self'; img-src 'self' data: blob:; connect-src 'self'; font-src 'self'; "
            "object-src 'none'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'")


#: API responses (JSON, problem details, files): nothing to run, render or frame
API_CSP = "default-src 'none'; frame-ancestors 'none'"


class SecurityHeadersMiddleware:
    """``X-Content-Type-Options: nosniff``, ``X-Frame-Options: DENY``, ``Referrer-Policy`` and a
    ``Content-Security-Policy`` on every response: the pages' policy under ``/ui/`` and on
    ``/docs``, and a deny-all policy on the API's own responses."""

    PAGE_PREFIXES = ("/ui", "/docs")

    def __init__(self, app, page_policy: str) -> None:
        self.app, self.page_policy = app, page_policy.encode()

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        path = scope.get("path", "")
        csp = self.page_policy if path == "/" or path.startswith(self.PAGE_PREFIXES) else API_CSP.encode()

        async def with_headers(msg):
            if msg["type"] == "http.response.start":
                headers = list(msg.get("headers", []))
                present = {k.lower() for k, _ in headers}
                for k, v in ((b"x-content-type-options", b"nosniff"), (b"x-frame-options", b"DENY"),
                             (b"referrer-policy", b"no-referrer"), (b"content-security-policy", csp)):
                    if k not in present:
                        headers.append((k, v))
                msg = {**msg, "headers": headers}
            await send(msg)

        await self.app(scope, receive, with_headers)
