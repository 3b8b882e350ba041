"""A chaos map's exports (``GET /v1/ensembles/{id}/map``): one row or grid point per cell, as CSV (a header
row naming each column and its unit), JSON (2-D arrays, rows along the first coordinate) or NetCDF-4
(dimensions the two coordinates; the status as CF flags). The numbers are the members' JSON, bit for bit.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import numpy as np

from schemas.chaos_maps import INDICATOR_WORDS, STATUS_CODES, MapArrays, map_arrays
from service.ensembles import request_units
from service.exports_netcdf import CONVENTIONS, REFERENCES, write_netcdf

_WORDS = {code: word for word, code in STATUS_CODES.items()}


def arrays_of(record: Mapping[str, Any], members: Iterable[Mapping[str, Any]]) -> MapArrays:
    request = record["request"]
    return map_arrays(request, members, request["members"]["grid"]["ranges"])


def _unit(units: Mapping[str, str], name: str) -> str:
    vector = name.rstrip("0123456789")
    return units.get(name, units.get(vector, "1"))


def map_csv(record: Mapping[str, Any], members: Iterable[Mapping[str, Any]]) -> Iterator[str]:
    """One row per cell: i, j, the two coordinates, status, branches, each indicator, each integral's drift."""
    a = arrays_of(record, members)
    units = request_units(record["request"])
    names = list(a.values)
    drifts = sorted(a.drift)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["i", "j", *(f"{c} [{_unit(units, c)}]" for c in a.coordinates), "status", "branches",
                     *(f"{n} [{INDICATOR_WORDS[n][1]}]" for n in names), *(f"drift_{d} [1]" for d in drifts)])
    yield buffer.getvalue()
    for i in range(a.status.shape[0]):
        buffer.seek(0)
        buffer.truncate()
        for j in range(a.status.shape[1]):
            writer.writerow([i, j, repr(float(a.axes[0][i])), repr(float(a.axes[1][j])), _WORDS[int(a.status[i, j])],
                             int(a.branches[i, j]),
                             *(_number(a.values[n][i, j]) for n in names),
                             *(_number(a.drift[d][i, j]) for d in drifts)])
        yield buffer.getvalue()


def _number(value: float) -> str:
    return repr(float(value)) if np.isfinite(value) else ""


def map_json(record: Mapping[str, Any], members: Iterable[Mapping[str, Any]],
             summary: Mapping[str, Any] | None) -> dict[str, Any]:
    """The map as 2-D arrays (``[i][j]``, i along the first coordinate; null where not integrated)."""
    a = arrays_of(record, members)
    units = request_units(record["request"])

    def grid(values: np.ndarray) -> list[list[float | None]]:
        return [[float(v) if np.isfinite(v) else None for v in row] for row in values]

    return {"coordinates": list(a.coordinates), "units": {c: _unit(units, c) for c in a.coordinates},
            "axes": [a.axes[0].tolist(), a.axes[1].tolist()],
            "status": [[_WORDS[int(v)] for v in row] for row in a.status],
            "branches": a.branches.tolist(),
            "indicators": {n: grid(v) for n, v in a.values.items()},
            "integral_drift": {n: grid(v) for n, v in a.drift.items()},
            "summary": (summary or {}).get("map")}


def map_netcdf(ensemble_id: str, record: Mapping[str, Any], members: Iterable[Mapping[str, Any]],
               summary: Mapping[str, Any] | None) -> bytes:
    """The map as NetCDF-4: dimensions the two coordinates, ``status`` (CF flags), each indicator, each
    integral's drift, ``branches``; the request and the summary as JSON attributes."""
    import netCDF4
    import xarray

    a = arrays_of(record, members)
    request = record["request"]
    units = request_units(request)
    dims = a.coordinates
    coords = {c: (c, a.axes[k], {"units": _unit(units, c), "long_name": f"{c} at the cell's centre"})
              for k, c in enumerate(dims)}
    variables: dict[str, Any] = {
        "status": (dims, a.status, {"long_name": "cell status", "flag_values": np.array(sorted(_WORDS), np.int8),
                                    "flag_meanings": " ".join(_WORDS[k] for k in sorted(_WORDS))}),
        "branches": (dims, a.branches, {"long_name": "states of the level crossing the section at the cell"}),
    }
    for name, values in a.values.items():
        word, unit, meaning = INDICATOR_WORDS[name]
        variables[name] = (dims, values, {"units": unit, "long_name": f"{word}: {meaning}"})
    for name, values in a.drift.items():
        variables[f"drift_{name}"] = (dims, values, {"units": "1", "long_name": f"largest relative drift of {name}"})
    grid = request["members"]["grid"]
    attrs = {
        "Conventions": CONVENTIONS,
        "title": f"{request['system'].get('kind', '')}: chaos map of ensemble {ensemble_id} on {grid['surface']} = "
                 f"{grid['value']:g}",
        "institution": "nonholonomic: a computation service for nonholonomic mechanics",
        "source": "nonholonomic (each cell's tangent flow integrated by heyoka)",
        "history": f"{record.get('created_at', '')}: ensemble {ensemble_id} submitted; exported by GET /v1/ensembles/"
                   f"{ensemble_id}/map?format=netcdf (xarray {xarray.__version__}, netCDF4 {netCDF4.__version__})",
        "references": REFERENCES, "ensemble_id": ensemble_id, "request": json.dumps(request),
        "summary": json.dumps((summary or {}).get("map")), "t_final": float(request["t_final"]),
    }
    return write_netcdf(variables, coords, attrs)
