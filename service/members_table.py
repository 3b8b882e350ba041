"""An ensemble's members as one table (``GET /v1/ensembles/{id}/members?format=csv``), with what sets each apart.

One row per member done, in index order: ``member``, ``status``; a sweep's value in a column named after its
parameter (``D [1]``), a chaos map cell's ``cell_i``, ``cell_j``, its two coordinates and ``branches``; then
``t_final``, ``tau_final``, ``initial_<component>`` and ``final_<component>`` (the system's own names),
``drift_<integral>``, ``checks_passed``, ``exponent_<k>``, ``section_points`` and ``error``; each header names
its unit where it has one. The same columns as the client's ``members(..., format="pandas")`` (issue 35, item 2).
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from typing import Any

#: A parameter path's group: ``inertia`` of ``inertia[1]``, ``potential`` of ``potential.a[2]``.
_GROUP = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _unit_of_component(name: str, names: Mapping[str, Sequence[str]], units: Mapping[str, str]) -> str | None:
    for vector, components in names.items():
        if name in components:
            return units.get(vector)
    return None


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
            unit = _unit_of_component(str(key), names, units)
            out.append((f"{key} [{unit}]" if unit else str(key), value))
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


def members_csv(members: Iterable[Mapping[str, Any]], names: Mapping[str, Sequence[str]],
                units: Mapping[str, str]) -> Iterator[str]:
    """The members as CSV text: the header of every column any member has (in first-seen order), then one row
    per member (an empty cell where a member has no such column: a failed member's drift)."""
    rows = [dict(member_row(m, names, units)) for m in sorted(members, key=lambda m: m["index"])]
    header: dict[str, None] = {}
    for row in rows:
        header.update(dict.fromkeys(row))
    if not header:
        header = dict.fromkeys(("member", "status"))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(list(header))
    for row in rows:
        writer.writerow([_cell(row.get(column)) for column in header])
    yield buffer.getvalue()
