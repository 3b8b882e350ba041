"""A job's branch of periodic orbits as one table (``GET /v1/jobs/{id}/branch?format=csv`` or ``format=netcdf``).

One row per point of the branch and of each branch switched onto, in order along each, with each located
bifurcation as a row of its own after the point it follows. Columns: ``branch`` (0 the job's, then the switched
ones in the order of their bifurcations), ``period`` (k of the return map), ``kind`` (``point`` or the
bifurcation's kind), ``index`` (the point's index along its branch; a bifurcation's: the point before it), the
continued value named after it (``energy [J]``, ``potential.a[2] [kg m^2/s^2]``), ``arclength``, ``period_t [s]``,
``period_tau``, the two section coordinates (``gamma1 [1]`` ...), ``trace``, ``stability``, each section
multiplier's ``multiplier_k_re``, ``_im`` and ``_modulus``, ``residual``, ``residual_independent`` (empty where
DOP853 was not run), ``checks_passed``, ``located`` and ``test_function`` (bifurcation rows). The client's
``branch(..., format="pandas")`` reads this CSV.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from service.exports import result_components
from service.members_table import _cell, component_header, table_variables


def _point_row(point: Mapping[str, Any], value_header: str, coordinate_headers: list[str]) -> dict[str, Any]:
    row: dict[str, Any] = {value_header: point.get("value"), "arclength": point.get("arclength"),
                           "period_t [s]": point.get("period_t"), "period_tau": point.get("period_tau")}
    for header, c in zip(coordinate_headers, point.get("coordinates") or []):
        row[header] = c
    row["trace"], row["stability"] = point.get("trace"), point.get("stability")
    for k, m in enumerate(point.get("multipliers") or []):
        for part in ("re", "im", "modulus"):
            row[f"multiplier_{k + 1}_{part}"] = m.get(part)
    row["residual"], row["residual_independent"] = point.get("residual"), point.get("residual_independent")
    row["checks_passed"] = point.get("checks_passed")
    return row


def branch_rows(branch: Mapping[str, Any], names: Mapping[str, Sequence[str]],
                units: Mapping[str, str]) -> list[dict[str, Any]]:
    """Every row of the table (see the module docstring), the switched branches after the job's; ``names`` and
    ``units``: the system's components and their vectors' units, for the section coordinates' headers."""
    value_unit = (branch.get("units") or {}).get("value")
    value_header = f"{branch['in']} [{value_unit}]" if value_unit else str(branch["in"])
    coordinate_headers = [component_header(c, names, units) for c in branch.get("coordinate_names") or []]
    rows: list[dict[str, Any]] = []
    for number, b in enumerate([branch, *(branch.get("switched") or [])]):
        after: dict[int, list[Mapping[str, Any]]] = {}
        for bif in b.get("bifurcations") or []:
            after.setdefault(int(bif["between"][0]), []).append(bif)
        for i, point in enumerate(b.get("points") or []):
            head = {"branch": number, "period": b["period"], "kind": "point", "index": i}
            rows.append({**head, **_point_row(point, value_header, coordinate_headers),
                         "located": None, "test_function": None})
            for bif in after.get(i, []):
                rows.append({**head, "kind": bif["kind"], **_point_row(bif["point"], value_header, coordinate_headers),
                             "located": bif.get("located"), "test_function": bif.get("test_function")})
    return rows


def _header(rows: list[dict[str, Any]]) -> list[str]:
    header: dict[str, None] = {}
    for row in rows:
        header.update(dict.fromkeys(row))
    return list(header)


def branch_csv(result: Mapping[str, Any], request: Mapping[str, Any]) -> Iterator[str]:
    """The table as CSV text (floats written to read back exactly)."""
    rows = branch_rows(result["periodic_orbit"]["branch"], result_components(result, request),
                       result["system"]["units"])
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    header = _header(rows)
    writer.writerow(header)
    for row in rows:
        writer.writerow([_cell(row.get(column)) for column in header])
    yield buffer.getvalue()


def branch_netcdf(job_id: str, created_at: str, result: Mapping[str, Any], request: Mapping[str, Any]) -> bytes:
    """The table as NetCDF-4: dimension ``row``, one variable per column (``units``, the header as ``long_name``),
    ``checks_passed`` and ``located`` as CF flags (1, 0, -1 for none), ``kind`` and ``stability`` as strings; the
    branch's status, reason and bifurcations (JSON) as global attributes."""
    from service.exports_netcdf import _job_attrs, write_netcdf

    branch = result["periodic_orbit"]["branch"]
    rows = branch_rows(branch, result_components(result, request), result["system"]["units"])
    variables = table_variables(rows, _header(rows), "row", {"checks_passed": "not_checked failed passed",
                                                              "located": "none no yes"})
    attrs = _job_attrs(f"{result['system'].get('title', '')}: branch of periodic orbits of job {job_id}", job_id,
                       created_at, result, request, f"GET /v1/jobs/{job_id}/branch?format=netcdf")
    attrs.update({"branch_in": str(branch["in"]), "branch_status": str(branch["status"]),
                  "branch_reason": str(branch["reason"]),
                  "bifurcations": json.dumps([{k: v for k, v in b.items() if k != "point"}
                                              for b in branch.get("bifurcations") or []])})
    coords = {"row": ("row", np.arange(len(rows), dtype=np.int64), {"long_name": "row of the table"})}
    return write_netcdf(variables, coords, attrs)
