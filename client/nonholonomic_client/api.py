"""The Python client of the nonholonomic HTTP API (``httpx``): every route as a method, results as
dicts, bytes, files, or (with the ``[notebook]`` extra) xarray Datasets and pandas DataFrames.

Examples
--------
>>> from nonholonomic_client import Client
>>> with Client("http://127.0.0.1:8000") as api:                      # doctest: +SKIP
...     job_id = api.submit({"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
...                          "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]},
...                          "t_final": 20.0, "samples": 51})
...     api.wait(job_id, progress=True)
...     ds = api.trajectory(job_id, format="xarray")
...     api.trajectory(job_id, "csv", out="trajectory.csv")
"""

from __future__ import annotations

import io
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np

from nonholonomic_client import frames
from nonholonomic_client.base import DEFAULT_URL, TERMINAL, Progress, default_url
from nonholonomic_client.errors import ApiError
from nonholonomic_client.orbits import OrbitRoutes
from nonholonomic_client.progress import notebook_progress
from nonholonomic_client.symbolic import SymbolicRoutes

if TYPE_CHECKING:
    import pandas
    import xarray

__all__ = ["DEFAULT_URL", "TERMINAL", "Client", "Progress", "default_url"]

#: Downloads the server writes (a file's bytes).
FILE_FORMATS = ("csv", "npz", "netcdf")
#: Members asked for per page when a table of every member is built.
MEMBERS_PAGE = 1000


class Client(OrbitRoutes, SymbolicRoutes):
    """A client of the nonholonomic API: every route as a method; every error answer raises
    :class:`ApiError`. Made as :class:`~nonholonomic_client.base.BaseClient` (``base_url``,
    ``timeout``, ``api_key``, ``transport``); use it as a context manager.
    """

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
             progress: Progress | bool | None = None, trajectory: bool = True) -> dict[str, Any]:
        """Poll a job until it succeeded, failed or was cancelled.

        Parameters
        ----------
        job_id : str
        timeout : float, optional
            Seconds to wait at most; default no limit.
        poll : float, default 0.2
            Seconds between polls.
        progress : callable or bool, optional
            Called as ``progress(fraction, status)`` after each poll (the last call of a job that
            succeeded has fraction 1.0). ``True``: a tqdm bar (a widget in Jupyter, text in a
            terminal) in simulated seconds, so its rate and ETA are linear in simulated time.
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
        def summary(ident: str) -> dict[str, Any]:
            return self.job(ident, trajectory=False)

        if progress is True:
            first = summary(job_id)
            t_final = (first.get("request") or {}).get("t_final")
            simulated = isinstance(t_final, int | float)  # a report job has no t_final: a bare bar
            total = cast(float, t_final) if simulated else 1.0
            with notebook_progress(total, "s" if simulated else None, label=job_id[:8]) as bar:
                view = self._wait("job", summary, job_id, timeout, poll, bar)
        else:
            view = self._wait("job", summary, job_id, timeout, poll, progress or None)
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
        return self._succeeded(self.job(job_id), job_id)

    def trajectory(self, job_id: str,
                   format: Literal["json", "csv", "npz", "netcdf", "xarray", "pandas"] = "json",  # noqa: A002
                   out: str | Path | None = None) -> dict[str, Any] | bytes | Path | xarray.Dataset | pandas.DataFrame:
        """``GET /v1/jobs/{id}/trajectory``: the sampled trajectory of a succeeded job.

        Parameters
        ----------
        job_id : str
        format : {"json", "csv", "npz", "netcdf", "xarray", "pandas"}, default "json"
            JSON (``units``, ``t``, ``tau`` and each vector), CSV (a header naming each column with
            its unit; ``t``, ``tau`` first), NPZ (``numpy.load``), NetCDF-4 (``xarray.open_dataset``);
            or, built here from the JSON (values equal bit for bit), an :class:`xarray.Dataset` over
            ``t`` with one variable per component (``M1`` ... ``gamma3``, ``tau``), each with its
            ``units``, and the request, versions and evidence in ``attrs``, or a
            :class:`pandas.DataFrame` indexed by ``t``.
        out : str or Path, optional
            Stream a file format into this file (written in chunks; replaced only once complete).

        Returns
        -------
        dict or bytes or Path or xarray.Dataset or pandas.DataFrame

        Raises
        ------
        ApiError
            404 for an unknown job, 409 if it has not succeeded.
        """
        path = f"/v1/jobs/{job_id}/trajectory"
        if format in ("xarray", "pandas"):
            samples = self._json("GET", path, params={"format": "json"})
            view = self.job(job_id, trajectory=False)
            build = frames.trajectory_dataset if format == "xarray" else frames.trajectory_frame
            return build(samples, view)
        params = {"format": format}
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
        return self._page("/v1/jobs", status, limit, cursor)

    def _page(self, path: str, status: str | None, limit: int, cursor: str | None) -> dict[str, Any]:
        """A page of a list (``GET /v1/jobs`` or ``/v1/ensembles``)."""
        params: dict[str, Any] = {"limit": limit}
        if status is not None:
            params["status"] = status
        if cursor is not None:
            params["cursor"] = cursor
        return self._json("GET", path, params=params)

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

    def ensembles(self, status: str | None = None, limit: int = 50, cursor: str | None = None) -> dict[str, Any]:
        """``GET /v1/ensembles``: a page of ensembles, newest first (the key's own, with API keys).

        Parameters
        ----------
        status : str, optional
            Only ensembles in this status (queued, running, succeeded, failed, cancelled).
        limit : int, default 50
            Ensembles read for the page (at most 500; with ``status`` a page may hold fewer).
        cursor : str, optional
            The previous page's ``next_cursor``.

        Returns
        -------
        dict
            ``{items: [{id, status, progress, created_at, kind, members, members_done, label, location}],
            next_cursor}``; ``label`` says what varies across the members (``sweep of D`` ...).

        Notes
        -----
        Every method taking an ensemble's or a job's id also takes its first characters (6 or more, as the
        progress bar shows 8) when no other of yours starts so.
        """
        return self._page("/v1/ensembles", status, limit, cursor)

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
                      progress: Progress | bool | None = None) -> dict[str, Any]:
        """Poll an ensemble until it succeeded or was cancelled (like :meth:`wait`).

        Parameters
        ----------
        ensemble_id : str
        timeout : float, optional
        poll : float, default 0.2
        progress : callable or bool, optional
            ``progress(members done / members, status)`` after each poll; ``True``: a tqdm bar in members.

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
        if progress is True:
            with notebook_progress(float(self.ensemble(ensemble_id).get("members") or 1), "members",
                              label=ensemble_id[:8]) as bar:
                return self._wait("ensemble", self.ensemble, ensemble_id, timeout, poll, bar)
        return self._wait("ensemble", self.ensemble, ensemble_id, timeout, poll, progress or None)

    def members(self, ensemble_id: str, offset: int = 0, limit: int | None = None,
                format: Literal["json", "pandas", "csv", "netcdf"] = "json",  # noqa: A002
                out: str | Path | None = None) -> dict[str, Any] | pandas.DataFrame | bytes | Path:
        """``GET /v1/ensembles/{id}/members``: a page of member results, or every member as a table.

        Parameters
        ----------
        ensemble_id : str
        offset : int, default 0
        limit : int, optional
            Members at most: for ``"json"`` one page (default 100, at most 1000); for ``"pandas"``
            default every member from ``offset`` on (fetched a page of 1000 at a time).
        format : {"json", "pandas", "csv", "netcdf"}, default "json"
            ``"pandas"``: a DataFrame indexed by ``member`` (see
            :func:`nonholonomic_client.frames.members_frame` for its columns). ``"csv"``, ``"netcdf"``: the
            server's table of every member done (the same columns; NetCDF: dimension ``member``, a variable per
            column with its units), as bytes or streamed into ``out``; ``offset`` and ``limit`` do not apply.
        out : str or Path, optional
            Where to write a ``csv`` or ``netcdf`` table.

        Returns
        -------
        dict, pandas.DataFrame, bytes or Path
            ``{offset, limit, total, members: [{index, status, initial_state, final_state, ...}]}``
            for ``"json"``; ``out`` when given.
        """
        path = f"/v1/ensembles/{ensemble_id}/members"
        if format in ("csv", "netcdf"):
            if out is not None:
                return self._download(path, {"format": format}, out)
            return self._request("GET", path, params={"format": format}).content
        if format == "json":
            return self._json("GET", path, params={"offset": offset, "limit": 100 if limit is None else limit})
        names: dict[str, list[str]] = {}
        return frames.members_frame(self._every_member(ensemble_id, offset, limit, names), names)

    def _every_member(self, ensemble_id: str, offset: int = 0, limit: int | None = None,
                      names: dict[str, list[str]] | None = None) -> Iterator[dict[str, Any]]:
        """Members ``offset`` .. ``offset + limit`` page by page; a page leaves out the members of chunks not
        done yet, so the pages advance by the indices asked for, not by the members they hold. ``names`` is
        filled with the pages' component names (``components``) before the first member is yielded."""
        path, end = f"/v1/ensembles/{ensemble_id}/members", None if limit is None else offset + limit
        while end is None or offset < end:
            size = MEMBERS_PAGE if end is None else min(MEMBERS_PAGE, end - offset)
            page = self._json("GET", path, params={"offset": offset, "limit": size})
            if names is not None:
                names.update(page.get("components") or {})
            yield from page["members"]
            offset += size
            if offset >= page["total"]:
                return

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

    def _is_ensemble(self, ident: str, of: str | None) -> bool:
        if of is not None:
            if of not in ("job", "ensemble"):
                raise ValueError(f"of must be 'job' or 'ensemble', not {of!r}")
            return of == "ensemble"
        try:
            self._request("GET", f"/v1/jobs/{ident}", params={"trajectory": "false"})
            return False
        except ApiError as exc:
            if exc.status != 404:
                raise
        return True

    def section(self, ident: str, format: Literal["csv", "npz", "netcdf", "json", "pandas"] = "csv",  # noqa: A002
                out: str | Path | None = None, *,
                of: Literal["job", "ensemble"] | None = None) -> bytes | Path | dict[str, Any] | pandas.DataFrame:
        """The Poincaré section of a job or of an ensemble (every member's crossings).

        ``GET /v1/jobs/{id}/section`` or ``GET /v1/ensembles/{id}/poincare``.

        Parameters
        ----------
        ident : str
            A job's or an ensemble's id.
        format : {"csv", "npz", "netcdf", "json", "pandas"}, default "csv"
            A file's bytes, the section's JSON (a job's ``result.poincare``; not for an ensemble),
            or a DataFrame: one row per crossing with ``member`` (an ensemble's), ``t``, ``tau`` and
            every component of the state at the crossing, equal to the JSON bit for bit.
        out : str or Path, optional
            Stream a file format into this file.
        of : {"job", "ensemble"}, optional
            What ``ident`` is; default: asked of the API (one request).

        Returns
        -------
        bytes or Path or dict or pandas.DataFrame

        Raises
        ------
        ApiError
            404 for an unknown id, 409 if the job or ensemble asked for no section or has not finished.
        """
        ensemble = self._is_ensemble(ident, of)
        if format in FILE_FORMATS:
            path = f"/v1/ensembles/{ident}/poincare" if ensemble else f"/v1/jobs/{ident}/section"
            if out is not None:
                return self._download(path, {"format": format}, out)
            return self._request("GET", path, params={"format": format}).content
        if format not in ("json", "pandas"):
            raise ValueError(f"format must be one of csv, npz, netcdf, json, pandas, not {format!r}")
        if ensemble:
            if format == "json":
                raise ValueError("an ensemble's section comes as csv, npz, netcdf or pandas")
            raw = self._request("GET", f"/v1/ensembles/{ident}/poincare", params={"format": "npz"}).content
            with np.load(io.BytesIO(raw), allow_pickle=False) as arrays:
                return frames.section_npz_frame(dict(arrays), {"ensemble": ident})
        view = self.job(ident, trajectory=False)
        result = self._succeeded(view, ident)
        section = result.get("poincare")
        if section is None:
            raise ApiError({"type": "/problems/conflict", "title": "No section", "status": None,
                            "detail": f"job {ident} asked for no Poincare section (request.poincare)"})
        if format == "json":
            return section
        attrs = frames.provenance(view)
        attrs.update(surface=str(section.get("surface")), value=str(section.get("value")),
                     direction=str(section.get("direction")))
        return frames.section_frame([(None, section)], result["system"]["units"], attrs,
                                    result["system"].get("components"))

    def chaos_map(self, ensemble_id: str, format: Literal["xarray", "json", "csv", "netcdf"] = "xarray",  # noqa: A002
                  out: str | Path | None = None) -> xarray.Dataset | dict[str, Any] | bytes | Path:
        """A chaos map (an ensemble with ``members.grid``): ``GET /v1/ensembles/{id}/map``.

        ``xarray`` (the ``[notebook]`` extra): a Dataset on the two coordinates with ``status``, each
        indicator and each integral's drift, equal to the JSON bit for bit; ``json``: the 2-D arrays;
        ``csv`` or ``netcdf``: the file's bytes (or streamed into ``out``).

        Raises
        ------
        ApiError
            404 for an unknown id, 409 if the ensemble is not a map.
        """
        path = f"/v1/ensembles/{ensemble_id}/map"
        if format in ("csv", "netcdf"):
            if out is not None:
                return self._download(path, {"format": format}, out)
            return self._request("GET", path, params={"format": format}).content
        if format not in ("json", "xarray"):
            raise ValueError(f"format must be one of xarray, json, csv, netcdf, not {format!r}")
        data = self._request("GET", path, params={"format": "json"}).json()
        if format == "json":
            return data
        return frames.map_dataset(data, self.ensemble(ensemble_id))

    def exponents(self, ident: str, format: Literal["json", "pandas"] = "pandas", *,  # noqa: A002
                  of: Literal["job", "ensemble"] | None = None) -> dict[str, Any] | pandas.DataFrame:
        """The Lyapunov exponents of a job (its spectrum) or of an ensemble (each member's).

        Parameters
        ----------
        ident : str
            A job's or an ensemble's id.
        format : {"pandas", "json"}, default "pandas"
            A job: a DataFrame indexed by ``i`` (``exponent`` in 1/s, ``moved_last_20pct``,
            ``expected_zero``; the sum and the warnings, e.g. "not converged", in ``attrs``), or the
            result's ``lyapunov``. An ensemble: a DataFrame indexed by ``member`` (``status``,
            ``exponent_1`` ...), or ``{member: lyapunov}``.
        of : {"job", "ensemble"}, optional
            What ``ident`` is; default: asked of the API.

        Returns
        -------
        dict or pandas.DataFrame
        """
        if self._is_ensemble(ident, of):
            members = list(self._every_member(ident))
            if format == "json":
                return {m["index"]: m.get("lyapunov") for m in members}
            table = frames.members_frame(members)
            return table[["status", *[c for c in table.columns if c.startswith("exponent_")]]]
        result = self._succeeded(self.job(ident, trajectory=False), ident)
        lyapunov = result.get("lyapunov")
        if lyapunov is None:
            raise ApiError({"type": "/problems/conflict", "title": "No spectrum", "status": None,
                            "detail": f"job {ident} asked for no Lyapunov spectrum (request.lyapunov)"})
        return lyapunov if format == "json" else frames.exponents_frame(lyapunov)

    def plot(self, ident: str, name: str, fmt: Literal["png", "svg"] = "png", *,  # noqa: A002
             of: Literal["job", "ensemble"] | None = None) -> bytes:
        """``GET /v1/jobs/{id}/plots/{name}.{fmt}`` (or an ensemble's): a plot the server draws, as bytes
        (``IPython.display.Image(api.plot(job, "bifurcation"))`` shows it in a notebook).

        Parameters
        ----------
        ident : str
            A job's or an ensemble's id (or its first characters).
        name : str
            A job's ``trajectory``, ``integrals``, ``poincare``, ``lyapunov``, ``periodic_orbit``,
            ``bifurcation``; an ensemble's ``poincare``, ``exponents``, ``map``.
        fmt : {"png", "svg"}
        of : {"job", "ensemble"}, optional
            Which ``ident`` is (default: a job if one has that id).
        """
        kind = "ensembles" if self._is_ensemble(ident, of) else "jobs"
        return self._request("GET", f"/v1/{kind}/{ident}/plots/{name}.{fmt}").content

    def convergence(self, job_id: str) -> pandas.DataFrame:
        """How a job's finite-time Lyapunov estimates moved: a DataFrame indexed by ``t``, a column
        ``exponent_k`` each.

        Parameters
        ----------
        job_id : str

        Returns
        -------
        pandas.DataFrame
        """
        lyapunov = self.exponents(job_id, format="json", of="job")
        return frames.convergence_frame(lyapunov)
