"""Continuation of a periodic orbit in one parameter, with its bifurcations flagged.

Natural-parameter continuation: at each value of the swept parameter, in the order given, Newton
(:func:`nonholonomic.analysis.periodic_orbit.refine`) starts from the previous value's orbit (its state
and period; the level is that state's under the new parameters). Between two consecutive closed orbits,
a section multiplier passing through +1 or −1 changes the sign of

    P(+1) = Π (1 − μ_i)    or    P(−1) = Π (−1 − μ_i)

over the section multipliers μ_i (the characteristic polynomial of the section map's linearisation at
±1; for a measure-preserving map with multipliers λ, 1/λ: 2 − trace and 2 + trace). The first is a
``fold`` (saddle-node, or a pitchfork where a symmetry makes it one), the second a ``period_doubling``.
A value where Newton no longer closes the orbit ends the branch (``lost``): past a fold the branch turns
back in the parameter, or the step was too large.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from nonholonomic.analysis.periodic_orbit import PeriodicOrbit, refine
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import IntegrationError


@dataclass(frozen=True)
class BranchEvent:
    """A bifurcation or the branch's end between two consecutive parameter values."""

    kind: str          # fold | period_doubling | lost
    between: tuple[float, float]
    detail: str


@dataclass(frozen=True)
class Branch:
    """The orbit at each parameter value reached (``values[i]`` ↔ ``orbits[i]``) and the events."""

    parameter: str
    values: tuple[float, ...]
    orbits: tuple[PeriodicOrbit, ...]
    events: tuple[BranchEvent, ...]
    skipped: tuple[float, ...]


def characteristic_signs(section_mu: np.ndarray) -> tuple[float, float]:
    """P(+1) and P(−1) of the section multipliers (real: complex ones come in conjugate pairs)."""
    return float(np.prod(1.0 - section_mu).real), float(np.prod(-1.0 - section_mu).real)


def continue_orbit(system: MechanicalSystem, start: PeriodicOrbit, parameter: str, values: Sequence[float],
                   parameter_vectors: Sequence[np.ndarray], *, tolerance: float,
                   progress: Callable[[float], bool] | None = None) -> Branch:
    """Follow ``start`` (closed) through ``parameter_vectors`` (one per entry of ``values``, in order).

    Parameters
    ----------
    start : the orbit at the job's own parameters.
    parameter : the swept parameter's name (for the messages).
    values, parameter_vectors : the parameter's values and the whole parameter vector at each.
    progress : called with the fraction of values done; False cancels.
    """
    orbits: list[PeriodicOrbit] = []
    events: list[BranchEvent] = []
    previous, previous_value = start, None
    for i, (value, p) in enumerate(zip(values, parameter_vectors)):
        part = None if progress is None else (lambda f, i=i: progress((i + f) / len(values)))
        try:
            orbit = refine(system, np.asarray(p, dtype=float), previous.initial_state, previous.period_t,
                           previous.surface, value=previous.value, direction=previous.direction,
                           period=previous.period, level=tuple(previous.level), tolerance=tolerance,
                           coordinates=previous.coordinate_names or None, progress=part)
        except IntegrationError as exc:
            orbit = PeriodicOrbit("not_found", f"the integration failed: {exc}", previous.surface, previous.value,
                                  previous.direction, previous.period, previous.level, previous.initial_state,
                                  previous.period_t)
        orbits.append(orbit)
        span = (previous_value if previous_value is not None else float("nan"), float(value))
        if orbit.status == "not_found":
            events.append(BranchEvent("lost", span, f"Newton did not close the orbit at {parameter} = {value:g} "
                                                    f"({orbit.reason}); past a fold the branch turns back in "
                                                    f"{parameter}, or the step from the last value was too large"))
            return Branch(parameter, tuple(values[: i + 1]), tuple(orbits), tuple(events), tuple(values[i + 1:]))
        if previous_value is not None and previous.status == "found" and orbit.status == "found":
            events.extend(_crossed(previous, orbit, span, parameter))
        previous, previous_value = orbit, float(value)
    return Branch(parameter, tuple(values), tuple(orbits), tuple(events), ())


def _crossed(a: PeriodicOrbit, b: PeriodicOrbit, span: tuple[float, float], parameter: str) -> list[BranchEvent]:
    """The multipliers' passages through ±1 between two consecutive orbits."""
    if len(a.section_multipliers) != len(b.section_multipliers) or len(a.section_multipliers) == 0:
        return []
    plus_a, minus_a = characteristic_signs(a.section_multipliers)
    plus_b, minus_b = characteristic_signs(b.section_multipliers)
    found = []
    where = f"{parameter} between {span[0]:g} and {span[1]:g}"
    if plus_a * plus_b < 0:
        found.append(BranchEvent("fold", span, f"a section multiplier passes through +1 ({where}; trace "
                                               f"{a.trace:.6g} -> {b.trace:.6g}): a fold (saddle-node), or a "
                                               "pitchfork where a symmetry forces one"))
    if minus_a * minus_b < 0:
        found.append(BranchEvent("period_doubling", span, f"a section multiplier passes through -1 ({where}; trace "
                                                          f"{a.trace:.6g} -> {b.trace:.6g}): a period-doubling "
                                                          f"bifurcation, a period-{2 * a.period} orbit is born "
                                                          "or dies"))
    return found
