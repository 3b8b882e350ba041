"""A chaos map's cells as JSON (an ensemble member each) and the map as arrays (the exports read them)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from nonholonomic.analysis.chaos_map import CellResult
from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import vector_slice

#: What each indicator is, for labels and units.
INDICATOR_WORDS = {
    "megno": ("MEGNO <Y>", "1", "mean exponential growth of nearby orbits (Cincotta & Simo 2000): 2 on a torus, "
                                "~ lambda T / 2 in chaos"),
    "fli": ("FLI", "1", "fast Lyapunov indicator (Froeschle, Lega & Gonczi 1997): max over t <= T of ln |w(t)|, "
                        "|w(0)| = 1"),
    "lyapunov": ("finite-time largest Lyapunov exponent", "1/s", "ln |w(T)| / T"),
}
#: Status codes of the exports (CSV and NetCDF keep both the code and the word).
STATUS_CODES = {"outside": 0, "regular": 1, "chaotic": 2, "failed": 3}


def cell_to_json(system: MechanicalSystem, cell: CellResult) -> dict[str, Any]:
    """One cell as an ensemble member: index, label (cell, coordinates, branches), status, initial state
    by vector (integrated cells), and ``cell`` (status, indicators, integrals' drift, check)."""
    member_status = {"regular": "succeeded", "chaotic": "succeeded"}.get(cell.status, cell.status)
    out: dict[str, Any] = {"index": cell.index, "status": member_status, "label": dict(cell.label)}
    if np.all(np.isfinite(cell.initial_state)):
        out["initial_state"] = {vec.name: cell.initial_state[vector_slice(system, vec.name)].tolist()
                                for vec in system.state}
    block: dict[str, Any] = {"status": cell.status}
    if cell.values:
        block["indicators"] = dict(cell.values)
        block["integral_drift"] = dict(cell.integral_drift)
        block["integrals_failed"] = list(cell.drift_failed)
        block["steps"] = cell.steps
    if cell.check is not None:
        block["check"] = dict(cell.check)
    if cell.error:
        out["error"] = block["error"] = cell.error
    out["cell"] = block
    return out


@dataclass(frozen=True)
class MapArrays:
    """The map on its grid: ``axes`` (cell centres per coordinate), ``status`` (codes, shape ``shape``),
    each indicator's values (NaN where not integrated), the largest drift of each integral per cell."""

    coordinates: tuple[str, str]
    axes: tuple[np.ndarray, np.ndarray]
    status: np.ndarray
    values: dict[str, np.ndarray]
    drift: dict[str, np.ndarray]
    branches: np.ndarray


def map_arrays(request: Mapping[str, Any], members: Iterable[Mapping[str, Any]], ranges: Any) -> MapArrays:
    """Arrays of the map from its member JSON (cells of unfinished chunks stay ``outside`` with NaN
    values; ``ranges``: the grid's resolved ranges)."""
    grid = request["members"]["grid"]
    shape = tuple(grid["shape"])
    names = tuple(grid["coordinates"])
    axes = tuple(lo + (np.arange(n) + 0.5) * (hi - lo) / n for (lo, hi), n in zip(ranges, shape))
    status = np.full(shape, STATUS_CODES["outside"], dtype=np.int8)
    branches = np.zeros(shape, dtype=np.int8)
    values = {name: np.full(shape, np.nan) for name in request["indicators"]}
    drift: dict[str, np.ndarray] = {}
    for m in members:  # a chunk that failed whole stores its cells with index, status and error only
        i, j = divmod(int(m["index"]), shape[1])
        block = m.get("cell", {})
        status[i, j] = STATUS_CODES[block.get("status", "failed")]
        branches[i, j] = (m.get("label") or {}).get("branches", 0)
        for name, v in block.get("indicators", {}).items():
            if name in values:
                values[name][i, j] = v
        for name, v in block.get("integral_drift", {}).items():
            drift.setdefault(name, np.full(shape, np.nan))[i, j] = v
    return MapArrays(names, axes, status, values, drift, branches)
