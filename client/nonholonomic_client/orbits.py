"""A job's periodic orbit, its continuation and its branch of periodic orbits (issue 36); :class:`Client` has them."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from nonholonomic_client import frames
from nonholonomic_client.base import BaseClient
from nonholonomic_client.errors import ApiError

if TYPE_CHECKING:
    import pandas


class OrbitRoutes(BaseClient):
    """``GET /v1/jobs/{id}`` (its ``periodic_orbit``) and ``GET /v1/jobs/{id}/branch``."""

    def periodic_orbit(self, job_id: str, format: Literal["pandas", "json"] = "pandas",  # noqa: A002
                       ) -> dict[str, Any] | pandas.DataFrame:
        """A job's periodic orbit (it asked for ``periodic_orbit``) and its continuation.

        Parameters
        ----------
        job_id : str
            The job's id (or its first characters).
        format : {"pandas", "json"}, default "pandas"
            ``pandas`` (the ``[notebook]`` extra): one row per parameter value of the continuation, indexed
            by the parameter's name (``D``): ``status``, ``period_t``, ``trace``, ``stability``, ``residual``,
            ``checks_passed``, the section multipliers, and ``fold`` / ``period_doubling`` / ``lost``
            flags on the first point past each bifurcation; the orbit, the events and the skipped values
            in ``attrs`` (:func:`nonholonomic_client.frames.periodic_orbit_frame`). ``json``: the result's
            ``periodic_orbit``.

        Raises
        ------
        ApiError
            If the job has not succeeded, or asked for no periodic orbit.
        """
        orbit = self._result_of(job_id).get("periodic_orbit")
        if orbit is None:
            raise ApiError({"type": "/problems/conflict", "title": "No periodic orbit", "status": None,
                            "detail": f"job {job_id} asked for no periodic orbit (request.periodic_orbit)"})
        return orbit if format == "json" else frames.periodic_orbit_frame(orbit)

    def branch(self, job_id: str, format: Literal["pandas", "json", "csv", "netcdf"] = "pandas",  # noqa: A002
               out: str | Path | None = None) -> dict[str, Any] | pandas.DataFrame | bytes | Path:
        """``GET /v1/jobs/{id}/branch``: the job's branch of periodic orbits (it asked for
        ``periodic_orbit.branch``), with the branches switched onto at its period doublings.

        Parameters
        ----------
        job_id : str
            The job's id (or its first characters).
        format : {"pandas", "json", "csv", "netcdf"}, default "pandas"
            ``pandas`` (the ``[notebook]`` extra): the server's CSV table as a DataFrame, one row per point and
            per located bifurcation (``kind``: ``point``, ``fold``, ``period_doubling`` ...), with the columns
            ``branch``, ``period``, ``index``, the continued value (``energy [J]``), ``arclength``,
            ``period_t [s]``, ``period_tau``, the section coordinates, ``trace``, ``stability``, the
            multipliers, ``residual``, ``residual_independent``, ``checks_passed``, ``located``,
            ``test_function``; ``attrs`` holds the branch's status, reason and bifurcations. ``json``: the
            result's ``periodic_orbit.branch``. ``csv``, ``netcdf``: the file's bytes, or streamed into ``out``.
        out : str or Path, optional
            Where to write a ``csv`` or ``netcdf`` table.

        Raises
        ------
        ApiError
            409 if the job has not succeeded or asked for no branch.
        """
        path = f"/v1/jobs/{job_id}/branch"
        if format in ("csv", "netcdf"):
            if out is not None:
                return self._download(path, {"format": format}, out)
            return self._request("GET", path, params={"format": format}).content
        if format == "json":
            return dict(self._json("GET", path))
        if format != "pandas":
            raise ValueError(f"format must be one of pandas, json, csv, netcdf, not {format!r}")
        pd = frames._pandas()
        text = self._request("GET", path, params={"format": "csv"}).text
        frame = pd.read_csv(io.StringIO(text))
        data = self._json("GET", path)
        frame.attrs = {key: data.get(key) for key in ("in", "to", "period", "status", "reason", "units",
                                                      "coordinate_names", "warnings")}
        frame.attrs["bifurcations"] = [{k: v for k, v in b.items() if k != "point"}
                                       for b in [*data.get("bifurcations", []),
                                                 *(x for s in data.get("switched", []) for x in s["bifurcations"])]]
        return frame

    def orbit_diagram(self, ensemble_id: str, format: Literal["pandas", "json", "csv"] = "pandas",  # noqa: A002
                      out: str | Path | None = None) -> dict[str, Any] | pandas.DataFrame | bytes | Path:
        """``GET /v1/ensembles/{id}/orbit-diagram``: a sweep's section points against the swept value.

        Parameters
        ----------
        ensemble_id : str
            A sweep ensemble's id (or its first characters) that asked for a ``poincare`` section.
        format : {"pandas", "json", "csv"}, default "pandas"
            ``pandas``: one row per crossing, ``member``, the swept value named after its parameter with its
            unit, ``crossing``, the section's two coordinates. ``json``: one array per column. ``csv``: the
            file's bytes, or streamed into ``out``.
        out : str or Path, optional
            Where to write the ``csv``.

        Raises
        ------
        ApiError
            409 if the ensemble is not a sweep with a section.
        """
        path = f"/v1/ensembles/{ensemble_id}/orbit-diagram"
        if format == "json":
            return dict(self._json("GET", path, params={"format": "json"}))
        if format == "csv":
            if out is not None:
                return self._download(path, {"format": "csv"}, out)
            return self._request("GET", path, params={"format": "csv"}).content
        if format != "pandas":
            raise ValueError(f"format must be one of pandas, json, csv, not {format!r}")
        return frames._pandas().read_csv(io.StringIO(self._request("GET", path, params={"format": "csv"}).text))

    def _result_of(self, job_id: str) -> dict[str, Any]:
        return self._succeeded(self._json("GET", f"/v1/jobs/{job_id}", params={"trajectory": "false"}), job_id)
