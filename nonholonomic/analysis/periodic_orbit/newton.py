"""Periodic orbits, the solver: Newton's method on the closing equations, with the monodromy.

A periodic orbit of period ``T`` through ``x₀`` on the section ``S(x) = value`` solves

    x(T; x₀) − x₀ = 0,    S(x₀) − value = 0,    I_j(x₀) − c_j = 0 (the level),    C_i(x₀) − v_i = 0,

``n + 1 + m + q`` equations in the ``n + 1`` unknowns (x₀, T): the section fixes the phase along the
orbit, the level (the seed's values of the fixed integrals) and the constraints (|γ| = 1, ...) the
directions in which periodic orbits of a conservative system come in families. The system is
overdetermined but consistent, and its Jacobian

    J = [[Φ(T) − 1, f(x(T))], [∇S, 0], [∇I_j, 0], [∇C_i, 0]]

has full column rank at an isolated orbit; Φ(T) = ∂x(T)/∂x₀ is the monodromy, integrated with the
state from the variational equations (``hy.var_ode_sys`` of the one definition,
:func:`nonholonomic.analysis.lyapunov.variational.variational_equations`). The Gauss–Newton step is
the least-squares solution of ``J Δ = −R``; it converges quadratically at an isolated orbit and, with
its minimum-norm steps, onto a point of a family of periodic orbits where J is rank-deficient (a
resonant torus of an integrable system). The rows after the first n are scaled to unit gradient, so
every residual is a distance in the state's units.

When Newton wanders (a step that raises the residual, that moves the state by more than
:data:`MAX_STEP` of its size or the period by more than half of it, or an integration that fails),
the solver falls back to Levenberg–Marquardt (``scipy.optimize.least_squares(method="lm")``, the same
residual and Jacobian) from the best point so far, then polishes with Newton again.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import heyoka as hy
import numpy as np
import sympy as sp

from nonholonomic.analysis.lyapunov.variational import _integrator
from nonholonomic.analysis.poincare.surface import parse_surface
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics import tally
from nonholonomic.numerics.integration import IntegrationCancelled, IntegrationError
from nonholonomic.numerics.kernels import VectorKernel, numeric, vectorize
from nonholonomic.numerics.taylor import taylor_system

#: Newton stops when the scaled residual is below this (relative to the state's size) ...
TARGET = 1e-13
#: ... and an orbit is accepted as closed when its best residual is below this.
CLOSING_TOLERANCE = 1e-9
#: A Newton step moving the state by more than this fraction of its size (or T by half) wanders.
MAX_STEP = 0.5
#: Newton iterations before the fallback, and after it to polish.
NEWTON_ITERATIONS = 25
#: Residual evaluations the Levenberg–Marquardt fallback may spend.
FALLBACK_EVALUATIONS = 60


@dataclass(frozen=True)
class Rows:
    """The algebraic rows' kernels: values and gradients of the surface, the level's integrals and the
    constraints, in that order (``names`` labels each row)."""

    names: tuple[str, ...]
    values: VectorKernel
    gradients: VectorKernel
    targets_fixed: tuple[float | None, ...]   # a constraint's value; None: taken from the seed


@lru_cache(maxsize=32)
def rows(system: MechanicalSystem, surface: str, level: tuple[str, ...]) -> Rows:
    """Compile the rows for ``surface`` and the integrals named in ``level`` (checked by the caller)."""
    expr_s = parse_surface(system, surface)
    by_name = {i.name: i.expression for i in system.integrals}
    exprs: list[sp.Expr] = [expr_s] + [by_name[name] for name in level] + [c.expression for c in system.constraints]
    names = ("surface",) + tuple(level) + tuple(f"constraint {c.formula}" for c in system.constraints)
    targets: tuple[float | None, ...] = (None,) + (None,) * len(level) + tuple(float(c.value)
                                                                                for c in system.constraints)
    state = system.state_symbols
    args = list(state) + list(system.parameter_symbols)
    grads = [sp.diff(e, s) for e in exprs for s in state]
    return Rows(names, vectorize(exprs, args), vectorize(grads, args), targets)


@lru_cache(maxsize=32)
def integral_gradients(system: MechanicalSystem) -> VectorKernel:
    """∇I of every first integral and ∇C of every constraint, flattened row-major (for the trivial
    multipliers' count: 1 + their rank at the orbit)."""
    exprs = [i.expression for i in system.integrals] + [c.expression for c in system.constraints]
    state = system.state_symbols
    return vectorize([sp.diff(e, s) for e in exprs for s in state] or [sp.Integer(0)],
                     list(state) + list(system.parameter_symbols))


@dataclass(frozen=True)
class Flow:
    """x(T; x₀), the monodromy Φ(T) and ∫₀ᵀ div f dt, with the Taylor steps taken; ``dx_dlambda``: ∂x(T)/∂λ
    for a continued parameter λ (None without one)."""

    state: np.ndarray
    monodromy: np.ndarray
    divergence_integral: float
    steps: int
    dx_dlambda: np.ndarray | None = None


def flow(system: MechanicalSystem, p: np.ndarray, x0: np.ndarray, t: float, tolerance: float,
         pars: tuple[int, ...] = (), dpars: np.ndarray | None = None) -> Flow:
    """Integrate the state and its variational equations from ``x0`` over [0, ``t``] (heyoka, compact mode);
    with ``pars``, also the sensitivities to those runtime parameters, combined as ∂x(T)/∂λ = Σ_k ∂x(T)/∂p_k
    · ``dpars[k]``.

    Raises
    ------
    IntegrationError
        If ``t`` is not positive and finite, or heyoka stops before ``t``.
    """
    if not (np.isfinite(t) and t > 0):
        raise IntegrationError(f"the period must be positive and finite, got T = {t!r}")
    n, k = system.dimension, len(pars)
    ts = taylor_system(system)
    ta = _integrator(system, tolerance, pars=pars)
    ta.time = 0.0
    ta.pars[:] = ts.runtime_parameters(p)[: len(ta.pars)]
    state = ta.state
    state[:n] = x0
    block = np.zeros((n, n + k))
    block[:, :n] = np.eye(n)
    state[n: n + n * (n + k)] = block.reshape(-1)
    state[-1] = 0.0
    outcome, _, _, steps, _, _ = ta.propagate_until(float(t), max_steps=2_000_000)
    if outcome != hy.taylor_outcome.time_limit or not np.all(np.isfinite(state)):
        raise IntegrationError(f"heyoka stopped at t = {ta.time:g} of {t:g} with outcome {outcome.name}")
    partials = state[n: n + n * (n + k)].reshape(n, n + k)
    dx_dlambda = None if not k or dpars is None else partials[:, n:] @ dpars
    tally.count(integrations=1)
    return Flow(state[:n].copy(), partials[:, :n].copy(), float(state[-1]), int(steps), dx_dlambda)


class CancelCheck:
    """Calls ``progress`` with a growing fraction; raises when it answers False."""

    def __init__(self, progress: Callable[[float], bool] | None, budget: int) -> None:
        self.progress, self.budget, self.done = progress, max(budget, 1), 0

    def tick(self) -> None:
        self.done += 1
        if self.progress is not None and not self.progress(min(self.done / self.budget, 0.99)):
            raise IntegrationCancelled("cancelled during the periodic-orbit search")


@dataclass
class Closing:
    """The closing equations of one search: residual and Jacobian at z = (x₀, T), the last evaluation kept."""

    system: MechanicalSystem
    p: np.ndarray
    rows: Rows
    targets: np.ndarray
    tolerance: float
    cancel: CancelCheck
    scale: float
    evaluations: int = 0
    steps: int = 0
    _last: tuple[bytes, np.ndarray, np.ndarray, Flow] | None = field(default=None, repr=False)

    def evaluate(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, Flow]:
        """R(z), J(z) and the flow (remembered for the last z)."""
        key = z.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1], self._last[2], self._last[3]
        n = self.system.dimension
        x0, t = z[:n], float(z[n])
        self.cancel.tick()
        fl = flow(self.system, self.p, x0, t, self.tolerance)
        R, J, _ = self.assemble(x0, self.p, self.targets, fl, 0)
        self._last = (key, R, J, fl)
        return R, J, fl

    def assemble(self, x0: np.ndarray, p: np.ndarray, targets: np.ndarray, fl: Flow,
                 extra: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """R and J (with ``extra`` zero columns after T, scaled by 1/scale) from a flow; the rows' gradient norms
        (each algebraic row is divided by its own)."""
        n = self.system.dimension
        self.evaluations += 1
        self.steps += fl.steps
        values = self.rows.values(x0[None, :], p)[0]
        grads = self.rows.gradients(x0[None, :], p)[0].reshape(len(values), n)
        norms = np.maximum(np.linalg.norm(grads, axis=1), 1e-300)
        f_t = numeric(self.system).rhs_single(fl.state, p)
        R = np.concatenate([(fl.state - x0), (values - targets) / norms]) / self.scale
        J = np.zeros((n + len(values), n + 1 + extra))
        J[:n, :n] = fl.monodromy - np.eye(n)
        J[:n, n] = f_t
        J[n:, :n] = grads / norms[:, None]
        J /= self.scale
        return R, J, norms

    def residual(self, z: np.ndarray) -> float:
        try:
            return float(np.max(np.abs(self.evaluate(z)[0])))
        except IntegrationError:
            return float("inf")


@dataclass
class Search:
    """What the solver did: the best point, its residual, the residual after each evaluation, the method."""

    z: np.ndarray
    residual: float
    history: list[float]
    method: str
    wandered: str | None = None


def newton(closing: Closing, z: np.ndarray, iterations: int,
           history: list[float]) -> tuple[np.ndarray, float, str | None]:
    """Gauss–Newton from ``z``: the best point, its residual and why it stopped wandering (None: converged
    or stagnated at the noise level)."""
    n = closing.system.dimension
    best, best_r = z, closing.residual(z)
    history.append(best_r)
    if not np.isfinite(best_r):
        return best, best_r, "the integration from the starting point failed"
    for _ in range(iterations):
        if best_r <= TARGET:
            return best, best_r, None
        R, J, _ = closing.evaluate(best)
        step = np.linalg.lstsq(J, -R, rcond=1e-13)[0]
        dx, dt = step[:n], step[n]
        size = max(float(np.max(np.abs(best[:n]))), 1.0)
        if float(np.max(np.abs(dx))) > MAX_STEP * size or abs(dt) > MAX_STEP * best[n]:
            return best, best_r, (f"a step of |dx| = {np.max(np.abs(dx)):.3g}, dT = {dt:.3g} "
                                  f"from T = {best[n]:.6g}")
        trial = best + step
        r = closing.residual(trial)
        history.append(r)
        if not r < best_r:
            if best_r <= CLOSING_TOLERANCE:  # at the noise level: done
                return best, best_r, None
            return best, best_r, f"the residual rose from {best_r:.3g} to {r:.3g}"
        if r > 0.5 * best_r and best_r <= CLOSING_TOLERANCE:  # no longer converging quadratically: noise
            return trial, r, None
        best, best_r = trial, r
    return best, best_r, None if best_r <= CLOSING_TOLERANCE else f"{iterations} iterations without closing"


def levenberg_marquardt(closing: Closing, z: np.ndarray, history: list[float]) -> tuple[np.ndarray, float]:
    """The fallback: ``scipy.optimize.least_squares(method="lm")`` on the same equations from ``z``."""
    from scipy.optimize import least_squares

    def fun(v: np.ndarray) -> np.ndarray:
        try:
            R = closing.evaluate(v)[0]
        except IntegrationError:
            R = np.full(len(closing.targets) + closing.system.dimension, 1e3)
        history.append(float(np.max(np.abs(R))))
        return R

    def jac(v: np.ndarray) -> np.ndarray:
        try:
            return closing.evaluate(v)[1]
        except IntegrationError:
            n = closing.system.dimension
            return np.eye(len(closing.targets) + n, n + 1)

    fit = least_squares(fun, z, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=FALLBACK_EVALUATIONS, x_scale=np.maximum(np.abs(z), 1e-3))
    return fit.x, closing.residual(fit.x)


def solve(closing: Closing, z0: np.ndarray) -> Search:
    """Newton from ``z0``; on wandering, Levenberg–Marquardt from the best point, then Newton again."""
    history: list[float] = []
    z, r, wandered = newton(closing, z0, NEWTON_ITERATIONS, history)
    if wandered is None:
        return Search(z, r, history, "newton")
    z_lm, r_lm = levenberg_marquardt(closing, z, history)
    if r_lm < r:
        z, r = z_lm, r_lm
    z, r, _ = newton(closing, z, NEWTON_ITERATIONS, history)
    return Search(z, r, history, "newton, then levenberg-marquardt", wandered)


def level_values(p: np.ndarray, x: np.ndarray, surface_value: float, level: Sequence[str], r: Rows) -> np.ndarray:
    """The rows' targets at a seed ``x``: the section's value, the seed's integrals, the constraints' values."""
    values = r.values(x[None, :], p)[0]
    fixed: list[float] = []
    for t in r.targets_fixed[1 + len(level):]:
        assert t is not None  # the constraints' values (only the surface's and the level's come from the seed)
        fixed.append(float(t))
    targets = np.array([surface_value] + [float(v) for v in values[1: 1 + len(level)]] + fixed)
    return targets
