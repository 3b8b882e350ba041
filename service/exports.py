"""A job's sampled trajectory as a file: CSV (one header row naming each column and its unit, t and
τ first) streamed row by row, or NPZ (the arrays, with the request and the library versions as JSON)."""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterator
from typing import Any

import numpy as np

#: CSV rows written per streamed piece.
ROWS_PER_PIECE = 2000


def _vectors(trajectory: dict[str, Any]) -> list[str]:
    return [k for k in trajectory if k not in ("t", "tau")]


def trajectory_columns(result: dict[str, Any]) -> list[tuple[str, str, int | None]]:
    """(header ``name [unit]``, trajectory key, component or None) for t, τ and every vector's components."""
    units = result["system"]["units"]
    trajectory = result["trajectory"]
    cols: list[tuple[str, str, int | None]] = [(f"t [{units.get('t', 's')}]", "t", None)]
    if trajectory.get("tau") is not None:
        cols.append((f"tau [{units.get('tau', '')}]", "tau", None))
    for name in _vectors(trajectory):
        width = len(trajectory[name][0]) if trajectory[name] else 3
        cols += [(f"{name}{k + 1} [{units.get(name, '')}]", name, k) for k in range(width)]
    return cols


def trajectory_csv(result: dict[str, Any]) -> Iterator[str]:
    """The samples as CSV, a piece of :data:`ROWS_PER_PIECE` rows at a time (floats in full precision)."""
    cols = trajectory_columns(result)
    trajectory = result["trajectory"]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([c[0] for c in cols])
    for row in range(len(trajectory["t"])):
        writer.writerow([repr(float(trajectory[key][row] if k is None else trajectory[key][row][k]))
                         for _, key, k in cols])
        if (row + 1) % ROWS_PER_PIECE == 0:
            yield buffer.getvalue()
            buffer.seek(0)
            buffer.truncate()
    yield buffer.getvalue()


def trajectory_npz(result: dict[str, Any], request: dict[str, Any]) -> bytes:
    """The samples as NPZ: ``t``, ``tau`` (when the system has one), each vector ``(n, 3)``, ``units_json``,
    ``request_json`` and ``versions_json`` (0-d strings)."""
    trajectory = result["trajectory"]
    arrays = {"t": np.asarray(trajectory["t"], dtype=float)}
    if trajectory.get("tau") is not None:
        arrays["tau"] = np.asarray(trajectory["tau"], dtype=float)
    arrays.update({name: np.asarray(trajectory[name], dtype=float) for name in _vectors(trajectory)})
    buffer = io.BytesIO()
    np.savez(buffer, **arrays, units_json=np.array(json.dumps(result["system"]["units"])),
             request_json=np.array(json.dumps(request)),
             versions_json=np.array(json.dumps(result["integration"]["versions"])))
    return buffer.getvalue()
