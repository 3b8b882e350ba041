"""The client's plumbing: the connection pool, error answers as :class:`ApiError`, downloads streamed
to a file, and polling until a job ends. :class:`nonholonomic_client.Client` adds the API's routes.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Self

import httpx

from nonholonomic_client.errors import ApiError, JobFailed

#: Where the client looks for the API when neither an argument nor ``NONHOLONOMIC_URL`` says.
DEFAULT_URL = "http://127.0.0.1:8000"
#: Statuses after which a job or an ensemble no longer changes.
TERMINAL = frozenset({"succeeded", "failed", "cancelled"})

Progress = Callable[[float, str], None]


def default_url() -> str:
    """The API's base URL: ``NONHOLONOMIC_URL`` if set, else ``http://127.0.0.1:8000``.

    Returns
    -------
    str
        The base URL without a trailing slash.
    """
    return (os.environ.get("NONHOLONOMIC_URL") or DEFAULT_URL).rstrip("/")


class BaseClient:
    """A connection to the nonholonomic API; every error answer raises :class:`ApiError`.

    Parameters
    ----------
    base_url : str, optional
        The API's address, e.g. ``http://127.0.0.1:8000``; default ``NONHOLONOMIC_URL`` (read when
        the client is made), else ``http://127.0.0.1:8000``.
    timeout : float, default 30.0
        Seconds allowed for each HTTP request (not for a job: see :meth:`wait`).
    api_key : str, optional
        The API key, sent as ``Authorization: Bearer <key>``, for a service with keys on; default
        ``NONHOLONOMIC_API_KEY`` if set.
    transport : httpx.BaseTransport, optional
        A custom transport (``httpx.MockTransport`` in tests).

    Notes
    -----
    Use it as a context manager (or call :meth:`close`) to release the connection pool. A request
    that cannot reach the service raises :class:`ApiError` with ``status`` 0.
    """

    def __init__(self, base_url: str | None = None, timeout: float = 30.0, *, api_key: str | None = None,
                 transport: httpx.BaseTransport | None = None) -> None:
        self.base_url: str = (base_url or default_url()).rstrip("/")
        self.timeout = timeout
        headers = {"accept": "application/json, application/problem+json;q=0.9, */*;q=0.1"}
        key = api_key or os.environ.get("NONHOLONOMIC_API_KEY")
        if key:
            headers["authorization"] = f"Bearer {key}"
        self._http = httpx.Client(base_url=self.base_url, timeout=timeout, transport=transport, headers=headers)

    # -- plumbing ---------------------------------------------------------------------------

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connection pool."""
        self._http.close()

    def url(self, path: str) -> str:
        """The absolute URL of an API path.

        Parameters
        ----------
        path : str
            E.g. ``/v1/jobs/<id>``.

        Returns
        -------
        str
        """
        return f"{self.base_url}{path}"

    def _request(self, method: str, path: str, *, json: Any = None, params: Mapping[str, Any] | None = None,
                 accept: tuple[int, ...] = ()) -> httpx.Response:
        try:
            response = self._http.request(method, path, json=json, params=params)
        except httpx.TransportError as exc:
            raise ApiError.unreachable_at(self.url(path), exc) from exc
        if response.is_success or response.status_code in accept:
            return response
        raise ApiError.from_response(response)

    def _json(self, method: str, path: str, **kwargs: Any) -> Any:
        response = self._request(method, path, **kwargs)
        try:
            return response.json()
        except ValueError as exc:
            raise ApiError({"status": response.status_code, "title": "Answer is not JSON",
                            "detail": f"{method} {self.url(path)}: {response.text[:200]!r}"}) from exc

    def _download(self, path: str, params: Mapping[str, Any], out: str | Path) -> Path:
        target = Path(out)
        partial = target.with_name(target.name + ".part")
        try:
            with self._http.stream("GET", path, params=params) as response:
                if not response.is_success:
                    response.read()
                    raise ApiError.from_response(response)
                with partial.open("wb") as f:
                    for chunk in response.iter_bytes(chunk_size=1 << 16):
                        f.write(chunk)
            partial.replace(target)
        except httpx.TransportError as exc:
            raise ApiError.unreachable_at(self.url(path), exc) from exc
        finally:
            partial.unlink(missing_ok=True)
        return target

    def _wait(self, kind: str, get: Callable[[str], dict[str, Any]], ident: str, timeout: float | None,
              poll: float, progress: Progress | None) -> dict[str, Any]:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                view = get(ident)
            except ApiError as exc:  # busy or briefly away (429, 503 with Retry-After): wait as asked
                if exc.status not in (429, 503) or exc.retry_after is None:
                    raise
                if deadline is not None and time.monotonic() + exc.retry_after > deadline:
                    raise
                time.sleep(exc.retry_after)
                continue
            status = str(view.get("status"))
            if progress is not None:
                progress(float(view.get("progress") or 0.0), status)
            if status == "succeeded":
                return view
            if status in TERMINAL:
                raise JobFailed(kind, view)
            pause = poll
            if deadline is not None:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TimeoutError(f"{kind} {ident} still {status} after {timeout:g} s")
                pause = min(poll, remaining)
            time.sleep(pause)

    @staticmethod
    def _succeeded(view: Mapping[str, Any], ident: str) -> dict[str, Any]:
        if view.get("status") == "succeeded" and view.get("result") is not None:
            return dict(view["result"])
        if view.get("status") in TERMINAL:
            raise JobFailed("job", dict(view))
        raise ApiError({"type": "/problems/conflict", "title": "No result yet", "status": None,
                        "detail": f"job {ident} is {view.get('status')}; wait for it first"})
