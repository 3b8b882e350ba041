"""The client's exceptions: one :class:`ApiError` for every error answer of the API.

The service answers every error as an RFC 9457 ``application/problem+json`` document; the client
turns it into :class:`ApiError` without losing anything. Answers that are not problem+json (a proxy's
HTML page, a truncated body) and connection failures become an :class:`ApiError` too, so a caller
(the command line) handles one exception type.
"""

from __future__ import annotations

import json
from typing import Any

import httpx

#: ``status`` of an :class:`ApiError` raised because the service could not be reached.
UNREACHABLE = 0


class ApiError(Exception):
    """An error answer of the API, as its RFC 9457 problem.

    Parameters
    ----------
    problem : dict
        The problem document: ``type``, ``title``, ``status``, ``detail``, ``instance`` and
        ``errors`` (a list of ``{"field", "reason"}``); missing members take RFC 9457's defaults.

    Attributes
    ----------
    status : int or None
        The HTTP status; ``0`` when the service could not be reached; ``None`` when no HTTP error
        is involved (a job that failed, see :class:`JobFailed`).
    type : str
        The problem type (``/problems/invalid-request`` ...; ``about:blank`` if none was given).
    title : str
        Short summary of the problem type.
    detail : str
        What went wrong with this request.
    errors : list of dict
        Each offending field as ``{"field": "system.inertia[0]", "reason": "..."}``.
    problem : dict
        The whole problem document as received (or built).
    retry_after : float or None
        Seconds the service asked to wait before retrying (``Retry-After`` of a 429 or 503).
    request_id : str or None
        The answer's ``X-Request-ID``: quote it to the service's operator, whose logs carry it on every
        line of the request and of its job.

    Examples
    --------
    >>> err = ApiError({"status": 404, "title": "Unknown job", "detail": "no job with id 'x'"})
    >>> str(err)
    "404 Unknown job: no job with id 'x'"
    """

    def __init__(self, problem: dict[str, Any]) -> None:
        self.problem: dict[str, Any] = dict(problem)
        status = self.problem.get("status")
        self.status: int | None = int(status) if isinstance(status, (int, float)) else None
        self.type: str = str(self.problem.get("type") or "about:blank")
        self.title: str = str(self.problem.get("title") or "Error")
        self.detail: str = str(self.problem.get("detail") or "")
        self.retry_after: float | None = None
        self.request_id: str | None = None
        raw = self.problem.get("errors") or []
        self.errors: list[dict[str, str]] = [
            {"field": str(e.get("field", "")), "reason": str(e.get("reason", ""))} if isinstance(e, dict)
            else {"field": "", "reason": str(e)} for e in raw]
        super().__init__(self._text())

    def _text(self) -> str:
        detail = self.detail or "; ".join(f"{e['field']}: {e['reason']}" for e in self.errors)
        head = f"{self.status} {self.title}" if self.status is not None else self.title
        return f"{head}: {detail}" if detail else head

    def __str__(self) -> str:
        return self._text()

    @property
    def unreachable(self) -> bool:
        """Whether the service could not be reached at all (no HTTP answer)."""
        return self.status == UNREACHABLE

    @classmethod
    def from_response(cls, response: httpx.Response) -> ApiError:
        """Build the error of a non-2xx answer.

        Parameters
        ----------
        response : httpx.Response
            The answer, its body read.

        Returns
        -------
        ApiError
            The body's problem if it is a JSON object with a ``title`` or ``detail``; otherwise a
            problem built from the status line and the start of the body.
        """
        try:
            body = response.json()
        except (ValueError, UnicodeDecodeError):
            body = None
        if isinstance(body, dict) and ("title" in body or "detail" in body):
            error = cls({"status": response.status_code, **body})
        else:
            text = response.text.strip() if body is None else json.dumps(body)
            error = cls({"type": "about:blank", "title": response.reason_phrase or "HTTP error",
                         "status": response.status_code,
                         "detail": text[:500] or f"{response.request.method} {response.request.url} answered "
                                                  f"{response.status_code} without a body"})
        retry = response.headers.get("retry-after", "")
        error.retry_after = float(retry) if retry.isdigit() else None
        error.request_id = response.headers.get("x-request-id")
        return error

    @classmethod
    def unreachable_at(cls, url: str, exc: Exception) -> ApiError:
        """The error raised when ``url`` cannot be reached (refused, DNS, timeout ...).

        Parameters
        ----------
        url : str
            The URL that was asked for.
        exc : Exception
            The transport error.

        Returns
        -------
        ApiError
            With ``status`` 0 and ``detail`` "cannot reach <url>: <reason>".
        """
        reason = str(exc) or type(exc).__name__
        return cls({"type": "about:blank", "title": "Service unreachable", "status": UNREACHABLE,
                    "detail": f"cannot reach {url}: {reason}"})


class JobFailed(ApiError):
    """A job or ensemble that ended ``failed`` or ``cancelled`` while the client waited for it.

    Parameters
    ----------
    kind : {"job", "ensemble"}
        What was waited for.
    view : dict
        Its last view (``GET /v1/jobs/{id}`` or ``GET /v1/ensembles/{id}``).

    Attributes
    ----------
    job_id : str
        The job's (or ensemble's) id.
    job_status : str
        ``"failed"`` or ``"cancelled"``.
    view : dict
        The last view.
    error : dict or None
        The job's ``error`` (``{"type", "message"}``) when the service gave one.
    """

    def __init__(self, kind: str, view: dict[str, Any]) -> None:
        self.job_id: str = str(view.get("id", ""))
        self.job_status: str = str(view.get("status", "failed"))
        self.view: dict[str, Any] = view
        self.error: dict[str, Any] | None = view.get("error")
        if self.error:
            detail = f"{self.error.get('type', 'Error')}: {self.error.get('message', '')}"
        else:
            detail = f"{kind} {self.job_id} was {self.job_status}"
        super().__init__({"type": "about:blank", "title": f"{kind.capitalize()} {self.job_status}", "status": None,
                          "detail": detail, "errors": []})
