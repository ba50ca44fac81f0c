"""ASGI middleware: request body size limit (FastAPI has none by default)."""

from __future__ import annotations

import json

from starlette.exceptions import HTTPException

from service.problems import MEDIA_TYPE


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
                           "instance": scope.get("path", "")}).encode()
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-type", MEDIA_TYPE.encode()), (b"content-length", str(len(body)).encode()),
                                (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})
