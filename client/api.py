"""The Python client of the nonholonomic HTTP API (``httpx``).

Examples
--------
>>> from client import Client
>>> with Client("http://127.0.0.1:8000") as api:                      # doctest: +SKIP
...     job_id = api.submit({"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
...                          "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
...                          "t_final": 20.0, "samples": 51})
...     api.wait(job_id, progress=lambda fraction, status: print(fraction, status))
...     final = api.result(job_id)["final_state"]
...     api.trajectory(job_id, "csv", out="trajectory.csv")
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal, Self

import httpx

from client.errors import ApiError, JobFailed

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


class Client:
    """A client of the nonholonomic API; every error answer raises :class:`ApiError`.

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

    # -- service ----------------------------------------------------------------------------

    def health(self) -> dict[str, Any]:
        """``GET /health``: mode, broker and workers.

        Returns
        -------
        dict
            ``status`` is ``"ok"`` when jobs can run, else ``"degraded"`` (the 503 answer's body is
            returned, not raised).
        """
        return self._json("GET", "/health", accept=(503,))

    def systems(self) -> dict[str, Any]:
        """``GET /v1/systems``: the catalog.

        Returns
        -------
        dict
            ``{"systems": [{"kind", "title", "parameters", "state", "potentials", ...}, ...]}``.
        """
        return self._json("GET", "/v1/systems")

    def system(self, kind: str) -> dict[str, Any]:
        """``GET /v1/systems/{kind}``: one kind of the catalog.

        Parameters
        ----------
        kind : str
            E.g. ``"chaplygin_ball"``.

        Returns
        -------
        dict

        Raises
        ------
        ApiError
            404 for an unknown kind.
        """
        return self._json("GET", f"/v1/systems/{kind}")

    # -- jobs -------------------------------------------------------------------------------

    def submit(self, request: Mapping[str, Any]) -> str:
        """``POST /v1/jobs``: submit a simulation job.

        Parameters
        ----------
        request : dict
            ``{system, initial_state, t_final, samples, checks, ...}`` (see docs/first-job.md).

        Returns
        -------
        str
            The job id.

        Raises
        ------
        ApiError
            422 naming each offending field; nothing is queued then.
        """
        return str(self._json("POST", "/v1/jobs", json=request)["id"])

    def job(self, job_id: str, *, trajectory: bool = True) -> dict[str, Any]:
        """``GET /v1/jobs/{id}``: the job view.

        Parameters
        ----------
        job_id : str
        trajectory : bool, default True
            False: the summary view, a simulation's samples left out of ``result`` (its
            ``trajectory_location`` says where they are; :meth:`trajectory` downloads them).

        Returns
        -------
        dict
            ``{id, status, progress, created_at, request, result, error}``.
        """
        return self._json("GET", f"/v1/jobs/{job_id}", params=None if trajectory else {"trajectory": "false"})

    def wait(self, job_id: str, *, timeout: float | None = None, poll: float = 0.2,
             progress: Progress | None = None, trajectory: bool = True) -> dict[str, Any]:
        """Poll a job until it succeeded, failed or was cancelled.

        Parameters
        ----------
        job_id : str
        timeout : float, optional
            Seconds to wait at most; default no limit.
        poll : float, default 0.2
            Seconds between polls.
        progress : callable, optional
            Called as ``progress(fraction, status)`` after each poll (the last call of a job that
            succeeded has fraction 1.0).
        trajectory : bool, default True
            Whether the returned view holds the samples (the polls never carry them: the summary view).

        Returns
        -------
        dict
            The job's last view (status ``succeeded``).

        Raises
        ------
        JobFailed
            If the job failed or was cancelled; carries the job's ``error``.
        TimeoutError
            If it is still queued or running after ``timeout``.
        """
        view = self._wait("job", lambda ident: self.job(ident, trajectory=False), job_id, timeout, poll, progress)
        return self.job(job_id) if trajectory else view

    def result(self, job_id: str) -> dict[str, Any]:
        """The result of a succeeded job.

        Parameters
        ----------
        job_id : str

        Returns
        -------
        dict
            ``{system, final_state, t_final, tau_final, trajectory, integrals, checks, ...}`` (a
            paper report's result for a report job).

        Raises
        ------
        JobFailed
            If the job failed or was cancelled.
        ApiError
            If it has not finished yet (``status`` None, type ``/problems/conflict``).
        """
        view = self.job(job_id)
        if view.get("status") == "succeeded" and view.get("result") is not None:
            return view["result"]
        if view.get("status") in TERMINAL:
            raise JobFailed("job", view)
        raise ApiError({"type": "/problems/conflict", "title": "No result yet", "status": None,
                        "detail": f"job {job_id} is {view.get('status')}; wait for it first"})

    def trajectory(self, job_id: str, format: Literal["json", "csv", "npz"] = "json",
                   out: str | Path | None = None) -> dict[str, Any] | bytes | Path:
        """``GET /v1/jobs/{id}/trajectory``: the sampled trajectory of a succeeded job.

        Parameters
        ----------
        job_id : str
        format : {"json", "csv", "npz"}, default "json"
            JSON (``units``, ``t``, ``tau`` and each vector), CSV (a header naming each column with
            its unit; ``t``, ``tau`` first) or NPZ (``numpy.load``).
        out : str or Path, optional
            Stream the answer into this file (written in chunks; replaced only once complete).

        Returns
        -------
        dict or bytes or Path
            The parsed JSON for ``"json"``, the raw bytes for ``"csv"``/``"npz"``, or ``out`` as a
            :class:`~pathlib.Path` when given.

        Raises
        ------
        ApiError
            404 for an unknown job, 409 if it has not succeeded.
        """
        path, params = f"/v1/jobs/{job_id}/trajectory", {"format": format}
        if out is not None:
            return self._download(path, params, out)
        if format == "json":
            return self._json("GET", path, params=params)
        return self._request("GET", path, params=params).content

    def jobs(self, status: str | None = None, limit: int = 50, cursor: str | None = None) -> dict[str, Any]:
        """``GET /v1/jobs``: a page of jobs, newest first.

        Parameters
        ----------
        status : str, optional
            Only jobs in this status (queued, running, succeeded, failed, cancelled).
        limit : int, default 50
            At most 500.
        cursor : str, optional
            The previous page's ``next_cursor``.

        Returns
        -------
        dict
            ``{items: [{id, status, progress, created_at, kind, location}], next_cursor}``.
        """
        params: dict[str, Any] = {"limit": limit}
        if status is not None:
            params["status"] = status
        if cursor is not None:
            params["cursor"] = cursor
        return self._json("GET", "/v1/jobs", params=params)

    def cancel(self, job_id: str) -> dict[str, Any]:
        """``DELETE /v1/jobs/{id}``: cancel a job (a running one stops at its next progress report).

        Parameters
        ----------
        job_id : str

        Returns
        -------
        dict
            The job view (status ``cancelled``).

        Raises
        ------
        ApiError
            409 if the job already finished.
        """
        return self._json("DELETE", f"/v1/jobs/{job_id}")

    # -- ensembles --------------------------------------------------------------------------

    def submit_ensemble(self, request: Mapping[str, Any]) -> str:
        """``POST /v1/ensembles``: submit an ensemble.

        Parameters
        ----------
        request : dict
            ``{system, members, t_final, samples, checks, poincare, lyapunov, chunk_size}``.

        Returns
        -------
        str
            The ensemble id.
        """
        return str(self._json("POST", "/v1/ensembles", json=request)["id"])

    def ensemble(self, ensemble_id: str) -> dict[str, Any]:
        """``GET /v1/ensembles/{id}``: status, progress, chunks and summary.

        Parameters
        ----------
        ensemble_id : str

        Returns
        -------
        dict
        """
        return self._json("GET", f"/v1/ensembles/{ensemble_id}")

    def wait_ensemble(self, ensemble_id: str, *, timeout: float | None = None, poll: float = 0.2,
                      progress: Progress | None = None) -> dict[str, Any]:
        """Poll an ensemble until it succeeded or was cancelled (like :meth:`wait`).

        Parameters
        ----------
        ensemble_id : str
        timeout : float, optional
        poll : float, default 0.2
        progress : callable, optional
            ``progress(members done / members, status)`` after each poll.

        Returns
        -------
        dict
            The ensemble's last view. Members that failed alone leave it ``succeeded``; see its
            ``summary``.

        Raises
        ------
        JobFailed
            If the ensemble was cancelled.
        TimeoutError
            If it is not finished after ``timeout``.
        """
        return self._wait("ensemble", self.ensemble, ensemble_id, timeout, poll, progress)

    def members(self, ensemble_id: str, offset: int = 0, limit: int = 100) -> dict[str, Any]:
        """``GET /v1/ensembles/{id}/members``: a page of member results.

        Parameters
        ----------
        ensemble_id : str
        offset : int, default 0
        limit : int, default 100
            At most 1000.

        Returns
        -------
        dict
            ``{offset, limit, total, members: [{index, status, initial_state, final_state, ...}]}``.
        """
        return self._json("GET", f"/v1/ensembles/{ensemble_id}/members", params={"offset": offset, "limit": limit})

    def cancel_ensemble(self, ensemble_id: str) -> dict[str, Any]:
        """``DELETE /v1/ensembles/{id}``: stop every chunk.

        Parameters
        ----------
        ensemble_id : str

        Returns
        -------
        dict
            The ensemble view.
        """
        return self._json("DELETE", f"/v1/ensembles/{ensemble_id}")

    def section(self, ensemble_id: str, format: Literal["csv", "npz"] = "csv",
                out: str | Path | None = None) -> bytes | Path:
        """``GET /v1/ensembles/{id}/poincare``: every member's section points.

        Parameters
        ----------
        ensemble_id : str
        format : {"csv", "npz"}, default "csv"
        out : str or Path, optional
            Stream the answer into this file.

        Returns
        -------
        bytes or Path

        Raises
        ------
        ApiError
            409 if the ensemble asked for no section.
        """
        path, params = f"/v1/ensembles/{ensemble_id}/poincare", {"format": format}
        if out is not None:
            return self._download(path, params, out)
        return self._request("GET", path, params=params).content

    # -- the paper report -------------------------------------------------------------------

    def paper_claims(self) -> list[str]:
        """``GET /v1/paper/claims``: the ids of the claims the paper report checks.

        Returns
        -------
        list of str
        """
        return list(self._json("GET", "/v1/paper/claims")["claims"])

    def paper_report(self, claims: list[str] | None = None) -> str:
        """``POST /v1/paper/report``: check the paper's claims (all, or those given) in one job.

        Parameters
        ----------
        claims : list of str, optional
            Claim ids (see :meth:`paper_claims`); default every claim.

        Returns
        -------
        str
            The job id (wait with :meth:`wait`, read with :meth:`result` or :meth:`report_page`).
        """
        body = None if claims is None else {"claims": list(claims)}
        return str(self._json("POST", "/v1/paper/report", json=body)["id"])

    def report_page(self, job_id: str) -> str:
        """``GET /v1/paper/report/{id}``: the report as an HTML page.

        Parameters
        ----------
        job_id : str

        Returns
        -------
        str
            The HTML (a status page that reloads itself while the job runs).
        """
        return self._request("GET", f"/v1/paper/report/{job_id}").text
