"""Chaos-indicator maps: every cell of a section grid (:mod:`nonholonomic.analysis.chaos_map.grid`) integrated with
its tangent flow (:mod:`nonholonomic.analysis.chaos_map.indicators`), classified, and a random sample of cells
recomputed independently.

A cell's ``status`` is ``regular`` or ``chaotic`` by the first requested indicator against its
threshold (:func:`~nonholonomic.analysis.chaos_map.indicators.default_thresholds`), ``outside`` where no state of
the level crosses the section there, ``failed`` where the integration failed. A seeded random
:data:`CHECK_FRACTION` of the cells (at least one) is recomputed by Benettin's method, the job's
``lyapunov`` spectrum (the whole tangent matrix from ``hy.var_ode_sys``, QR every T/100, one scalar
integration): its largest exponent is compared with the cell's finite-time exponent and its verdict
(above the ``lyapunov`` threshold) with the cell's status.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nonholonomic.analysis.chaos_map import indicators
from nonholonomic.analysis.ensemble import Member
from nonholonomic.analysis.lyapunov import spectrum
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import IntegrationError, ProgressCallback
from nonholonomic.simulation import phase

#: Fraction of a map's cells recomputed independently (at least one cell).
CHECK_FRACTION = 0.01
#: Seed of the choice of the recomputed cells.
CHECK_SEED = 2024
#: QR steps of the recomputation (interval T / CHECK_QR_STEPS).
CHECK_QR_STEPS = 100


@dataclass(frozen=True)
class MapOptions:
    """What a map computes: ``indicators`` (the first sets the status), ``thresholds`` (per indicator,
    above: chaotic), the integrator tolerance and the number of cells (for the check's choice)."""

    indicators: tuple[str, ...]
    thresholds: Mapping[str, float]
    cells: int
    tolerance: float | None = None

    @property
    def primary(self) -> str:
        return self.indicators[0]


@dataclass(frozen=True)
class CellResult:
    """One cell: ``status`` (``regular``, ``chaotic``, ``outside``, ``failed``), its indicators and
    integrals' drift when integrated, the independent recomputation when it was one of the sample."""

    index: int
    label: Mapping[str, Any]
    initial_state: np.ndarray
    status: str
    values: Mapping[str, float] = field(default_factory=dict)
    integral_drift: Mapping[str, float] = field(default_factory=dict)
    steps: int = 0
    error: str | None = None
    check: Mapping[str, Any] | None = None
    drift_failed: tuple[str, ...] = ()


def checked_cells(cells: int) -> frozenset[int]:
    """The cells recomputed independently: a seeded random :data:`CHECK_FRACTION` of them (at least
    one), the same in every chunk."""
    count = max(1, int(round(CHECK_FRACTION * cells)))
    rng = np.random.default_rng(CHECK_SEED)
    return frozenset(int(k) for k in rng.choice(cells, size=min(count, cells), replace=False))


def classify(values: Mapping[str, float], options: MapOptions) -> str:
    """``chaotic`` if the first indicator is above its threshold, else ``regular``."""
    return "chaotic" if values[options.primary] > options.thresholds[options.primary] else "regular"


def run_cells(system: MechanicalSystem, members: Sequence[Member], t_final: float, options: MapOptions,
              progress: ProgressCallback | None = None) -> list[CellResult]:
    """Integrate the cells of ``members`` inside the level (batch mode), classify them, recompute the
    sampled ones; a member whose state is not finite is ``outside``."""
    inside = [m for m in members if np.all(np.isfinite(m.initial_state))]
    sample = checked_cells(options.cells)
    to_check = [m for m in inside if m.index in sample]
    share = len(inside) / (len(inside) + 10 * len(to_check)) if inside else 1.0  # a check costs ~10 cells
    found: dict[int, indicators.Indicators | IntegrationError] = {}
    if inside:
        P = np.array([m.parameters for m in inside])
        Y0 = np.array([m.initial_state for m in inside])
        found = dict(zip([m.index for m in inside],
                         indicators.run_batch(system, P, Y0, t_final, tolerance=options.tolerance,
                                              progress=phase(progress, 0.0, share), work=options.cells * t_final)))
    limit = indicators.integral_limit(options.tolerance)
    out = []
    for m in members:
        outcome = found.get(m.index)
        if outcome is None:
            out.append(CellResult(m.index, m.label, m.initial_state, "outside"))
        elif isinstance(outcome, Exception):
            out.append(CellResult(m.index, m.label, m.initial_state, "failed",
                                  error=f"{type(outcome).__name__}: {outcome}"))
        else:
            values = {name: outcome.value(name) for name in options.indicators}
            values.setdefault("lyapunov", outcome.lyapunov)
            drifted = tuple(name for name, d in outcome.integral_drift.items() if not d <= limit)
            out.append(CellResult(m.index, m.label, m.initial_state, classify(values, options), values,
                                  outcome.integral_drift, outcome.steps, drift_failed=drifted))
    by_index = {c.index: i for i, c in enumerate(out)}
    for k, m in enumerate(to_check):
        cell = out[by_index[m.index]]
        if cell.status in ("regular", "chaotic"):
            out[by_index[m.index]] = _checked(system, m, cell, t_final, options)
        if progress is not None:
            progress(share + (1 - share) * (k + 1) / len(to_check))
    return out


def _checked(system: MechanicalSystem, member: Member, cell: CellResult, t_final: float,
             options: MapOptions) -> CellResult:
    """The cell with its independent recomputation (Benettin's largest exponent)."""
    threshold = options.thresholds.get("lyapunov", indicators.default_thresholds(t_final)["lyapunov"])
    try:
        s = spectrum(system, member.parameters, member.initial_state, t_final, count=1,
                     interval=t_final / CHECK_QR_STEPS, tolerance=options.tolerance)
    except IntegrationError as exc:
        check: dict[str, Any] = {"method": "benettin", "error": str(exc)}
    else:
        exponent = float(s.exponents[0])
        status = "chaotic" if exponent > threshold else "regular"
        check = {"method": "benettin", "largest_exponent": exponent, "map_exponent": cell.values["lyapunov"],
                 "status": status, "agrees": status == cell.status}
    return CellResult(cell.index, cell.label, cell.initial_state, cell.status, cell.values, cell.integral_drift,
                      cell.steps, cell.error, check, cell.drift_failed)


def cell_digest(cell: CellResult) -> dict[str, Any]:
    """What the map's summary and images need of one cell."""
    out: dict[str, Any] = {"index": cell.index, "status": "succeeded" if cell.status in ("regular", "chaotic")
                           else cell.status, "cell_status": cell.status}
    if cell.values:
        out["indicators"] = dict(cell.values)
        out["integral_drift"] = dict(cell.integral_drift)
        out["checks_failed"] = list(cell.drift_failed)
    if cell.error:
        out["error"] = cell.error
    if cell.check is not None:
        out["check"] = dict(cell.check)
    return out


def map_summary(digests: Sequence[Mapping[str, Any]], indicators_asked: Sequence[str],
                thresholds: Mapping[str, float]) -> dict[str, Any]:
    """Counts per status, ``chaotic_fraction`` (chaotic / integrated cells), the thresholds, the
    indicators' ranges and the independent recomputation's agreement."""
    counts = {s: 0 for s in ("regular", "chaotic", "outside", "failed")}
    for d in digests:  # a chunk that failed whole stores its cells as failed members without a cell status
        counts[d.get("cell_status", "failed")] += 1
    integrated = counts["regular"] + counts["chaotic"]
    out: dict[str, Any] = {
        "cells": len(digests), **counts,
        "chaotic_fraction": counts["chaotic"] / integrated if integrated else None,
        "status_by": indicators_asked[0], "thresholds": {k: float(thresholds[k]) for k in indicators_asked},
        "indicators": {}}
    for name in indicators_asked:
        values = np.array([d["indicators"][name] for d in digests if "indicators" in d])
        if values.size:
            out["indicators"][name] = {"min": float(values.min()), "median": float(np.median(values)),
                                       "max": float(values.max())}
    checks = [d["check"] for d in digests if "check" in d and "agrees" in d["check"]]
    if checks:
        diff = [abs(c["largest_exponent"] - c["map_exponent"]) for c in checks]
        out["check"] = {"method": "Benettin's largest exponent (whole tangent matrix, QR every T/100), an independent "
                                  "scalar integration of a random 1 % of the cells, against the cell's status "
                                  "(its threshold: the lyapunov one) and finite-time exponent",
                        "cells": len(checks), "agree": sum(1 for c in checks if c["agrees"]),
                        "agreement": sum(1 for c in checks if c["agrees"]) / len(checks),
                        "exponent_difference_median": float(np.median(diff)),
                        "exponent_difference_max": float(np.max(diff))}
    return out
