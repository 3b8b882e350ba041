"""An ensemble's members as one table (``GET /v1/ensembles/{id}/members?format=csv`` or ``format=netcdf``), with what
sets each apart.

One row per member done, in index order: ``member``, ``status``; a sweep's value in a column named after its
parameter (``D [1]``), a chaos map cell's ``cell_i``, ``cell_j``, its two coordinates and ``branches``; then
``t_final``, ``tau_final``, ``initial_<component>`` and ``final_<component>`` (the system's own names),
``drift_<integral>``, ``checks_passed``, ``exponent_<k>``, ``section_points`` and ``error``; each header names
its unit where it has one. The same columns as the client's ``members(..., format="pandas")`` (issue 35, item 2).
"""

from __future__ import annotations

import csv
import io
import json
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import Any

import numpy as np

#: A parameter path's group: ``inertia`` of ``inertia[1]``, ``potential`` of ``potential.a[2]``.
_GROUP = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _unit_of_component(name: str, names: Mapping[str, Sequence[str]], units: Mapping[str, str]) -> str | None:
    for vector, components in names.items():
        if name in components:
            return units.get(vector)
    return None


def component_header(name: str, names: Mapping[str, Sequence[str]], units: Mapping[str, str]) -> str:
    """A component's column header with its vector's unit (``gamma1 [1]``), or its name alone."""
    unit = _unit_of_component(name, names, units)
    return f"{name} [{unit}]" if unit else name


def _label_columns(label: Mapping[str, Any] | None, names: Mapping[str, Sequence[str]],
                   units: Mapping[str, str]) -> list[tuple[str, Any]]:
    """``(header, value)`` of what sets a member apart (its ``label``)."""
    if not label:
        return []
    if "parameter" in label:
        path = str(label["parameter"])
        group = _GROUP.match(path)
        unit = units.get(group.group(0)) if group else None
        return [(f"{path} [{unit}]" if unit else path, label.get("value"))]
    out: list[tuple[str, Any]] = []
    for key, value in label.items():
        if key == "cell" and isinstance(value, (list, tuple)) and len(value) == 2:
            out += [("cell_i", value[0]), ("cell_j", value[1])]
        else:
            out.append((component_header(str(key), names, units), value))
    return out


def member_row(member: Mapping[str, Any], names: Mapping[str, Sequence[str]],
               units: Mapping[str, str]) -> list[tuple[str, Any]]:
    """One member as ``(header, value)`` pairs, in the table's column order."""
    row: list[tuple[str, Any]] = [("member", member["index"]), ("status", member.get("status"))]
    row += _label_columns(member.get("label"), names, units)
    row += [(f"t_final [{units.get('t', 's')}]", member.get("t_final")), ("tau_final", member.get("tau_final"))]
    for when in ("initial", "final"):
        for vector, values in (member.get(f"{when}_state") or {}).items():
            components = list(names.get(vector) or [f"{vector}{k + 1}" for k in range(len(values))])
            unit = units.get(vector)
            row += [(f"{when}_{c}" + (f" [{unit}]" if unit else ""), v) for c, v in zip(components, values)]
    row += [(f"drift_{i['name']}", i.get("max_rel_drift")) for i in member.get("integrals") or []]
    checks = member.get("checks") or []
    row.append(("checks_passed", all(c.get("passed") is not False for c in checks) if checks else None))
    exponents = (member.get("lyapunov") or {}).get("exponents") or []
    row += [(f"exponent_{k + 1} [1/s]", v) for k, v in enumerate(exponents)]
    if member.get("poincare") is not None:
        row.append(("section_points", member["poincare"].get("count")))
    row.append(("error", member.get("error")))
    return row


def _cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)  # reads back exactly
    return value


def _table(members: Iterable[Mapping[str, Any]], names: Mapping[str, Sequence[str]],
           units: Mapping[str, str]) -> tuple[list[dict[str, Any]], dict[str, None]]:
    """The members' rows in index order, and every column any of them has (in first-seen order)."""
    rows = [dict(member_row(m, names, units)) for m in sorted(members, key=lambda m: m["index"])]
    header: dict[str, None] = {}
    for row in rows:
        header.update(dict.fromkeys(row))
    return rows, header


def members_csv(members: Iterable[Mapping[str, Any]], names: Mapping[str, Sequence[str]],
                units: Mapping[str, str]) -> Iterator[str]:
    """The members as CSV text: the header of every column any member has (in first-seen order), then one row
    per member (an empty cell where a member has no such column: a failed member's drift)."""
    rows, header = _table(members, names, units)
    if not header:
        header = dict.fromkeys(("member", "status"))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(list(header))
    for row in rows:
        writer.writerow([_cell(row.get(column)) for column in header])
    yield buffer.getvalue()


def _header_parts(header: str) -> tuple[str, str | None]:
    """``("D", "1")`` of ``"D [1]"``; ``("status", None)`` of ``"status"``."""
    name, _, unit = header.partition(" [")
    return name, unit[:-1] if unit.endswith("]") else None


def _variable_name(name: str) -> str:
    """A NetCDF variable's name for a column: a sweep's path ``inertia[1]`` becomes ``inertia_1``."""
    return re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_") or "column"


def table_variables(rows: Sequence[Mapping[str, Any]], columns: Iterable[str], dimension: str,
                    flags: Mapping[str, str]) -> dict[str, Any]:
    """A table's columns as NetCDF variables along ``dimension``: each named after its header (``units`` and the
    header as ``long_name``); numbers as float64 (NaN where a row has none), the columns in ``flags`` as int8 CF
    flags (-1 none, 0 false, 1 true; ``flags`` gives their meanings), the rest as strings."""
    variables: dict[str, Any] = {}
    for column in columns:
        name, unit = _header_parts(column)
        values = [row.get(column) for row in rows]
        meta: dict[str, Any] = {"long_name": column, **({"units": unit} if unit else {})}
        if name in flags:
            data = np.array([-1 if v is None else int(bool(v)) for v in values], dtype=np.int8)
            meta.update(flag_values=np.array([-1, 0, 1], np.int8), flag_meanings=flags[name])
        elif all(v is None or isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            data = np.array([np.nan if v is None else float(v) for v in values], dtype=np.float64)
        else:
            data = np.array(["" if v is None else str(v) for v in values], dtype=object)
        variables[_variable_name(name)] = (dimension, data, meta)
    return variables


def members_netcdf(ensemble_id: str, record: Mapping[str, Any], members: Iterable[Mapping[str, Any]],
                   names: Mapping[str, Sequence[str]], units: Mapping[str, str]) -> bytes:
    """The members table (:func:`members_csv`'s columns) as NetCDF-4: dimension ``member`` (the coordinate, the
    member's index), one variable per column with its ``units`` and, as ``long_name``, the column's header; numbers
    as float64 (NaN where a member has none: a failed member's drift), ``checks_passed`` as int8 (1, 0, -1 for
    none: CF flags), ``status`` and ``error`` as strings. Global attributes: the conventions, the ensemble, its
    request as JSON, the paper."""
    import netCDF4
    import xarray

    from service.exports_netcdf import CONVENTIONS, REFERENCES, write_netcdf

    rows, header = _table(members, names, units)
    index = np.array([row["member"] for row in rows], dtype=np.int64)
    variables = table_variables(rows, [c for c in header if c != "member"], "member",
                                {"checks_passed": "not_checked failed passed"})
    coords = {"member": ("member", index, {"long_name": "ensemble member index"})}
    request = record["request"]
    attrs = {
        "Conventions": CONVENTIONS,
        "title": f"{request['system'].get('kind', '')}: the members of ensemble {ensemble_id}, one row each",
        "institution": "nonholonomic: a computation service for nonholonomic mechanics",
        "source": "nonholonomic (every member integrated by heyoka, see the members' integration blocks)",
        "history": f"{record.get('created_at', '')}: ensemble {ensemble_id} submitted; exported by GET /v1/ensembles/"
                   f"{ensemble_id}/members?format=netcdf (xarray {xarray.__version__}, netCDF4 {netCDF4.__version__})",
        "references": REFERENCES, "ensemble_id": ensemble_id, "system_kind": request["system"].get("kind", ""),
        "request": json.dumps(request),
    }
    return write_netcdf(variables, coords, attrs)
