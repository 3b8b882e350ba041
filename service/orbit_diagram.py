"""A sweep ensemble's orbit diagram: every member's section points against the swept parameter, as a table
(``GET /v1/ensembles/{id}/orbit-diagram?format=csv|json``) and as a plot (``.../plots/orbit_diagram.png``).

One row per crossing: ``member``, the swept value named after its parameter with its unit (``D [kg m^2]``),
``crossing`` (its number along the member's orbit), the section's two coordinates (``gamma1 [1]``, ``M3 ...``).
A periodic orbit of period k shows as k points above its value, a torus as a segment, chaos as a smear: the
same picture as the logistic map's, for a conservative flow."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Iterator, Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from schemas.sweeps import PATH as SWEEP_PATH
from service.exports import vector_components
from service.members_table import component_header
from service.plots import (
    MAX_SECTION_POINTS,
    PlotUnavailable,
    _axis_label,
    _headline,
    _new_figure,
    _thin,
)


class NoOrbitDiagram(ValueError):
    """The ensemble is not a sweep with a section."""


def sweep_of(request: Mapping[str, Any]) -> tuple[str, list[float]]:
    """The swept parameter and its values.

    Raises
    ------
    NoOrbitDiagram
        If the ensemble is not a sweep, or asked for no section.
    """
    sweep = (request.get("members") or {}).get("sweep")
    if not sweep or not request.get("poincare"):
        raise NoOrbitDiagram("an orbit diagram is a sweep's section points: this ensemble is "
                             + ("not a sweep (members.sweep)" if not sweep else "a sweep without a poincare section"))
    return str(sweep["parameter"]), [float(v) for v in sweep["values"]]


def _value_header(parameter: str, units: Mapping[str, str]) -> str:
    group = SWEEP_PATH.match(parameter.strip())
    unit = units.get(group.group(1)) if group else None
    return f"{parameter} [{unit}]" if unit else parameter


def diagram_rows(request: Mapping[str, Any], members: Iterable[tuple[int, Mapping[str, Any]]],
                 units: Mapping[str, str]) -> tuple[list[str], dict[str, list[Any]]]:
    """The table's headers and columns from (member index, its ``poincare`` block) pairs in index order."""
    parameter, values = sweep_of(request)
    names: list[str] = []
    columns: dict[str, list[Any]] = {"member": [], "value": [], "crossing": [], "c0": [], "c1": []}
    for index, section in members:
        names = names or list(section.get("coordinate_names") or ["coordinate 1", "coordinate 2"])
        points = np.asarray(section.get("coordinates") or [], dtype=float).reshape(-1, 2)
        columns["member"] += [index] * len(points)
        columns["value"] += [values[index]] * len(points)
        columns["crossing"] += list(range(1, len(points) + 1))
        columns["c0"] += points[:, 0].tolist()
        columns["c1"] += points[:, 1].tolist()
    names = names or [str(c) for c in (request.get("poincare") or {}).get("coordinates") or ["c0", "c1"]]
    components = vector_components(request["system"])
    headers = ["member", _value_header(parameter, units), "crossing",
               *(component_header(n, components, units) for n in names)]
    return headers, columns


def diagram_csv(request: Mapping[str, Any], members: Iterable[tuple[int, Mapping[str, Any]]],
                units: Mapping[str, str]) -> Iterator[str]:
    """The table as CSV (floats written to read back exactly)."""
    headers, columns = diagram_rows(request, members, units)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(headers)
    for row in zip(*(columns[k] for k in ("member", "value", "crossing", "c0", "c1"))):
        writer.writerow([row[0], repr(row[1]), row[2], repr(row[3]), repr(row[4])])
    yield buffer.getvalue()


def diagram_json(request: Mapping[str, Any], members: Iterable[tuple[int, Mapping[str, Any]]],
                 units: Mapping[str, str]) -> dict[str, Any]:
    """The table as JSON: the parameter, the coordinates' names, the headers and one array per column."""
    headers, columns = diagram_rows(request, members, units)
    parameter, _ = sweep_of(request)
    return {"parameter": parameter, "headers": headers, "member": columns["member"], "value": columns["value"],
            "crossing": columns["crossing"], "coordinates": [columns["c0"], columns["c1"]]}


def orbit_diagram_figure(view: Mapping[str, Any], members: Iterable[Mapping[str, Any]]) -> Figure:
    """Each section coordinate against the swept value, one small dot per crossing."""
    from service.plot_ensemble import _ensemble_system

    try:
        parameter, _ = sweep_of(view["request"])
    except NoOrbitDiagram as exc:
        raise PlotUnavailable(str(exc)) from None
    info, units = _ensemble_system(view)
    pairs = [(int(m["index"]), m["poincare"]) for m in members if m.get("poincare")]
    if not pairs:
        raise PlotUnavailable("no member has section points yet")
    headers, columns = diagram_rows(view["request"], sorted(pairs, key=lambda p: p[0]), units)
    value = np.asarray(columns["value"], dtype=float)
    keep = _thin(len(value), MAX_SECTION_POINTS)
    fig = _new_figure(12.0, 5.0)
    names = list(pairs[0][1].get("coordinate_names") or ["", ""])
    for k, key in enumerate(("c0", "c1")):
        ax = fig.add_subplot(1, 2, k + 1)
        ax.scatter(value[keep], np.asarray(columns[key], dtype=float)[keep], s=1.5, color="C0", linewidths=0,
                   rasterized=True)
        ax.set_xlabel(headers[1])
        ax.set_ylabel(_axis_label(names[k], units))
        ax.grid(alpha=0.3)
    section = view["request"]["poincare"]
    fig.suptitle(_headline(info, f"orbit diagram: the crossings of {section['surface']} = "
                                 f"{section.get('value', 0.0):g} of {len(pairs)} members against {parameter} "
                                 f"({len(value)} points)"))
    return fig
