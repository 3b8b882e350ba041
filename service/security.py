"""Security headers on every response, and the file names of downloads.

:class:`SecurityHeaders` (pure ASGI: it only appends to the header list of ``http.response.start``)
sends on every answer ``X-Content-Type-Options: nosniff``, ``Referrer-Policy: no-referrer`` (job and
ensemble ids in URLs never leave for another site; nothing here reads ``Referer``), ``X-Frame-Options:
DENY`` and a ``Content-Security-Policy`` chosen by the answer's media type:

- HTML pages (job, ensemble, report): :data:`PAGE_POLICY`: nothing but the service's own stylesheet
  and images (the plots), no script at all, no form, no frame;
- the section explorer (``/explore``): :data:`EXPLORE_POLICY`, set by its route: the same plus its one script
  from the service (``/static/explore.js``) and requests to the service (``connect-src 'self'``);
- ``/docs`` and ``/redoc`` (Swagger UI and ReDoc from the package's files): :data:`DOCS_POLICY`, looser:
  their scripts from the service plus the page's inline configuration script, allowed by its SHA-256
  (computed from the page itself), inline styles (both inject ``<style>``), ``data:`` images (Swagger
  UI's icons) and ``blob:`` workers (ReDoc);
- SVG plots opened by themselves: :data:`SVG_POLICY` (matplotlib's SVG carries a ``<style>``);
- everything else (JSON, problem+json, CSV, NPZ, PNG): :data:`API_POLICY`, ``default-src 'none'``.
"""

from __future__ import annotations

import base64
import hashlib
import re

from starlette.types import ASGIApp, Message, Receive, Scope, Send

#: The policy of every answer that is not a page: nothing may load, nothing may frame it.
API_POLICY = "default-src 'none'; frame-ancestors 'none'"
#: The job, ensemble and report pages: the stylesheet and images (plots, favicon) from the service; a form
#: (the trajectory plot's window) that asks the service for the page again.
PAGE_POLICY = ("default-src 'none'; style-src 'self'; img-src 'self'; base-uri 'none'; form-action 'self'; "
               "frame-ancestors 'none'")
#: The section explorer: its own script from the service, and its requests back to the service.
EXPLORE_POLICY = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; connect-src 'self'; "
                  "base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
#: A plot's SVG viewed on its own: its inline ``<style>``, nothing else (no script).
SVG_POLICY = "default-src 'none'; style-src 'unsafe-inline'; frame-ancestors 'none'"
#: Swagger UI and ReDoc; ``{scripts}`` becomes the hashes of the page's inline scripts.
DOCS_POLICY = ("default-src 'none'; script-src 'self'{scripts}; style-src 'self' 'unsafe-inline'; "
               "img-src 'self' data:; font-src 'self' data:; connect-src 'self'; worker-src 'self' blob:; "
               "base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
#: Sent on every answer.
COMMON_HEADERS: tuple[tuple[bytes, bytes], ...] = (
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
    (b"x-frame-options", b"DENY"),
)
_CSP = b"content-security-policy"
_INLINE_SCRIPT = re.compile(rb"<script(?![^>]*\bsrc\s*=)[^>]*>(.*?)</script>", re.S | re.I)
#: Characters a download's file name keeps; any other becomes ``_``.
_UNSAFE_FILENAME = re.compile(r"[^A-Za-z0-9._-]")


def safe_filename(name: str, limit: int = 120) -> str:
    """``name`` with every character outside ``[A-Za-z0-9._-]`` replaced by ``_`` (at most ``limit``
    characters, never empty, never starting with a dot): safe inside ``filename="..."``.

    >>> safe_filename('job-a"b\\r\\nX-Evil: 1-trajectory.csv')
    'job-a_b__X-Evil__1-trajectory.csv'
    """
    cleaned = _UNSAFE_FILENAME.sub("_", name)[:limit].lstrip(".")
    return cleaned or "download"


def content_disposition(kind: str, name: str) -> dict[str, str]:
    """The ``Content-Disposition`` header of a download: ``kind`` is ``attachment`` or ``inline``,
    ``name`` is passed through :func:`safe_filename` (ids from the URL or the broker never reach the
    header as they are)."""
    if kind not in ("attachment", "inline"):
        raise ValueError(f"Content-Disposition kind {kind!r}")
    return {"Content-Disposition": f'{kind}; filename="{safe_filename(name)}"'}


def script_hashes(html: bytes) -> list[str]:
    """CSP source expressions (``'sha256-...'``) of the inline scripts of ``html``."""
    return ["'sha256-" + base64.b64encode(hashlib.sha256(body).digest()).decode() + "'"
            for body in _INLINE_SCRIPT.findall(html)]


def _policy_for(content_type: bytes) -> bytes:
    if content_type.startswith(b"text/html"):
        return PAGE_POLICY.encode()
    if content_type.startswith(b"image/svg+xml"):
        return SVG_POLICY.encode()
    return API_POLICY.encode()


def _with_headers(message: Message, policy: bytes | None = None) -> Message:
    """``http.response.start`` with the common headers and a CSP added (what the app set is kept)."""
    headers = list(message.get("headers", ()))
    present = {name.lower() for name, _ in headers}
    content_type = next((value for name, value in headers if name.lower() == b"content-type"), b"")
    headers.extend(header for header in COMMON_HEADERS if header[0] not in present)
    if _CSP not in present:
        headers.append((_CSP, policy or _policy_for(content_type)))
    return {**message, "headers": headers}


class SecurityHeaders:
    """ASGI middleware: the headers of the module docstring on every HTTP answer.

    ``docs_paths`` are answered with :data:`DOCS_POLICY` (their small HTML is read first, to hash its
    inline scripts); any other path costs one pass over the header list.
    """

    def __init__(self, app: ASGIApp, docs_paths: frozenset[str] = frozenset()) -> None:
        self.app, self.docs_paths = app, docs_paths

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if scope["path"] in self.docs_paths:
            await self._docs(scope, receive, send)
            return

        async def send_with_headers(message: Message) -> None:
            await send(_with_headers(message) if message["type"] == "http.response.start" else message)

        await self.app(scope, receive, send_with_headers)

    async def _docs(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Hold the answer until its body is complete, then send it with the hashes of its scripts."""
        start: Message | None = None
        body: list[bytes] = []

        async def held(message: Message) -> None:
            nonlocal start
            if message["type"] == "http.response.start":
                start = message
                return
            if message["type"] != "http.response.body" or start is None:
                await send(message)
                return
            body.append(message.get("body", b""))
            if message.get("more_body", False):
                return
            content = b"".join(body)
            scripts = "".join(" " + h for h in script_hashes(content))
            policy = DOCS_POLICY.format(scripts=scripts).encode()
            is_html = any(n.lower() == b"content-type" and v.startswith(b"text/html")
                          for n, v in start.get("headers", ()))
            await send(_with_headers(start, policy if is_html else None))
            await send({"type": "http.response.body", "body": content})

        await self.app(scope, receive, held)
