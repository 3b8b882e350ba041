"""``X-Request-ID``: every answer carries the request's id, the client's own or one made here.

The id is this request's context (:data:`workers.logs.REQUEST_ID`) while it is answered: the API's log
lines carry it, and so does a job's task (its ``request_id`` header), so the worker's lines of that job
carry it too (:mod:`workers.logs`). Wraps the whole stack: a 413 or a 500 carries the id as well.
"""

from __future__ import annotations

from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from workers.logs import HEADER, REQUEST_ID, request_id_from

_HEADER_BYTES = HEADER.lower().encode()


class RequestId:
    """Pure ASGI middleware: reads ``X-Request-ID`` (a valid one is kept, else one is made), sets it for
    the request's context and echoes it in the answer's headers."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        sent = next((v for k, v in scope["headers"] if k == _HEADER_BYTES), None)
        request_id = request_id_from(sent.decode("latin-1") if sent is not None else None)
        token = REQUEST_ID.set(request_id)

        async def send_with_id(message: Message) -> None:
            if message["type"] == "http.response.start":
                MutableHeaders(scope=message)[HEADER] = request_id
            await send(message)

        try:
            await self.app(scope, receive, send_with_id)
        finally:
            REQUEST_ID.reset(token)
