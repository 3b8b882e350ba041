"""First integrals evaluated along a trajectory: initial, final and the largest drift (one trajectory,
or many of one system at once)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import heyoka as hy
import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import Trajectory
from nonholonomic.numerics.kernels import numeric, parameter_vector
from nonholonomic.numerics.taylor import TaylorSystem, taylor_system

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
    buffers = _Buffers(system.dimension, cf.nparams, 2 * len(system.integrals), max(GROUP_POINTS, max(counts)))
    out: list[list[IntegralEvidence]] = []
    start = 0
    while start < len(trajectories):  # groups of members with about GROUP_POINTS points: cache-sized arrays
        stop, total = start, 0
        while stop < len(trajectories) and (stop == start or total + counts[stop] <= GROUP_POINTS):
            total += counts[stop]
            stop += 1
        out.extend(_group(system, cf, buffers, runtime[:, start:stop], trajectories[start:stop], counts[start:stop],
                          tolerance))
        start = stop
    return out


#: Points per call of the compiled integrals in :func:`integral_evidence_batch`.
GROUP_POINTS = 8192


class _Buffers:
    """The arrays of one group (points, their parameters, the values), allocated once per
    :func:`integral_evidence_batch` call and reused by every group: arrays this size allocated afresh
    come from the system as new pages, whose first touch costs more than the compiled function."""

    def __init__(self, n_inputs: int, n_pars: int, n_outputs: int, size: int) -> None:
        self.rows = (n_inputs, n_pars, n_outputs)
        self.flat = [np.empty(rows * size) for rows in self.rows]

    def arrays(self, total: int) -> list[np.ndarray]:
        """C-contiguous views of ``total`` columns: points, parameters, values."""
        return [flat[:rows * total].reshape(rows, total) for flat, rows in zip(self.flat, self.rows)]


def _group(system: MechanicalSystem, cf: hy.cfunc, buffers: _Buffers, runtime: np.ndarray,
           trajectories: Sequence[Trajectory], counts: list[int],
           tolerance: float | None) -> list[list[IntegralEvidence]]:
    """The evidence of a few trajectories (``runtime``: their runtime parameters, one column each)."""
    k, m = len(system.integrals), len(trajectories)
    points, pars, values = buffers.arrays(sum(counts))
    # one column per point: each trajectory's samples, then its steps
    np.concatenate([a.T for t in trajectories for a in (t.states, t.step_states)], axis=1, out=points)
    if np.all(runtime == runtime[:, :1]):  # one parameter vector (an ensemble of initial states)
        pars[:] = runtime[:, :1]
    else:
        pars[:] = np.repeat(runtime, counts, axis=1)
    cf(points, pars=pars, outputs=values)  # the integrals, then their scales
    first = np.cumsum([0] + counts[:-1])
    initial = values[:k, first]
    final = values[:k, first + np.array([len(t.t) for t in trajectories]) - 1]
    # max |I - I(0)| from the extremes (subtraction is monotonic: the same number exactly)
    abs_drift = np.maximum(np.maximum.reduceat(values[:k], first, axis=1) - initial,
                           initial - np.minimum.reduceat(values[:k], first, axis=1))
    scale = np.maximum.reduceat(np.abs(values[k:], out=values[k:]), first, axis=1)
    reference = np.maximum(np.abs(initial), scale)
    reference[~(reference > 0)] = 1.0
    with np.errstate(all="ignore"):
        rel_drift = abs_drift / reference
    tols = [integral_tolerance(t.tolerance) if tolerance is None else tolerance for t in trajectories]
    passed = np.isfinite(rel_drift) & (rel_drift <= np.array(tols))
    # one row per (member, integral), member-major: the claim's words, the numbers, the member's count and tolerance
    claims = [(c.name, c.formula, c.equation) for c in system.integrals] * m
    numbers = zip(*(a.T.ravel().tolist() for a in (initial, final, abs_drift, rel_drift, reference, passed)))
    member = [(count, tol) for count, tol in zip(counts, tols) for _ in range(k)]
    new, evidence = object.__new__, []
    for words, (i0, i1, d_abs, d_rel, ref, ok), (count, tol) in zip(claims, numbers, member):
        # the fields stored straight into the instance's __dict__, in their order, not by the frozen
        # dataclass's object.__setattr__ one at a time (3x faster; an ensemble chunk builds thousands)
        item = new(IntegralEvidence)
        d = item.__dict__
        d["name"], d["formula"], d["equation"] = words
        (d["initial"], d["final"], d["max_abs_drift"], d["max_rel_drift"], d["reference"], d["evaluated_at"],
         d["tolerance"], d["passed"]) = i0, i1, d_abs, d_rel, ref, count, tol, ok
        evidence.append(item)
    return [evidence[j:j + k] for j in range(0, k * m, k)]


@lru_cache(maxsize=64)
def compiled_integrals(system: MechanicalSystem) -> tuple[hy.cfunc, TaylorSystem]:
    """A heyoka compiled function of the state: ``[integral_1, ..., integral_k, scale_1, ..., scale_k]``,
    with :func:`~nonholonomic.numerics.taylor.taylor_system`'s runtime parameters (once per system and process)."""
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
        flattened by :func:`~nonholonomic.numerics.kernels.parameter_vector`).
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
