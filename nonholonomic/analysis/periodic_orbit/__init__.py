"""Periodic orbits of a Poincaré section map: a fixed point of the k-th return map, found from a seed.

:func:`find_periodic_orbit` takes a seed state, integrates it to its first crossing of the section
``S(x) = value`` (in ``direction``) and to its k-th return after that (heyoka events, :mod:`.poincare`),
and hands the crossing state and the return time to Newton's method on the closing equations with the
monodromy from the variational equations (:mod:`.newton`; Levenberg–Marquardt when Newton
wanders). The search stays on the seed's level: the integrals named in ``level`` (by default those the
kind's level sets are drawn on, :func:`nonholonomic.analysis.sampling.fixable`; every integral for a
system without a recipe) and the constraints keep their seed values.

What is reported of a closed orbit, and checked:

* ``multipliers``: the eigenvalues of the full flow's monodromy Φ(T). One is 1 for the flow's direction
  and one per independent integral or constraint (the ``trivial`` ones: 1 + the rank of their gradients
  at x₀); checked to be 1 within a tolerance that allows for their Jordan blocks (a defective eigenvalue
  moves by √(ε‖Φ‖)). The others are the section map's multipliers; with two of them the ``trace``
  classifies the orbit (|trace| < 2 elliptic, > 2 hyperbolic).
* their product, det Φ(T) = exp ∫₀ᵀ div f dt (Liouville), equals ρ(x₀)/ρ(x(T)) for a system with an
  invariant measure ρ (div(ρf) = 0 gives div f = −d ln ρ/dt), which is 1 on a closed orbit;
* the closing error re-checked by an independent integration (scipy's DOP853 at rtol = atol = 1e-13);
* the section crossed exactly k times in (0, T] in ``direction``, the last at T (heyoka's events again).

A family of periodic orbits through the solution (J rank-deficient: the ratio of its smallest to its
largest singular value below :data:`DEGENERATE_BELOW`) is reported as ``degenerate``, not failed: on a
resonant torus of an integrable system every orbit is periodic with the same period, and the result
says which unfixed integrals are constant along the family.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np

from nonholonomic.analysis.periodic_orbit.newton import (
    CLOSING_TOLERANCE,
    FALLBACK_EVALUATIONS,
    NEWTON_ITERATIONS,
    CancelCheck,
    Closing,
    Flow,
    integral_gradients,
    level_values,
    rows,
    solve,
)
from nonholonomic.analysis.poincare import Section, section
from nonholonomic.analysis.poincare.request import _validate
from nonholonomic.analysis.poincare.surface import SurfaceError
from nonholonomic.analysis.sampling import fixable
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import MACHINE_EPSILON, SCIPY_MIN_TOLERANCE, IntegrationError, integrate
from nonholonomic.numerics.kernels import numeric
from nonholonomic.refusals import RefusedField

#: A solution whose Jacobian's singular values have a ratio below this lies on a family of periodic orbits.
DEGENERATE_BELOW = 1e-8
#: The independent integration's closing error must be below this (relative to the state's size) × max(1, ‖Φ‖).
INDEPENDENT_TOLERANCE = 1e-8
#: The multipliers' product against ρ(x₀)/ρ(x(T)): relative tolerance × max(1, ‖Φ‖).
PRODUCT_TOLERANCE = 1e-9
#: Longest period k of the return map.
MAX_PERIOD = 64


class PeriodicOrbitError(RefusedField):
    """A request that cannot be searched, with the field (relative to ``periodic_orbit``) and why."""


@dataclass(frozen=True)
class OrbitCheck:
    """One check of a closed orbit: ``passed`` None when it cannot be decided (no measure claimed)."""

    name: str
    passed: bool | None
    value: float
    expected: float | None
    tolerance: float | None
    detail: str


@dataclass(frozen=True)
class PeriodicOrbit:
    """A periodic orbit of the k-th return map, or why none was found.

    ``status``: ``found`` (an isolated orbit, every check run), ``degenerate`` (it closes, on a family of
    periodic orbits: ``reason`` says which), ``not_found`` (``reason``; ``initial_state`` is the best
    point reached). ``multipliers`` and ``section_multipliers`` are complex arrays; ``residual`` is the
    closing error max|x(T) − x₀| / max(1, max|x₀|) of the solver's last integration,
    ``residual_independent`` that of scipy's DOP853. ``search_time_s``: Newton's part of ``wall_time_s``
    (the rest: the seed's crossings and the checks).
    """

    status: str
    reason: str
    surface: str
    value: float
    direction: str
    period: int
    level: Mapping[str, float]
    initial_state: np.ndarray
    period_t: float
    period_tau: float | None = None
    coordinate_names: tuple[str, ...] = ()
    coordinates: tuple[float, ...] = ()
    crossing_times: tuple[float, ...] = ()
    multipliers: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=complex))
    trivial_count: int = 0
    section_multipliers: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=complex))
    trace: float | None = None
    stability: str | None = None
    residual: float = float("nan")
    residual_independent: float | None = None
    checks: tuple[OrbitCheck, ...] = ()
    iterations: tuple[float, ...] = ()
    method: str = "newton"
    wandered: str | None = None
    singular_ratio: float | None = None
    family_dimension: int = 0
    evaluations: int = 0
    steps: int = 0
    wall_time_s: float = 0.0
    search_time_s: float = 0.0
    warnings: tuple[str, ...] = ()

    @property
    def closed(self) -> bool:
        return self.status in ("found", "degenerate")


def default_level(system: MechanicalSystem) -> tuple[str, ...]:
    """The integrals held at the seed's values by default: the kind's level (energy, area ...), or every
    integral of a system without a sampling recipe."""
    return fixable(system) or tuple(i.name for i in system.integrals)


def check_request(system: MechanicalSystem, surface: str, value: float, direction: str, period: int,
                  level: Sequence[str] | None, t_final: float, tolerance: float | None,
                  coordinates: Sequence[str] | None = None) -> tuple[str, ...]:
    """The request's fields checked; the level's integral names.

    Raises
    ------
    PeriodicOrbitError
        Naming ``surface``, ``direction``, ``period``, ``coordinates`` or ``level``.
    """
    if direction not in ("increasing", "decreasing"):
        raise PeriodicOrbitError("direction", "a return map crosses the section one way: increasing or decreasing")
    if isinstance(period, bool) or not isinstance(period, (int, np.integer)) or not 1 <= period <= MAX_PERIOD:
        raise PeriodicOrbitError("period", f"must be an integer 1 .. {MAX_PERIOD}, got {period!r}")
    try:
        _validate(system, surface, value, direction, coordinates, int(period) + 2, t_final, tolerance)
    except SurfaceError as exc:
        where = f" (at position {exc.position})" if exc.position is not None else ""
        raise PeriodicOrbitError(exc.field, exc.reason + where) from None
    names = [i.name for i in system.integrals]
    chosen = default_level(system) if level is None else tuple(level)
    for i, name in enumerate(chosen):
        if name not in names:
            raise PeriodicOrbitError(f"level[{i}]", f"{name!r} is not a first integral of {system.kind}; "
                                                   f"its integrals: {', '.join(names) or 'none'}")
    if len(set(chosen)) != len(chosen):
        raise PeriodicOrbitError("level", "names an integral twice")
    return chosen


def crossing_states(system: MechanicalSystem, sec: Section) -> np.ndarray:
    """The state at each crossing of a :class:`~nonholonomic.analysis.poincare.Section`."""
    return np.concatenate([sec.points[v.name] for v in system.state], axis=1)


def find_periodic_orbit(
    system: MechanicalSystem,
    parameters: np.ndarray,
    seed: np.ndarray,
    surface: str,
    *,
    value: float = 0.0,
    direction: str = "increasing",
    period: int = 1,
    level: Sequence[str] | None = None,
    coordinates: Sequence[str] | None = None,
    t_final: float = 1000.0,
    tolerance: float | None = None,
    progress: Callable[[float], bool] | None = None,
) -> PeriodicOrbit:
    """A fixed point of the ``period``-th return map to ``surface = value`` near the orbit of ``seed``.

    Parameters
    ----------
    system, parameters : the definition and its parameter vector.
    seed : a state; its first crossing of the section and its ``period``-th return after it (within
        ``t_final``) start Newton's method.
    surface, value, direction : the section (as for :func:`nonholonomic.analysis.poincare.section`).
    period : k, the return map's power.
    level : the integrals held at the seed's values (default :func:`default_level`).
    coordinates : two components reported as the orbit's point on the section (default: the section's).
    t_final : the horizon for the seed's crossings.
    tolerance : heyoka's (default machine epsilon).
    progress : called with a fraction of the search's budget; False cancels (IntegrationCancelled).

    Raises
    ------
    PeriodicOrbitError
        A refused field. A seed that does not return is a ``not_found`` result, not an error.
    """
    chosen = check_request(system, surface, value, direction, period, level, t_final, tolerance, coordinates)
    tol = MACHINE_EPSILON if tolerance is None else float(tolerance)
    p = np.asarray(parameters, dtype=float)
    x_seed = np.asarray(seed, dtype=float)
    start = time.perf_counter()
    targets = level_values(p, x_seed, value, chosen, rows(system, surface, chosen))
    level_map = dict(zip(chosen, targets[1: 1 + len(chosen)].tolist()))
    try:
        sec = section(system, p, x_seed, t_final, surface, value=value, direction=direction,
                      max_points=period + 1, tolerance=tol)
    except IntegrationError as exc:
        return PeriodicOrbit("not_found", f"the seed's integration failed: {exc}", surface, value, direction, period,
                             level_map, x_seed, float("nan"), wall_time_s=time.perf_counter() - start)
    if sec.count < period + 1:
        return PeriodicOrbit(
            "not_found", f"the seed's orbit crosses {surface} = {value:g} ({direction}) {sec.count} time(s) before "
                         f"t_final = {t_final:g}; a period-{period} orbit needs {period + 1} (the first crossing, "
                         f"then {period} returns): raise t_final or choose another seed",
            surface, value, direction, period, level_map, x_seed, float("nan"),
            wall_time_s=time.perf_counter() - start)
    states = crossing_states(system, sec)
    return refine(system, p, states[0], float(sec.t[period] - sec.t[0]), surface, value=value, direction=direction,
                  period=period, level=chosen, tolerance=tol, coordinates=coordinates, progress=progress,
                  started=start)


def refine(system: MechanicalSystem, p: np.ndarray, x0: np.ndarray, period_t: float, surface: str, *,
           value: float, direction: str, period: int, level: Sequence[str], tolerance: float,
           coordinates: Sequence[str] | None = None, progress: Callable[[float], bool] | None = None,
           started: float | None = None) -> PeriodicOrbit:
    """Newton from (``x0``, ``period_t``) on the level of ``x0``, then the checks (see the module docstring)."""
    start = time.perf_counter() if started is None else started
    chosen = tuple(level)
    r = rows(system, surface, chosen)
    targets = level_values(p, x0, value, chosen, r)
    level_map = dict(zip(chosen, targets[1: 1 + len(chosen)].tolist()))
    scale = max(1.0, float(np.max(np.abs(x0))))
    closing = Closing(system, p, r, targets, tolerance, CancelCheck(progress, 2 * NEWTON_ITERATIONS
                                                                     + FALLBACK_EVALUATIONS), scale)
    searching = time.perf_counter()
    search = solve(closing, np.append(x0, period_t))
    n = system.dimension
    x, t = search.z[:n].copy(), float(search.z[n])
    common = _SearchStats(iterations=tuple(search.history), method=search.method, wandered=search.wandered,
                          evaluations=closing.evaluations, steps=closing.steps,
                          search_time_s=time.perf_counter() - searching)
    if not search.residual <= CLOSING_TOLERANCE:
        why = f" ({search.wandered})" if search.wandered else ""
        return PeriodicOrbit(
            "not_found", f"Newton's method did not close the orbit{why}; the best closing error reached is "
                         f"{search.residual:.3g} (needed {CLOSING_TOLERANCE:g}): try another seed, period or level",
            surface, value, direction, period, level_map, x, t, residual=search.residual,
            wall_time_s=time.perf_counter() - start, **common)
    return _verified(system, p, x, t, closing, search.residual, surface, value, direction, period, chosen,
                     level_map, tolerance, coordinates, start, common)


class _SearchStats(TypedDict):
    """What the search reports into a :class:`PeriodicOrbit`, closed or not."""

    iterations: tuple[float, ...]
    method: str
    wandered: str | None
    evaluations: int
    steps: int
    search_time_s: float


def _verified(system: MechanicalSystem, p: np.ndarray, x: np.ndarray, t: float, closing: Closing, residual: float,
              surface: str, value: float, direction: str, period: int, chosen: tuple[str, ...],
              level_map: dict[str, float], tolerance: float, coordinates: Sequence[str] | None, start: float,
              common: _SearchStats) -> PeriodicOrbit:
    """The closed orbit's multipliers, family, crossings and independent closing error."""
    _, J, fl = closing.evaluate(np.append(x, t))
    warnings: list[str] = []
    # the family: rank of the closing equations' Jacobian
    u, sv, vt = np.linalg.svd(J)
    ratio = float(sv[-1] / sv[0])
    family = int(np.sum(sv / sv[0] < DEGENERATE_BELOW))
    ms = split_multipliers(system, p, x, fl)
    mu, trivial, section_mu, size = ms.all, ms.trivial_count, ms.section, ms.size
    trace, stability = stability_of(section_mu, ms.trivial_tolerance)
    checks = [ms.trivial_check, product_check(system, p, x, fl, mu, size)]
    # the crossings in (0, T]
    sec = section(system, p, x, t * (1 + 1e-7) + 1e-12, surface, value=value, direction=direction,
                  max_points=period + 2, coordinates=coordinates, tolerance=tolerance)
    keep = sec.t > 1e-7 * t
    times = sec.t[keep]
    states = crossing_states(system, sec)[keep]
    crossings_ok = len(times) == period and abs(float(times[-1]) - t) <= 1e-7 * t
    checks.append(OrbitCheck("crossings", crossings_ok, float(len(times)), float(period), 0.0,
                             f"crossings of {surface} = {value:g} ({direction}) in (0, T]: {period} expected, the last "
                             "at T"))
    scale = max(1.0, float(np.max(np.abs(x))))
    for j in range(1, period):
        if j < len(states) and period % j == 0 and np.max(np.abs(states[j - 1] - x)) <= 1e-7 * scale:
            warnings.append(f"the orbit's prime period is {j}: it is the period-{j} orbit traversed {period // j} "
                            "times")
            break
    crossing_coordinates = tuple(float(c) for c in sec.coordinates[keep][-1]) if len(times) else ()
    # the closing error, independently
    period_tau = None
    if system.reduced_time is not None:
        tau = integrate(system, p, x, t, 2, engine="heyoka", tolerance=tolerance).tau
        period_tau = None if tau is None else float(tau[-1])
    try:
        other = integrate(system, p, x, t, 2, engine="scipy", tolerance=SCIPY_MIN_TOLERANCE)
        independent = float(np.max(np.abs(other.states[-1] - x)) / scale)
        ind_tol = INDEPENDENT_TOLERANCE * size
        checks.append(OrbitCheck("closes_independently", independent <= ind_tol, independent, 0.0, ind_tol,
                                 "max|x(T) - x0| / max(1, max|x0|) by scipy's DOP853 at rtol = atol = "
                                 f"{SCIPY_MIN_TOLERANCE:g}, a second integrator"))
    except IntegrationError as exc:
        independent = None
        checks.append(OrbitCheck("closes_independently", False, float("nan"), 0.0, None, f"scipy failed: {exc}"))
    status, reason = "found", "an isolated periodic orbit: it closes, and every check ran"
    if family:
        status, reason = "degenerate", _family_reason(system, p, x, vt[-family:], chosen, family, ratio)
    if not crossings_ok:
        status = "not_found"
        reason = (f"Newton closed an orbit of period T = {t:.12g} that crosses {surface} = {value:g} ({direction}) "
                  f"{len(times)} time(s) in (0, T], not {period}: it is not a period-{period} orbit of this return map")
    return PeriodicOrbit(
        status, reason, surface, value, direction, period, level_map, x, t, period_tau,
        tuple(sec.coordinate_names), crossing_coordinates, tuple(float(v) for v in times), mu, trivial, section_mu,
        trace, stability, residual, independent, tuple(checks), singular_ratio=ratio, family_dimension=family,
        wall_time_s=time.perf_counter() - start, warnings=tuple(warnings), **common)


@dataclass(frozen=True)
class Multipliers:
    """The monodromy's multipliers split into the trivial ones (1: the flow and each independent integral or
    constraint) and the section map's (largest modulus first); ``size`` = max(1, ‖Φ‖₂)."""

    all: np.ndarray
    trivial_count: int
    section: np.ndarray
    trivial_check: OrbitCheck
    trivial_tolerance: float
    size: float


def split_multipliers(system: MechanicalSystem, p: np.ndarray, x: np.ndarray, fl: Flow) -> Multipliers:
    """The multipliers of Φ(T) at the orbit through ``x``, split, with the trivial ones' check."""
    n = system.dimension
    size = max(1.0, float(np.linalg.norm(fl.monodromy, 2)))
    mu = np.linalg.eigvals(fl.monodromy)
    grads = integral_gradients(system)(x[None, :], p)[0].reshape(-1, n)
    norms = np.linalg.norm(grads, axis=1)
    grads = grads[norms > 0] / norms[norms > 0, None]
    rank = int(np.linalg.matrix_rank(grads, tol=1e-8)) if len(grads) else 0
    trivial = min(1 + rank, n)
    order = np.argsort(np.abs(mu - 1.0), kind="stable")
    trivial_mu, section_mu = mu[order[:trivial]], mu[order[trivial:]]
    trivial_dev = float(np.max(np.abs(trivial_mu - 1.0)))
    trivial_tol = max(1e-6, 100.0 * float(np.sqrt(MACHINE_EPSILON * size)))
    section_mu = section_mu[np.argsort(-np.abs(section_mu), kind="stable")]
    check = OrbitCheck("trivial_multipliers", trivial_dev <= trivial_tol, trivial_dev, 0.0, trivial_tol,
                       f"{trivial} multipliers of the monodromy are 1 (the flow's direction and {rank} independent "
                       f"integrals or constraints); the largest |mu - 1| among them")
    return Multipliers(mu, trivial, section_mu, check, trivial_tol, size)


def stability_of(section_mu: np.ndarray, at_one: float) -> tuple[float | None, str | None]:
    """The section map's trace and the orbit's linear stability from its multipliers (within ``at_one`` of 1
    all: parabolic, as on a family of orbits)."""
    if len(section_mu) == 0:
        return None, None
    trace = float(np.sum(section_mu).real)
    moduli = np.abs(section_mu)
    if np.all(np.abs(section_mu - 1.0) <= at_one):
        return trace, "parabolic"
    if len(section_mu) == 2 and abs(float(np.prod(section_mu).real) - 1.0) <= 1e-6:
        if abs(abs(trace) - 2.0) <= 1e-9:
            return trace, "parabolic"
        return trace, "elliptic" if abs(trace) < 2.0 else "hyperbolic"
    if np.all(np.abs(moduli - 1.0) <= 1e-9):
        return trace, "elliptic"
    if np.all(moduli < 1.0):
        return trace, "attracting"
    return trace, "unstable"


def product_check(system: MechanicalSystem, p: np.ndarray, x: np.ndarray, fl: Flow, mu: np.ndarray,
                   size: float) -> OrbitCheck:
    """det Φ(T) = Π μ against ρ(x₀)/ρ(x(T)) of the claimed measure (Liouville)."""
    product = float(np.prod(mu).real)
    liouville = float(np.exp(fl.divergence_integral))
    tol = PRODUCT_TOLERANCE * size
    if system.measure.density is None:
        return OrbitCheck("multiplier_product", None, product, None, None,
                          f"no invariant measure is claimed: the product is exp(int div f dt) = {liouville:.15g}, "
                          "checked against no density")
    rho = numeric(system).density(np.stack([x, fl.state]), p)[:, 0]
    expected = float(rho[0] / rho[1])
    return OrbitCheck("multiplier_product", abs(product - expected) <= tol, product, expected, tol,
                      f"product of the monodromy's multipliers = rho(x0)/rho(x(T)) for the measure "
                      f"{system.measure.formula}; exp(int div f dt) = {liouville:.15g}")


def _in_span(g: np.ndarray, rows_: np.ndarray) -> bool:
    """Whether ``g`` is a combination of ``rows_`` (to 1e-8 of its size)."""
    if len(rows_) == 0:
        return False
    coef = np.linalg.lstsq(rows_.T, g, rcond=None)[0]
    return float(np.linalg.norm(rows_.T @ coef - g)) <= 1e-8 * max(float(np.linalg.norm(g)), 1e-300)


def _family_reason(system: MechanicalSystem, p: np.ndarray, x: np.ndarray, null: np.ndarray,
                   chosen: tuple[str, ...], family: int, ratio: float) -> str:
    """What the family of periodic orbits through x is: which unfixed integrals it keeps."""
    n = system.dimension
    others = [i for i in system.integrals if i.name not in chosen]
    kept: list[str] = []
    moved: list[str] = []
    if others:
        grads = integral_gradients(system)(x[None, :], p)[0].reshape(-1, n)
        names = [i.name for i in system.integrals]
        held = np.array([g / max(float(np.linalg.norm(g)), 1e-300) for k, g in enumerate(grads)
                         if k >= len(names) or names[k] in chosen])
        for k, integral in enumerate(system.integrals):
            g = grads[k]
            if integral.name in chosen or _in_span(g, held):  # held, or fixed by what is held (|gamma| = 1)
                continue
            change = max(abs(float(g @ v[:n])) / max(float(np.linalg.norm(g) * np.linalg.norm(v[:n])), 1e-300)
                         for v in null)
            (kept if change < 1e-6 else moved).append(integral.name)
    text = (f"the closing equations are rank-deficient here (singular values' ratio {ratio:.2g}): the periodic "
            f"orbits through this point form a {family}-parameter family on the level, so none is isolated")
    if kept and not moved:
        return text + (f"; the family keeps {', '.join(kept)} constant: a resonant torus of an integrable system, "
                       "where every orbit is periodic with this period")
    if moved:
        return text + f"; {', '.join(moved)} change along it: fix them too (periodic_orbit.level) for isolated orbits"
    return text + " (as on a resonant torus of an integrable system)"
