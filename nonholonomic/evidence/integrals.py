"""First integrals evaluated along a trajectory: initial, final and the largest drift (one trajectory,
or many of one system at once)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from functools import lru_cache

import heyoka as hy
import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.integration import Trajectory
from nonholonomic.kernels import numeric, parameter_vector
from nonholonomic.taylor import TaylorSystem, taylor_system

#: The verdict's tolerance on the relative drift never goes below this.
INTEGRAL_TOLERANCE_FLOOR = 1e-10
#: ...and is this many integrator tolerances above a looser integrator tolerance.
INTEGRAL_TOLERANCE_FACTOR = 1e4


def integral_tolerance(integrator_tolerance: float) -> float:
    """Tolerance on an integral's relative drift: ``max(1e-10, 1e4 · integrator tolerance)``."""
    return max(INTEGRAL_TOLERANCE_FLOOR, INTEGRAL_TOLERANCE_FACTOR * integrator_tolerance)


@dataclass(frozen=True)
class IntegralEvidence:
    """One first integral along a trajectory.

    ``max_rel_drift = max_abs_drift / reference`` with ``reference = max(|initial|, scale)``, where
    ``scale`` is the largest natural size of the integral along the trajectory (e.g. ``|M||γ|`` for
    ``c = (M, γ)``), so that an integral whose value is zero still gets a meaningful relative drift.
    """

    name: str
    formula: str
    equation: str
    initial: float
    final: float
    max_abs_drift: float
    max_rel_drift: float
    reference: float
    evaluated_at: int
    tolerance: float
    passed: bool


def integral_evidence(system: MechanicalSystem, parameters: np.ndarray, trajectory: Trajectory,
                      tolerance: float | None = None) -> list[IntegralEvidence]:
    """Evaluate every integral of ``system`` at the samples and at every accepted step.

    Parameters
    ----------
    tolerance : bound on ``max_rel_drift`` for the verdict; by default
        :func:`integral_tolerance` of the trajectory's integrator tolerance.
    """
    if not system.integrals:
        return []
    kernels = numeric(system)
    tol = integral_tolerance(trajectory.tolerance) if tolerance is None else tolerance
    points = np.vstack([trajectory.states, trajectory.step_states])
    values = kernels.integrals(points, parameters)
    initial = values[0]
    final = values[len(trajectory.t) - 1]
    scale = np.max(np.abs(kernels.integral_scales(points, parameters)), axis=0)
    reference = np.maximum(np.abs(initial), scale)
    reference = np.where(reference > 0, reference, 1.0)
    abs_drift = np.max(np.abs(values - initial), axis=0)
    rel_drift = abs_drift / reference
    return [
        IntegralEvidence(
            name=claim.name, formula=claim.formula, equation=claim.equation,
            initial=float(initial[i]), final=float(final[i]),
            max_abs_drift=float(abs_drift[i]), max_rel_drift=float(rel_drift[i]),
            reference=float(reference[i]), evaluated_at=len(points), tolerance=tol,
            passed=bool(np.isfinite(rel_drift[i]) and rel_drift[i] <= tol),
        )
        for i, claim in enumerate(system.integrals)
    ]


def integral_evidence_batch(system: MechanicalSystem, parameters: np.ndarray, trajectories: Sequence[Trajectory],
                            tolerance: float | None = None) -> list[list[IntegralEvidence]]:
    """:func:`integral_evidence` of many trajectories of one system (e.g. an ensemble's members) at once.

    The integrals and their scales are evaluated at the trajectories' points (samples and steps) by
    a heyoka compiled function generated from the same symbolic integrals
    (:func:`compiled_integrals`), a few thousand points per call, then reduced per trajectory with
    numpy; ~10× faster than :func:`integral_evidence` member by member for short trajectories. The
    numbers agree with :func:`integral_evidence`'s (numpy kernels) to rounding: a drift of a few
    1e-16 may differ in its last units.

    Parameters
    ----------
    parameters : shape ``(n_members, n_parameters)``: each trajectory's parameter vector.
    trajectories : one per row of ``parameters``.
    tolerance : as for :func:`integral_evidence` (default: each trajectory's own).
    """
    P = np.asarray(parameters, dtype=float).reshape(len(trajectories), -1)
    if not system.integrals or not trajectories:
        return [[] for _ in trajectories]
    cf, ts = compiled_integrals(system)
    runtime = ts.runtime_parameters(P.T)[:cf.nparams]
    counts = [len(t.states) + len(t.step_states) for t in trajectories]
    out: list[list[IntegralEvidence]] = []
    start = 0
    while start < len(trajectories):  # groups of members with about GROUP_POINTS points: cache-sized arrays
        stop, total = start, 0
        while stop < len(trajectories) and (stop == start or total + counts[stop] <= GROUP_POINTS):
            total += counts[stop]
            stop += 1
        out.extend(_group(system, cf, runtime[:, start:stop], trajectories[start:stop], counts[start:stop], tolerance))
        start = stop
    return out


#: Points per call of the compiled integrals in :func:`integral_evidence_batch`.
GROUP_POINTS = 8192


def _group(system: MechanicalSystem, cf: hy.cfunc, runtime: np.ndarray, trajectories: Sequence[Trajectory],
           counts: list[int], tolerance: float | None) -> list[list[IntegralEvidence]]:
    """The evidence of a few trajectories (``runtime``: their runtime parameters, one column each)."""
    k = len(system.integrals)
    first = np.cumsum([0] + counts[:-1])
    points = np.empty((system.dimension, sum(counts)))  # one column per point: samples, then steps
    for t, start in zip(trajectories, first.tolist()):
        middle = start + len(t.states)
        points[:, start:middle] = t.states.T
        points[:, middle:middle + len(t.step_states)] = t.step_states.T
    values = cf(points, pars=np.repeat(runtime, counts, axis=1))  # the integrals, then their scales
    initial = values[:k, first]
    final = values[:k, first + np.array([len(t.t) for t in trajectories]) - 1]
    # max |I - I(0)| from the extremes (subtraction is monotonic: the same number exactly)
    abs_drift = np.maximum(np.maximum.reduceat(values[:k], first, axis=1) - initial,
                           initial - np.minimum.reduceat(values[:k], first, axis=1))
    scale = np.maximum.reduceat(np.abs(values[k:]), first, axis=1)
    reference = np.maximum(np.abs(initial), scale)
    reference = np.where(reference > 0, reference, 1.0)
    with np.errstate(all="ignore"):
        rel_drift = abs_drift / reference
    tols = [integral_tolerance(t.tolerance) if tolerance is None else tolerance for t in trajectories]
    passed = np.isfinite(rel_drift) & (rel_drift <= np.array(tols))
    rows = zip(*(a.T.tolist() for a in (initial, final, abs_drift, rel_drift, reference, passed)))
    return [[_evidence((claim.name, claim.formula, claim.equation, i0, i1, d_abs, d_rel, ref, count, tol, ok))
             for claim, i0, i1, d_abs, d_rel, ref, ok in zip(system.integrals, *member)]
            for member, count, tol in zip(rows, counts, tols)]


_FIELDS = tuple(f.name for f in fields(IntegralEvidence))


def _evidence(values: tuple[object, ...]) -> IntegralEvidence:
    """An :class:`IntegralEvidence` from its field values in order, set in one ``__dict__`` update
    instead of the frozen dataclass's ``object.__setattr__`` per field (4× faster; an ensemble
    chunk builds thousands)."""
    evidence = object.__new__(IntegralEvidence)
    evidence.__dict__.update(zip(_FIELDS, values))
    return evidence


@lru_cache(maxsize=64)
def compiled_integrals(system: MechanicalSystem) -> tuple[hy.cfunc, TaylorSystem]:
    """A heyoka compiled function of the state: ``[integral_1, ..., integral_k, scale_1, ..., scale_k]``,
    with :func:`~nonholonomic.taylor.taylor_system`'s runtime parameters (once per system and process)."""
    ts = taylor_system(system)
    exprs = [c.expression for c in system.integrals] + [c.scale for c in system.integrals]
    return hy.cfunc(ts.expressions(exprs), list(ts.variables[: ts.n_state])), ts


def integral_series(system: MechanicalSystem, parameters: dict[str, object],
                    states: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every first integral of ``system`` and its natural scale at each phase point (e.g. along the samples).

    Evaluated by :func:`compiled_integrals` (the heyoka compiled function of the same symbolic
    integrals the evidence uses), so ``|I − I(0)| / max(|I(0)|, max scale)`` of these series is the
    relative drift of :class:`IntegralEvidence` restricted to ``states``.

    Parameters
    ----------
    system : the symbolic definition.
    parameters : named parameter groups as a request gives them (``{"inertia": [..], "D": .., "a": [..]}``;
        flattened by :func:`~nonholonomic.kernels.parameter_vector`).
    states : shape ``(n, system.dimension)``: one phase point per row, columns in the order of
        ``system.state_symbols``.

    Returns
    -------
    dict
        ``name → (values, scales)``, two arrays of shape ``(n,)`` per integral, in the system's order
        (empty when the system claims no integral).

    Raises
    ------
    KeyError
        If a parameter group is missing.
    ValueError
        If a parameter group is malformed or ``states`` has the wrong number of columns.
    """
    X = np.atleast_2d(np.asarray(states, dtype=float))
    if X.shape[1] != system.dimension:
        raise ValueError(f"{system.kind} has {system.dimension} state variables, the states have {X.shape[1]} columns")
    if not system.integrals:
        return {}
    k, n = len(system.integrals), X.shape[0]
    if n == 0:
        return {c.name: (np.empty(0), np.empty(0)) for c in system.integrals}
    p = parameter_vector(system, parameters)
    cf, ts = compiled_integrals(system)
    runtime = ts.runtime_parameters(p)[:cf.nparams]
    pars = np.ascontiguousarray(np.repeat(runtime[:, None], n, axis=1))  # one column per point
    values = cf(np.ascontiguousarray(X.T), pars=pars)  # the integrals, then their scales
    return {claim.name: (values[i].copy(), values[k + i].copy()) for i, claim in enumerate(system.integrals)}
