"""Trajectories and Poincaré sections as NetCDF-4 files (CF-1.10 style), written with xarray.

One variable per state or derived component, named as the CSV's columns (``M1``, ``M2``, ``M3``,
``gamma1`` ...), float64, no fill value, with ``units`` and ``long_name``. A trajectory has the
dimension ``t`` (the coordinate ``t`` [s], and ``tau``, the reduced time, along it); a section has the
dimension ``crossing`` with the coordinates ``t`` and ``tau`` (and ``member``, an ensemble's member index).
Global attributes: ``Conventions``, ``title``, ``institution``, ``source`` (the service's and the
libraries' versions, the engine), ``history``, ``references`` (the paper), ``request`` (the request as
JSON), ``evidence`` (the integrals' drifts and the checks' verdicts as JSON) and a few plain facts (kind,
id, parameters). The numbers are the JSON result's, bit for bit.

xarray and netCDF4 are imported when the first file is written; the file goes through a temporary
file (netCDF4's in-memory writer pads the file to 64 KiB).
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from service.exports import component_name, point_array, result_components, section_facts, vector_components

CONVENTIONS = "CF-1.10"
REFERENCES = ('A. V. Borisov, I. S. Mamaev, "Hamiltonization of nonholonomic systems" (the equations, integrals, '
              'invariant measures and reduced times cited by number in the attributes)')
#: A plain label for t; tau's is written from the system's reduced time.
T_LONG_NAME = "physical time t"


def _describe(system_json: Mapping[str, Any]) -> dict[str, Any]:
    """long_name of every state and derived vector (its meaning, and a derived vector's formula), and
    ``tau``'s (the reduced time's formula and equation); empty where the definition cannot be read. A
    system written by the user (generalized Chaplygin, Lagrangian) names its components itself:
    ``{"q": [names], "q_dot": [names]}`` under ``components``."""
    try:
        from schemas.systems import definition_of, system_spec

        spec = system_spec(dict(system_json))
        own = spec.component_names()
        if own:  # a system written by the user: its state (q, q_dot) named by the request, no definition needed
            return {"q": "generalized coordinate", "q_dot": "generalized velocity", "components": own}
        system = definition_of(dict(system_json))
    except Exception:  # noqa: BLE001 (a label is not worth failing a download)
        return {}
    names = {v.name: v.meaning for v in system.state}
    names.update({d.name: f"{d.meaning} ({d.formula})" for d in system.derived})
    if system.reduced_time is not None:
        tau = system.reduced_time
        names["tau"] = f"reduced time tau, {tau.formula} (eq. {tau.equation}), tau(0) = 0"
    return names


def _variables(vectors: Mapping[str, Any], count: int, dim: str, units: Mapping[str, str],
               labels: Mapping[str, Any], names: Mapping[str, Sequence[str]]) -> dict[str, Any]:
    """One ``(dim,)`` float64 variable per component, named by ``names`` (``M1`` ..., a user's ``x``, ``theta``
    ...: :func:`service.exports.component_name`), with units, long_name, its vector and its number in it
    (``names``: also the components of a vector without rows)."""
    out: dict[str, Any] = {}
    for name, values in vectors.items():
        array = np.asarray(values, dtype=np.float64).reshape(count, -1 if count else len(names.get(name, ())) or 3)
        own = labels.get("components", {}).get(name, [])
        for k in range(array.shape[1]):
            called = f" {own[k]}" if k < len(own) else ""
            out[component_name(names, name, k)] = (dim, np.ascontiguousarray(array[:, k]), {
                "units": units.get(name, ""),
                "long_name": f"{labels.get(name, name)}{called}: component {k + 1} of {name}",
                "vector": name, "component": np.int32(k + 1)})
    return out


def _times(block: Mapping[str, Any], dim: str, units: Mapping[str, str], labels: Mapping[str, Any]) -> dict[str, Any]:
    coords: dict[str, Any] = {"t": (dim, np.asarray(block["t"], dtype=np.float64),
                                    {"units": units.get("t", "s"), "long_name": T_LONG_NAME})}
    if block.get("tau") is not None:
        coords["tau"] = (dim, np.asarray(block["tau"], dtype=np.float64),
                         {"units": units.get("tau", ""), "long_name": labels.get("tau", "reduced time tau")})
    return coords


def _source(result: Mapping[str, Any]) -> str:
    integration = result.get("integration") or {}
    project = integration.get("project") or {}
    versions = ", ".join(f"{k} {v}" for k, v in (integration.get("versions") or {}).items())
    service = " ".join(str(project[k]) for k in ("name", "version") if project.get(k)) or "nonholonomic"
    commit = f" (commit {project['commit']})" if project.get("commit") else ""
    engine = (f"; integrator {integration['engine']}, tolerance {integration['tolerance']!r}"
              if "engine" in integration else "")
    return f"{service}{commit}{engine}; {versions}"


def _evidence(result: Mapping[str, Any]) -> dict[str, Any]:
    """The integrals' drifts, the checks' and claims' verdicts and the section's own measures."""
    out: dict[str, Any] = {
        "integrals": [{k: i.get(k) for k in ("name", "equation", "max_abs_drift", "max_rel_drift", "tolerance",
                                             "passed")} for i in result.get("integrals") or []],
        "checks": [{k: c.get(k) for k in ("name", "equation", "method", "residual", "tolerance", "passed")}
                   for c in result.get("checks") or []],
    }
    if result.get("claims"):
        out["claims"] = [{k: c.get(k) for k in ("name", "expression", "max_rel_drift", "tolerance", "passed")}
                         for c in result["claims"]]
    section = result.get("poincare")
    if section:
        out["poincare"] = {k: section.get(k) for k in ("count", "surface_residual_max", "integral_drift_max",
                                                       "stopped_early")}
    spectrum = result.get("lyapunov")
    if spectrum:
        out["lyapunov"] = {k: spectrum.get(k) for k in ("exponents", "sum", "sum_expected", "measure_consistent")}
    return out


def _system_attrs(system: Mapping[str, Any]) -> dict[str, Any]:
    return {"system_kind": system.get("kind", ""), "system_title": system.get("title", ""),
            "system_equation": system.get("equation", ""), "potential": system.get("potential_formula", ""),
            "parameters": json.dumps(system.get("parameters", {})), "units": json.dumps(system.get("units", {}))}


def _job_attrs(title: str, job_id: str, created_at: str, result: Mapping[str, Any], request: Mapping[str, Any],
               route: str) -> dict[str, Any]:
    import netCDF4
    import xarray

    return {
        "Conventions": CONVENTIONS, "title": title,
        "institution": "nonholonomic: a computation service for nonholonomic mechanics",
        "source": _source(result),
        "history": f"{created_at}: job {job_id} submitted; computed as the source says; exported by {route} "
                   f"(xarray {xarray.__version__}, netCDF4 {netCDF4.__version__})",
        "references": REFERENCES, "job_id": job_id, **_system_attrs(result["system"]),
        "request": json.dumps(request), "evidence": json.dumps(_evidence(result)),
        "warnings": "\n".join(result.get("warnings") or []),
    }


def _section_attrs(section: Mapping[str, Any]) -> dict[str, Any]:
    facts = section_facts(section)
    return {"surface": str(facts.get("surface", "")), "surface_value": float(facts.get("value", 0.0)),
            "direction": str(facts.get("direction", "")),
            "coordinate_names": " ".join(facts.get("coordinate_names") or []),
            "section": json.dumps(facts)}


def write_netcdf(variables: dict[str, Any], coords: dict[str, Any], attrs: dict[str, Any]) -> bytes:
    """The NetCDF-4 file of the variables (no fill values: the numbers as they are)."""
    import xarray

    dataset = xarray.Dataset(variables, coords=coords, attrs=attrs)
    encoding = {name: {"_FillValue": None} for name in [*variables, *coords]}
    with tempfile.TemporaryDirectory(prefix="nonholonomic-netcdf-") as folder:
        path = os.path.join(folder, "export.nc")
        dataset.to_netcdf(path, engine="netcdf4", format="NETCDF4", encoding=encoding)
        with open(path, "rb") as file:
            return file.read()


def trajectory_netcdf(job_id: str, created_at: str, result: Mapping[str, Any], request: Mapping[str, Any]) -> bytes:
    """A job's sampled trajectory as NetCDF-4 (dimension ``t``)."""
    trajectory = result["trajectory"]
    units = result["system"]["units"]
    labels = _describe(request["system"])
    vectors = {k: v for k, v in trajectory.items() if k not in ("t", "tau")}
    attrs = _job_attrs(f"{result['system'].get('title', '')}: trajectory of job {job_id}", job_id, created_at,
                       result, request, f"GET /v1/jobs/{job_id}/trajectory?format=netcdf")
    names = result_components(result, request)
    return write_netcdf(_variables(vectors, len(trajectory["t"]), "t", units, labels, names),
                        _times(trajectory, "t", units, labels), attrs)


def section_netcdf(job_id: str, created_at: str, result: Mapping[str, Any], request: Mapping[str, Any]) -> bytes:
    """A job's Poincaré crossings as NetCDF-4 (dimension ``crossing``, coordinates ``t`` and ``tau``)."""
    section = result["poincare"]
    units = result["system"]["units"]
    labels = _describe(request["system"])
    attrs = _job_attrs(f"{result['system'].get('title', '')}: Poincare section of job {job_id}", job_id, created_at,
                       result, request, f"GET /v1/jobs/{job_id}/section?format=netcdf")
    names = result_components(result, request)
    return write_netcdf(_variables(section["points"], len(section["t"]), "crossing", units, labels, names),
                        _times(section, "crossing", units, labels), {**attrs, **_section_attrs(section)})


def ensemble_section_netcdf(ensemble_id: str, record: Mapping[str, Any], summary: Mapping[str, Any] | None,
                            members: Iterable[tuple[int, dict[str, Any]]], units: Mapping[str, str]) -> bytes:
    """Every member's crossings as NetCDF-4 (dimension ``crossing``; coordinates ``member``, ``t``, ``tau``),
    the members in index order, each member's crossings in time order."""
    import netCDF4
    import xarray

    parts: dict[str, list[np.ndarray]] = {"member": [], "t": []}
    has_tau = True
    first: dict[str, Any] | None = None
    names = vector_components(record["request"]["system"])
    for index, section in members:
        count = len(section["t"])
        first = first or section
        parts["member"].append(np.full(count, index, dtype=np.int64))
        parts["t"].append(np.asarray(section["t"], dtype=np.float64))
        if section.get("tau") is None:
            has_tau = False
        else:
            parts.setdefault("tau", []).append(np.asarray(section["tau"], dtype=np.float64))
        for name, values in section["points"].items():
            parts.setdefault(name, []).append(point_array(values, count, len(names[name])))
    joined = {k: np.concatenate(v) if v else np.zeros(0) for k, v in parts.items()}
    request = record["request"]
    labels = _describe(request["system"])
    count = len(joined["t"])
    vectors = {k: v for k, v in joined.items() if k not in ("member", "t", "tau")}
    coords = _times({"t": joined["t"], "tau": joined.get("tau") if has_tau and first else None}, "crossing", units,
                    labels)
    coords["member"] = ("crossing", joined["member"].astype(np.int64), {"long_name": "ensemble member index"})
    attrs = {
        "Conventions": CONVENTIONS,
        "title": f"{request['system'].get('kind', '')}: Poincare sections of the members of ensemble {ensemble_id}",
        "institution": "nonholonomic: a computation service for nonholonomic mechanics",
        "source": "nonholonomic (every member integrated by heyoka, see the members' integration blocks)",
        "history": f"{record.get('created_at', '')}: ensemble {ensemble_id} submitted; exported by GET /v1/ensembles/"
                   f"{ensemble_id}/poincare?format=netcdf (xarray {xarray.__version__}, netCDF4 "
                   f"{netCDF4.__version__})",
        "references": REFERENCES, "ensemble_id": ensemble_id, "system_kind": request["system"].get("kind", ""),
        "units": json.dumps(dict(units)), "request": json.dumps(request),
        "evidence": json.dumps({"summary": summary}),
        "members_with_crossings": np.int64(sum(1 for m in parts["member"] if len(m))),
        **({} if first is None else {k: v for k, v in _section_attrs(first).items() if k != "section"}),
    }
    return write_netcdf(_variables(vectors, count, "crossing", units, labels, names), coords, attrs)
