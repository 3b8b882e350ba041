"""Ensembles: many orbits of one system, cut into chunks that workers run independently.

:func:`plan` cuts the members into contiguous chunks of about one second of work;
:func:`run_chunk` integrates one chunk's members together (heyoka's batch mode: one SIMD lane per
member, each lane with its own parameters), with the same evidence, section and spectrum as a
single job; :func:`digest` keeps what the ensemble's summary needs of each member and
:func:`summarize` reduces the digests. Pure computation: the workers only move chunks and results.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import heyoka as hy
import numpy as np

from nonholonomic.analysis.options import SectionOptions, SpectrumOptions
from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.integrals import integral_evidence_batch
from nonholonomic.initial_state import parameter_warnings
from nonholonomic.numerics import integration_batch
from nonholonomic.numerics.integration import ProgressCallback
from nonholonomic.simulation import SimulationResult, evidence, phase

#: Seconds of work one chunk aims at (the default ``chunk_size``).
CHUNK_SECONDS = 1.0
#: Estimated seconds per member and unit of physical time for a 6-dimensional system (Chaplygin's ball,
#: measured on 2 cores): the batch integration (bench/bench_ensemble.py, ~3500 trajectories of t = 100
#: per second) and the variational equations with QR every unit of time (~60 ms for t = 400).
SECONDS_PER_UNIT_TIME = 3e-6
LYAPUNOV_SECONDS_PER_UNIT_TIME = 1.5e-4
#: A chaos map's cell: the orbit with one tangent vector (~120 cells of t = 500 per second, batch mode).
INDICATOR_SECONDS_PER_UNIT_TIME = 1.7e-5
#: A section adds an event to every step.
SECTION_FACTOR = 1.5
MAX_CHUNK_SIZE = 4096
#: A member's integrals are checked at its samples and at this many equally spaced times
#: (heyoka's dense output inside ``propagate_grid``), not at every accepted step: the step log's Python
#: call per step cost about a fifth of an ensemble's time. Over bench_ensemble's 1000 members (t = 100,
#: ~200 steps each) the worst energy drift is 5.6e-15 at the check points and 5.8e-15 at the steps, the
#: median member's ratio 1.00 and the smallest 0.6 (tests/unit/test_ensemble_check_points.py). A single
#: job keeps every step.
CHECK_POINTS = 64


@dataclass(frozen=True)
class Member:
    """One member: its parameters and initial state (system order) and what sets it apart (``label``:
    e.g. ``{"parameter": "D", "value": 0.5}`` in a sweep, ``{}`` otherwise)."""

    index: int
    parameters: np.ndarray
    initial_state: np.ndarray
    label: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Chunk:
    """Members ``start .. stop − 1`` of an ensemble."""

    index: int
    start: int
    stop: int

    @property
    def size(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class MemberResult:
    """One member's outcome: ``result`` when it succeeded, ``error`` (the reason) when it failed."""

    index: int
    label: Mapping[str, Any]
    parameters: np.ndarray
    initial_state: np.ndarray
    result: SimulationResult | None = None
    error: str | None = None

    @property
    def status(self) -> str:
        return "succeeded" if self.result is not None else "failed"


def default_chunk_size(system: MechanicalSystem, t_final: float, *, poincare: SectionOptions | None = None,
                       lyapunov: SpectrumOptions | None = None, lanes: int | None = None,
                       indicators: bool = False) -> int:
    """Members per chunk for about :data:`CHUNK_SECONDS` of work, a multiple of ``lanes`` (by default
    heyoka's SIMD batch size, the lanes :func:`~nonholonomic.numerics.integration_batch.integrate_batch` fills)."""
    lanes = lanes or hy.recommended_simd_size()
    per_unit_time = SECONDS_PER_UNIT_TIME * (1 + SECTION_FACTOR * (poincare is not None))
    if lyapunov is not None:  # the orbit with its whole tangent matrix, a QR every interval
        per_unit_time += LYAPUNOV_SECONDS_PER_UNIT_TIME * max(1.0, 1.0 / lyapunov.interval)
    if indicators:
        per_unit_time = INDICATOR_SECONDS_PER_UNIT_TIME
    cost = per_unit_time * max(t_final, 1e-9) * (system.dimension / 6) ** 2
    size = int(CHUNK_SECONDS / cost)
    return max(lanes, min(MAX_CHUNK_SIZE, size - size % lanes))


def plan(count: int, chunk_size: int) -> list[Chunk]:
    """Cut ``count`` members into contiguous chunks of ``chunk_size`` (the last one may be smaller).

    Raises
    ------
    ValueError
        If ``count`` or ``chunk_size`` is below 1.
    """
    if count < 1 or chunk_size < 1:
        raise ValueError(f"need count >= 1 and chunk_size >= 1, got {count} and {chunk_size}")
    return [Chunk(i, start, min(start + chunk_size, count))
            for i, start in enumerate(range(0, count, chunk_size))]


def run_chunk(system: MechanicalSystem, members: Sequence[Member], t_final: float, samples: int, *,
              checks: Sequence[str] = ("integrals",), poincare: SectionOptions | None = None,
              lyapunov: SpectrumOptions | None = None, tolerance: float | None = None,
              parameter_groups: Mapping[str, object] | None = None,
              progress: ProgressCallback | None = None) -> list[MemberResult]:
    """Integrate ``members`` together (batch mode) and collect each one's evidence.

    A member whose integration fails (e.g. a blow-up) is a failed :class:`MemberResult` with the
    reason; the others are unaffected.

    Parameters
    ----------
    checks : evidence per member (``integrals``, ``measure``), as for :func:`~nonholonomic.simulation.simulate`.
    parameter_groups : the named parameter groups (for the warnings of unrealizable moments); members
        of a sweep differ in one of them, so the warnings are computed from each member's own vector.
    progress : ``progress(fraction) -> keep_going`` over the whole chunk; False cancels
        (:class:`~nonholonomic.numerics.integration.IntegrationCancelled` is raised).
    """
    if not members:
        return []
    P = np.array([m.parameters for m in members], dtype=float)
    Y0 = np.array([m.initial_state for m in members], dtype=float)
    parts = 1 + (poincare is not None) + (lyapunov is not None)
    trajectories = integration_batch.integrate_batch(system, P, Y0, t_final, samples, tolerance=tolerance,
                                                     check_points=CHECK_POINTS,
                                                     progress=phase(progress, 0.0, 1.0 / parts))
    done = 1
    sections: list[Any] = [None] * len(members)
    spectra: list[Any] = [None] * len(members)
    if poincare is not None:
        sections = poincare.run_batch(system, P, Y0, t_final, tolerance=tolerance,
                                      progress=phase(progress, done / parts, (done + 1) / parts))
        done += 1
    if lyapunov is not None:
        spectra = lyapunov.run_batch(system, P, Y0, t_final, tolerance=tolerance,
                                     progress=phase(progress, done / parts, 1.0))
    # the integrals' drift of every integrated member at once (one compiled function, not one call each)
    integrated = [i for i, t in enumerate(trajectories) if not isinstance(t, Exception)]
    drifts: dict[int, list[Any]] = {}
    if "integrals" in checks and integrated:
        completed = [t for t in trajectories if not isinstance(t, Exception)]  # in the order of ``integrated``
        drifts = dict(zip(integrated, integral_evidence_batch(system, P[integrated], completed)))
    out = []
    for i, (member, trajectory, section, spectrum) in enumerate(zip(members, trajectories, sections, spectra)):
        failure = next((x for x in (trajectory, section, spectrum) if isinstance(x, Exception)), None)
        if failure is not None:
            out.append(MemberResult(member.index, member.label, member.parameters, member.initial_state,
                                    error=f"{type(failure).__name__}: {failure}"))
            continue
        assert not isinstance(trajectory, Exception)  # a failed member was reported above
        derived, integrals, found = evidence(system, member.parameters, trajectory, checks, drifts.get(i, []))
        warnings = parameter_warnings(system, _groups(system, member.parameters, parameter_groups))
        result = SimulationResult(system, member.parameters, trajectory, derived, integrals, found, warnings,
                                  [], section, spectrum)
        out.append(MemberResult(member.index, member.label, member.parameters, member.initial_state, result))
    return out


def _groups(system: MechanicalSystem, p: np.ndarray, given: Mapping[str, object] | None) -> dict[str, object]:
    """The named groups of a member's parameter vector (only ``inertia`` matters for the warnings)."""
    groups: dict[str, object] = dict(given or {})
    offset = 0
    for par in system.parameters:
        if par.name == "inertia":
            groups["inertia"] = p[offset:offset + 3].tolist()
        offset += len(par.symbols)
    return groups


def digest(member: MemberResult) -> dict[str, Any]:
    """What the ensemble's summary needs of one member: status, worst integral drifts, failed checks,
    the largest Lyapunov exponent and the number of section points."""
    out: dict[str, Any] = {"index": member.index, "status": member.status}
    if member.result is None:
        out["error"] = member.error
        return out
    r = member.result
    out["integral_drift"] = {i.name: i.max_rel_drift for i in r.integrals}
    out["checks_failed"] = [c.name for c in r.checks if c.passed is False] + [
        i.name for i in r.integrals if not i.passed]
    if r.lyapunov is not None:
        out["largest_exponent"] = float(r.lyapunov.exponents[0])
    if r.poincare is not None:
        out["section_points"] = r.poincare.count
    if member.label:
        out["label"] = dict(member.label)
    return out


def summarize(digests: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Reduce member digests: counts, the worst drift of each integral, failed checks, statistics of
    the largest exponents, the section's points.

    The summary is JSON without NaN or infinity: an integral whose drift is not finite for some member
    has the worst drift None, and the exponents' statistics are over the finite ones (``non_finite``
    counts the others)."""
    ok = [d for d in digests if d["status"] == "succeeded"]
    failed = [d for d in digests if d["status"] == "failed"]
    worst: dict[str, float] = {}
    for d in ok:
        for name, drift in d.get("integral_drift", {}).items():
            worst[name] = max(worst.get(name, 0.0), drift) if math.isfinite(drift) else math.inf
    summary: dict[str, Any] = {
        "members": len(digests), "succeeded": len(ok), "failed": len(failed),
        "failures": [{"index": d["index"], "error": d.get("error")} for d in failed[:20]],
        "worst_integral_drift": {name: drift if math.isfinite(drift) else None for name, drift in worst.items()},
        "members_with_failed_checks": sum(1 for d in ok if d.get("checks_failed")),
    }
    outside = sum(1 for d in digests if d["status"] == "outside")
    if outside:
        summary["outside"] = outside  # a map's cells where no state of the level crosses the section
    exponents = np.array([d["largest_exponent"] for d in ok if "largest_exponent" in d], dtype=float)
    non_finite = int(np.count_nonzero(~np.isfinite(exponents)))
    exponents = exponents[np.isfinite(exponents)]
    if exponents.size or non_finite:
        summary["largest_exponent"] = {"count": int(exponents.size), "non_finite": non_finite}
    if exponents.size:
        summary["largest_exponent"] |= {
            "min": float(exponents.min()), "median": float(np.median(exponents)),
            "mean": float(exponents.mean()), "max": float(exponents.max()),
            "quartiles": [float(q) for q in np.quantile(exponents, [0.25, 0.5, 0.75])]}
    points = [d["section_points"] for d in ok if "section_points" in d]
    if points:
        summary["section_points"] = {"total": int(sum(points)), "min_per_member": int(min(points)),
                                     "max_per_member": int(max(points))}
    return summary
