"""A branch of periodic orbits by pseudo-arclength continuation, through folds, with its bifurcations
located and labelled and, at each period doubling, the period-2k branch followed.

:func:`follow_branch` starts from a closed orbit (:func:`nonholonomic.analysis.periodic_orbit.find_periodic_orbit`)
and moves λ, the energy or another integral (the family of a conservative system at fixed parameters, the level's other
integrals held) or one parameter (the whole level held), towards ``to``: predictor z + h t along the tangent,
corrector on the closing equations with Keller's arclength row (:mod:`.arclength`). The step h grows by 1.5
after a correction of at most 3 iterations, halves after one of 6 or more, and after a failure or a turn of
the tangent by more than :data:`MAX_TURN_COS`; below ``min_step`` the branch is ``lost``. Every limit is a
count or a size, never a clock: the same request gives the same branch.

Each point carries its scaled closing residual, its multipliers (trivial ones checked), the multipliers'
product against the claimed measure (Liouville), and at every ``check_every``-th point, the ends and each
bifurcation, the closing error of scipy's DOP853 from the same x₀ over the same T (an independent
integrator). Bifurcations: :mod:`.bifurcations`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from nonholonomic.analysis.periodic_orbit import (
    INDEPENDENT_TOLERANCE,
    Multipliers,
    OrbitCheck,
    PeriodicOrbit,
    product_check,
    split_multipliers,
    stability_of,
)
from nonholonomic.analysis.periodic_orbit.arclength import ArcClosing, Continued, Correction, correct, tangent
from nonholonomic.analysis.periodic_orbit.bifurcations import (
    Crossing,
    Tests,
    bifurcation_tests,
    crossings,
    doubled_tangent,
    locate,
    section_trace_det,
)
from nonholonomic.analysis.periodic_orbit.newton import CancelCheck, Flow, level_values, rows
from nonholonomic.analysis.poincare.surface import parse_surface
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import SCIPY_MIN_TOLERANCE, IntegrationError, integrate
from nonholonomic.numerics.kernels import vectorize
from nonholonomic.refusals import RefusedField

#: Consecutive tangents must agree to this cosine, else the step halves (the corrector may have jumped).
MAX_TURN_COS = 0.9
#: σ₋₂/σ₀ of J_λ below this: the kernel is not one-dimensional (a family of orbits, a branch point).
KERNEL_DEGENERATE = 1e-9
#: Most points of one branch, and most branches switched onto.
MAX_BRANCH_POINTS = 400
#: ``to`` within this (relative) of the start's value: the branch is the start orbit alone.
AT_START = 1e-12
MAX_SWITCHES = 4


class BranchError(RefusedField):
    """A branch request that cannot be followed, with the field (relative to ``periodic_orbit.branch``)."""


@dataclass(frozen=True)
class BranchOptions:
    """What to continue (``continued``: an integral's name, ``"energy"``, or a parameter path, with
    ``parameter_index`` its index in the parameter vector) and up to where (``to``); step control in the
    arclength of z = (x₀, T, λ)."""

    continued: str
    to: float
    parameter_index: int | None = None
    max_points: int = 100
    step: float = 0.05
    min_step: float = 1e-5
    max_step: float = 0.25
    switch: bool = True
    switch_points: int = 40
    check_every: int = 10
    max_multiplier: float = 1e3


@dataclass(frozen=True)
class BranchPoint:
    """One orbit of a branch: λ (``value``), x₀, T, τ over T, its point on the section, the section multipliers
    (largest modulus first), trace, stability, scaled closing residual, the arclength from the branch's start,
    the tangent's λ-component, the checks run; ``residual_independent`` None where DOP853 was not run."""

    value: float
    initial_state: np.ndarray
    period_t: float
    period_tau: float | None
    coordinates: tuple[float, ...]
    multipliers: np.ndarray
    trace: float | None
    stability: str | None
    residual: float
    arclength: float
    tangent_value: float
    checks: tuple[OrbitCheck, ...]
    residual_independent: float | None = None

    @property
    def checks_passed(self) -> bool | None:
        decided = [c.passed for c in self.checks if c.passed is not None]
        return all(decided) if decided else None


@dataclass(frozen=True)
class Bifurcation:
    """A located bifurcation: its kind, λ, the point there, between points ``index`` and ``index + 1``, the test
    function's value and bracket (``located`` False: the budget ran out; the best point), the trials spent;
    ``switched``: the index in :attr:`OrbitBranch.switched` of the branch followed from it."""

    kind: str
    value: float
    index: int
    point: BranchPoint
    test_value: float
    bracket: float
    trials: int
    located: bool
    detail: str
    switched: int | None = None


@dataclass(frozen=True)
class OrbitBranch:
    """A branch: its period k, the points in order along it, the bifurcations, why it ended (``status``:
    ``reached`` λ = to, ``bound`` back at the start's λ or out of the range, ``max_points``, ``lost``,
    ``degenerate``, ``unstable_limit``: a multiplier beyond ``max_multiplier``), the branches switched onto,
    and the work done."""

    continued: str
    period: int
    to: float
    points: tuple[BranchPoint, ...]
    bifurcations: tuple[Bifurcation, ...]
    status: str
    reason: str
    evaluations: int
    taylor_steps: int
    wall_time_s: float
    coordinate_names: tuple[str, ...] = ()
    switched: tuple[OrbitBranch, ...] = ()
    origin: str | None = None
    warnings: tuple[str, ...] = field(default=())


def check_branch(system: MechanicalSystem, options: BranchOptions, level: Sequence[str]) -> tuple[str, ...]:
    """The level the branch holds (with the continued integral added for a family in one).

    Raises
    ------
    BranchError
        Naming ``in``, ``max_points``, ``step`` or ``check_every``.
    """
    names = [i.name for i in system.integrals]
    if options.parameter_index is None:
        if options.continued not in names:
            raise BranchError("in", f"{system.kind} has no integral named {options.continued}; its integrals: "
                                    f"{', '.join(names) or 'none'}; or continue a parameter")
        if options.continued not in level:
            level = tuple(level) + (options.continued,)
    if not 2 <= options.max_points <= MAX_BRANCH_POINTS:
        raise BranchError("max_points", f"must be 2 .. {MAX_BRANCH_POINTS}, got {options.max_points}")
    if not 0 < options.min_step <= options.step <= options.max_step:
        raise BranchError("step", "needs 0 < min_step <= step <= max_step, got "
                                  f"{options.min_step:g}, {options.step:g}, {options.max_step:g}")
    if not options.max_multiplier > 1:
        raise BranchError("max_multiplier", f"must exceed 1, got {options.max_multiplier:g}")
    if options.check_every < 1:
        raise BranchError("check_every", f"must be at least 1, got {options.check_every}")
    return tuple(level)


class _Follower:
    """One branch's continuation: the closing equations, the points, and how each point is reported."""

    def __init__(self, system: MechanicalSystem, closing: ArcClosing, options: BranchOptions, period: int,
                 coordinates: tuple[str, ...], bounds: tuple[float, float], tolerance: float) -> None:
        self.system, self.closing, self.options, self.period = system, closing, options, period
        self.coordinates, self.bounds, self.tolerance = coordinates, bounds, tolerance
        state = system.state_symbols
        self.coordinate_kernel = vectorize([parse_surface(system, c) for c in coordinates] or [state[0]],
                                           list(state) + list(system.parameter_symbols))
        self.measure = system.measure.density is not None

    # -- one point --------------------------------------------------------------------------------------
    def point(self, corr: Correction, t: np.ndarray, arclength: float) -> tuple[BranchPoint, Tests]:
        n = self.system.dimension
        z, fl = corr.z, corr.flow
        assert fl is not None
        x, period_t, lam = z[:n].copy(), float(z[n]), float(z[n + 1])
        p = self.closing.parameters(lam)
        ms = split_multipliers(self.system, p, x, fl)
        trace, stability = stability_of(ms.section, ms.trivial_tolerance)
        if len(ms.section) == 2:  # smooth where the pair is double (see bifurcations)
            trace, det = section_trace_det(fl.monodromy, ms.trivial_count)
            if abs(det - 1.0) <= 1e-6 * ms.size:  # measure-preserving: the trace decides
                stability = ("parabolic" if abs(abs(trace) - 2.0) <= 1e-9
                             else "elliptic" if abs(trace) < 2.0 else "hyperbolic")
        checks = (ms.trivial_check, product_check(self.system, p, x, fl, ms.all, ms.size))
        tau = None
        if self.system.reduced_time is not None:
            out = integrate(self.system, p, x, period_t, 2, engine="heyoka", tolerance=self.tolerance).tau
            tau = None if out is None else float(out[-1])
        coords = tuple(float(c) for c in self.coordinate_kernel(x[None, :], p)[0][: len(self.coordinates)])
        bp = BranchPoint(lam, x, period_t, tau, coords, ms.section, trace, stability, corr.residual, arclength,
                         float(t[n + 1]), checks)
        return bp, self._tests(ms, fl, t)

    def independent(self, bp: BranchPoint) -> BranchPoint:
        """The point with scipy's DOP853 closing check added."""
        p = self.closing.parameters(bp.value)
        scale = max(1.0, float(np.max(np.abs(bp.initial_state))))
        size = max(1.0, float(np.max(np.abs(bp.multipliers)))) if len(bp.multipliers) else 1.0
        tol = INDEPENDENT_TOLERANCE * size
        try:
            other = integrate(self.system, p, bp.initial_state, bp.period_t, 2, engine="scipy",
                              tolerance=SCIPY_MIN_TOLERANCE)
        except IntegrationError as exc:
            check = OrbitCheck("closes_independently", False, float("nan"), 0.0, None, f"scipy failed: {exc}")
            return replace(bp, checks=bp.checks + (check,))
        err = float(np.max(np.abs(other.states[-1] - bp.initial_state)) / scale)
        check = OrbitCheck("closes_independently", err <= tol, err, 0.0, tol,
                           "max|x(T) - x0| / max(1, max|x0|) by scipy's DOP853 at rtol = atol = "
                           f"{SCIPY_MIN_TOLERANCE:g}")
        return replace(bp, checks=bp.checks + (check,), residual_independent=err)

    def evaluate_tests(self, corr: Correction, t: np.ndarray) -> Tests:
        """The test functions alone (a location's trial: no τ, coordinates or checks)."""
        n = self.system.dimension
        assert corr.flow is not None
        x = corr.z[:n]
        ms = split_multipliers(self.system, self.closing.parameters(float(corr.z[n + 1])), x, corr.flow)
        return self._tests(ms, corr.flow, t)

    def _tests(self, ms: Multipliers, fl: Flow, t: np.ndarray) -> Tests:
        return bifurcation_tests(float(t[self.system.dimension + 1]), fl.monodromy, ms.trivial_count, ms.section,
                                 self.measure)

    # -- the walk ---------------------------------------------------------------------------------------
    def run(self, start: Correction, t0: np.ndarray, max_points: int,
            born: bool = False) -> tuple[list[BranchPoint], list[Bifurcation], str, str]:
        """Walk from ``start`` along ``t0``; ``born``: ``start`` is a period doubling, where the new branch's
        test functions vanish, so the first interval is not searched for bifurcations."""
        n = self.system.dimension
        lo, hi = self.bounds
        e_lam = np.zeros(n + 2)
        e_lam[n + 1] = 1.0
        first, tests = self.point(start, t0, 0.0)
        points, found = [first], list[Bifurcation]()
        z, t, s, h = start.z, t0, 0.0, self.options.step
        while len(points) < max_points:
            pred = z + h * t
            lam_pred = float(pred[n + 1])
            end = None
            if lam_pred > hi or lam_pred < lo:
                end = hi if lam_pred > hi else lo
                if abs(t[n + 1]) < 1e-12 or abs(end - z[n + 1]) / abs(t[n + 1]) > h:
                    end = None
            if end is not None:
                h_end = (end - float(z[n + 1])) / float(t[n + 1])
                corr = correct(self.closing, z + h_end * t, e_lam, end)
            else:
                h_end = h
                corr = correct(self.closing, pred, t, float(t @ pred))
            t_new, ratio = tangent(corr.J, t) if corr.converged else (t, 0.0)
            if corr.converged and ratio < KERNEL_DEGENERATE:
                return points, found, "degenerate", (
                    f"the closing equations' kernel is not one-dimensional at {self.options.continued} = "
                    f"{corr.z[n + 1]:.10g} (singular values' ratio {ratio:.2g}): a family of orbits or a branch "
                    "point the branch cannot pass")
            if not corr.converged or float(t_new @ t) < MAX_TURN_COS:
                h *= 0.5
                if h < self.options.min_step:
                    return points, found, "lost", (
                        f"the corrector did not converge with steps down to {self.options.min_step:g} after "
                        f"{self.options.continued} = {z[n + 1]:.10g}")
                continue
            step = float(np.linalg.norm(corr.z - z))
            bp, tests_new = self.point(corr, t_new, s + step)
            for crossing in ([] if born and len(points) == 1 else crossings(tests, tests_new)):
                found.append(self._located(crossing, z, t, h_end, corr, tests_new, t_new, tests, len(points) - 1,
                                           s))
            points.append(bp)
            z, t, tests, s = corr.z, t_new, tests_new, s + step
            largest = float(np.max(np.abs(bp.multipliers))) if len(bp.multipliers) else 0.0
            if largest > self.options.max_multiplier:
                return points, found, "unstable_limit", (
                    f"the largest section multiplier reached {largest:.3g} > max_multiplier = "
                    f"{self.options.max_multiplier:g} at {self.options.continued} = {bp.value:.10g} (T = "
                    f"{bp.period_t:.6g}): past it the closing equations lose digits; where T grows while the value "
                    "stalls, a homoclinic orbit (infinite period) is near")
            if end is not None:
                where = "the requested value" if end == self.options.to else "the start's value (after a fold)"
                return points, found, ("reached" if end == self.options.to else "bound"), (
                    f"the branch reached {self.options.continued} = {end:.10g}, {where}")
            if corr.iterations <= 3:
                h = min(1.5 * h, self.options.max_step)
            elif corr.iterations >= 6:
                h = max(0.5 * h, self.options.min_step)
        return points, found, "max_points", f"{max_points} points (max_points) before {self.options.continued} = " \
                                            f"{self.options.to:g}"

    def _located(self, crossing: Crossing, z_a: np.ndarray, t_a: np.ndarray, h: float, corr_b: Correction,
                 tests_b: Tests, t_b: np.ndarray, tests_a: Tests, index: int, s_a: float) -> Bifurcation:
        """The bifurcation ``crossing`` between point ``index`` (z_a, t_a, at arclength s_a) and the next (corr_b),
        a step h apart, located."""
        n = self.system.dimension
        loc = locate(self.closing, z_a, t_a, h, crossing, self.evaluate_tests, corr_b, tests_b, t_b, tests_a)
        bp, _ = self.point(loc.correction, loc.tangent, s_a + loc.arclength)
        kind, _, q = crossing.kind.partition(":")
        detail = _DETAILS[kind].format(k=self.period, k2=2 * self.period, q=q or "",
                                       kq=self.period * int(q) if q else "")
        return Bifurcation(crossing.kind, float(loc.correction.z[n + 1]), index, bp, loc.test_value, loc.bracket,
                           loc.trials, loc.located, detail)


_DETAILS = {
    "fold": "the branch turns back in the continued value (tangent's λ-component 0); a section multiplier is +1",
    "tangent": "a section multiplier passes through +1 where the branch goes on: a pitchfork or transcritical "
               "branch point (another branch of period {k} crosses)",
    "period_doubling": "a section multiplier passes through -1: a period-{k2} orbit is born or dies here",
    "resonance_1": "the elliptic multipliers pass exp(+-2 pi i/{q}) (trace 2 cos(2 pi/{q})): {q} islands about each of "
                   "its points, an orbit of period {kq}, are born or pass through it",
    "neimark_sacker": "a complex pair of multipliers crosses the unit circle: an invariant curve of the section "
                      "map is born or dies",
    "krein_collision": "two pairs of multipliers on the unit circle collide and leave it (or enter it): the orbit "
                       "loses (or gains) its linear stability",
}


def follow_branch(system: MechanicalSystem, p: np.ndarray, start: PeriodicOrbit, options: BranchOptions, *,
                  tolerance: float, progress: Callable[[float], bool] | None = None) -> OrbitBranch:
    """Continue the closed orbit ``start`` (of the job's parameters ``p``) as ``options`` say.

    Raises
    ------
    BranchError
        A refused field (see :func:`check_branch`).
    IntegrationCancelled
        If ``progress`` answers False.
    """
    began = time.perf_counter()
    level = check_branch(system, options, tuple(start.level))
    surface, value, k = start.surface, start.value, start.period
    r = rows(system, surface, level)
    n = system.dimension
    x0 = np.asarray(start.initial_state, dtype=float)
    targets = level_values(p, x0, value, level, r)
    if options.parameter_index is None:
        row = 1 + level.index(options.continued)
        continued = Continued(options.continued, level_row=row)
        lam0 = float(targets[row])
    else:
        continued = Continued(options.continued, parameter_index=options.parameter_index)
        lam0 = float(p[options.parameter_index])
    budget = options.max_points * 6 * (1 + (options.switch and MAX_SWITCHES))
    cancel = CancelCheck(progress, budget)
    closing = ArcClosing(system, np.asarray(p, dtype=float).copy(), r, targets, tolerance, cancel,
                         max(1.0, float(np.max(np.abs(x0)))), continued=continued)
    bounds = (min(lam0, options.to), max(lam0, options.to))
    coords = tuple(start.coordinate_names)
    z0 = np.concatenate([x0, [start.period_t, lam0]])
    corr0 = correct(closing, z0, np.eye(n + 2)[n + 1], lam0)
    if not corr0.converged:
        return OrbitBranch(options.continued, k, options.to, (), (), "lost",
                           f"the start orbit does not close in the branch's equations (residual {corr0.residual:.3g})",
                           closing.evaluations, closing.steps, time.perf_counter() - began, coords)
    t0, _ = tangent(corr0.J)
    if t0[n + 1] * (options.to - lam0) < 0:
        t0 = -t0
    follower = _Follower(system, closing, options, k, coords, bounds, tolerance)
    if abs(lam0 - options.to) <= AT_START * max(1.0, abs(lam0)):
        points, found, status, reason = [follower.point(corr0, t0, 0.0)[0]], list[Bifurcation](), "reached", (
            f"the start orbit is at {options.continued} = {lam0:.17g} already")
    else:
        points, found, status, reason = follower.run(corr0, t0, options.max_points)
    points = _with_evidence(follower, points, found, options.check_every)
    found = [replace(b, point=follower.independent(b.point)) for b in found]
    switched: list[OrbitBranch] = []
    warnings: list[str] = []
    if options.switch:
        for i, b in enumerate(found):
            if b.kind != "period_doubling" or len(switched) >= MAX_SWITCHES:
                continue
            if 2 * k > 64:
                warnings.append(f"the period-doubling at {b.value:.10g} would need period {2 * k} > 64: not followed")
                continue
            sub = _switch(system, closing, options, b, k, coords, bounds, tolerance)
            found[i] = replace(b, switched=len(switched))
            switched.append(sub)
    return OrbitBranch(options.continued, k, options.to, tuple(points), tuple(found), status, reason,
                       closing.evaluations, closing.steps, time.perf_counter() - began, coords, tuple(switched),
                       warnings=tuple(warnings))


def _with_evidence(follower: _Follower, points: list[BranchPoint], found: list[Bifurcation],
                   every: int) -> list[BranchPoint]:
    """The independent closing check at every ``every``-th point and at the last."""
    return [follower.independent(bp) if (i % every == 0 or i == len(points) - 1) else bp
            for i, bp in enumerate(points)]


def _switch(system: MechanicalSystem, closing: ArcClosing, options: BranchOptions, at: Bifurcation, k: int,
            coords: tuple[str, ...], bounds: tuple[float, float], tolerance: float) -> OrbitBranch:
    """The period-2k branch from the period doubling ``at``: its tangent is the kernel vector of the doubled
    equations orthogonal to the old branch's (:func:`.bifurcations.doubled_tangent`)."""
    began = time.perf_counter()
    n = system.dimension
    evaluations, steps = closing.evaluations, closing.steps
    p0 = at.point
    z2 = np.concatenate([p0.initial_state, [2 * p0.period_t, p0.value]])
    origin = f"period_doubling at {options.continued} = {p0.value:.10g}"
    _, J1, _ = closing.evaluate(np.concatenate([p0.initial_state, [p0.period_t, p0.value]]))
    old, _ = tangent(J1)
    old[n] *= 2.0  # the old branch's tangent, its period doubled
    R2, J2, fl2 = closing.evaluate(z2)
    t_new, ratio = doubled_tangent(J2, old)
    follower = _Follower(system, closing, replace(options, switch=False), 2 * k, coords, bounds, tolerance)
    start = Correction(z2, float(np.max(np.abs(R2))), 0, J2, fl2, True)
    points, found, status, reason = follower.run(start, t_new, options.switch_points, born=True)
    warnings = []
    if len(points) < 2:
        reason = (f"no period-{2 * k} orbit found a step from the period doubling (kernel ratio {ratio:.2g}): "
                  + reason)
    else:
        half = _half_period_distance(system, closing, np.concatenate([points[1].initial_state,
                                                                       [points[1].period_t, points[1].value]]))
        if half <= 1e-6:
            warnings.append(f"x(T/2) is x0 to {half:.2g}: the corrector fell back onto the period-{k} orbit")
            status = "lost"
    points = _with_evidence(follower, points, found, options.check_every)
    found = [replace(b, point=follower.independent(b.point)) for b in found]
    return OrbitBranch(options.continued, 2 * k, options.to, tuple(points), tuple(found), status, reason,
                       closing.evaluations - evaluations, closing.steps - steps, time.perf_counter() - began,
                       coords, origin=origin, warnings=tuple(warnings))


def _half_period_distance(system: MechanicalSystem, closing: ArcClosing, z: np.ndarray) -> float:
    """max|x(T/2) − x₀| / scale: away from 0 on a genuine period-2k orbit."""
    n = system.dimension
    p = closing.parameters(float(z[n + 1]))
    out = integrate(system, p, z[:n], float(z[n]) / 2, 2, engine="heyoka", tolerance=closing.tolerance)
    return float(np.max(np.abs(out.states[-1] - z[:n]))) / closing.scale
