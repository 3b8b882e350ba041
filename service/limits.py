"""The request body limit: a body above ``NONHOLONOMIC_MAX_BODY_BYTES`` is refused with a 413
problem before it is read into memory (by its Content-Length, or while a chunked body arrives)."""

from __future__ import annotations

import json

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from schemas.problems import PROBLEM_MEDIA_TYPE

TOO_LARGE = "/problems/too-large"


class BodyLimit:
    """ASGI middleware: at most ``limit`` bytes of request body."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app, self.limit = app, limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        declared = dict(scope.get("headers") or []).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            await self._refuse(scope, send, int(declared))
            return
        received, started, refused = 0, False, False

        async def counted() -> Message:
            nonlocal received, refused
            if refused:
                return {"type": "http.disconnect"}
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.limit and not started:
                    # answer now; the app sees the client go away and whatever it sends is dropped
                    refused = True
                    await self._refuse(scope, send, received)
                    return {"type": "http.disconnect"}
            return message

        async def tracked(message: Message) -> None:
            nonlocal started
            if refused:
                return
            started = started or message["type"] == "http.response.start"
            await send(message)

        await self.app(scope, counted, tracked)

    async def _refuse(self, scope: Scope, send: Send, size: int) -> None:
        body = json.dumps({"type": TOO_LARGE, "title": "Request body too large", "status": 413,
                           "detail": f"the body has {'at least ' if size else ''}{size} bytes; this service accepts at "
                                     f"most {self.limit} (NONHOLONOMIC_MAX_BODY_BYTES)",
                           "instance": scope.get("path", ""),
                           "errors": [{"field": "body", "reason": f"larger than {self.limit} bytes"}]}).encode()
        await send({"type": "http.response.start", "status": 413,
                    "headers": [(b"content-type", PROBLEM_MEDIA_TYPE.encode()),
                                (b"content-length", str(len(body)).encode()), (b"connection", b"close")]})
        await send({"type": "http.response.body", "body": body})
