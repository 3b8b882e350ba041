"""Lyapunov spectra from heyoka's variational equations, with the structure that constrains them.

The tangent flow is integrated exactly as heyoka derives it from the system's one symbolic
definition: ``hy.var_ode_sys(taylor_system(system).state_equations, hy.var_args.vars, order=1)``
(τ is not needed), i.e. the state x and the n×n matrix Φ = ∂x(t)/∂x(t₀) with dΦ/dt = (∂f/∂x) Φ,
plus one quadrature variable s with ds/dt = div f. Every ``interval`` the columns of Φ (which start
from an orthonormal frame Q) are re-orthonormalised by a QR factorisation Φ Q = Q' R and
log|R_ii| is accumulated (the standard method of Benettin, Galgani, Giorgilli and Strelcyn 1980;
Shimada and Nagashima 1979): ``λ_i = Σ log|R_ii| / (t_final − transient)``. No two-trajectory
differences are taken.

Structure reported beside the exponents:

* **The sum.** Liouville: d/dt ln det Φ = div f, so Σ_i λ_i(T) = (1/T) ∫ div f dt exactly, for
  every T. A claimed invariant measure ρ d(state) (``div(ρ f) = 0``; Chaplygin's ball eq. 2604-3,
  the ball on a quadric eq. 2804-3) gives div f = −d/dt ln ρ along an orbit, so
  Σ_i λ_i(T) = −[ln ρ]_{t₀}^{T} / T → 0 on a bounded orbit where ρ stays positive and finite.
  Three numbers are reported: the sum of the exponents (from R), the quadrature (1/T)∫div f dt
  (``divergence_average``, independent of R and of the claim) and the claim's prediction
  −[ln ρ]/T (``measure_average``). A measure that is not invariant shows as a mismatch (warning).
* **Exponents that must vanish.** The variational equations live in the ambient coordinates (6
  for the ball: M, γ), where the constraints (|γ| = 1, Φ(x) = 0 ...) are first integrals too.
  One exponent vanishes for the time direction (f(x(t)) = Φ f(x(t₀)) stays bounded and away from 0
  on a bounded orbit off equilibria) and one for each functionally independent first integral I
  (the covector dI is carried unchanged by the adjoint flow). Dependent ones (|γ| = 1 beside
  (γ, γ)) are listed but not counted. If the measure holds and only one exponent is left, it
  vanishes too (the sum is 0): the ball with U = 0 has time + H + (γ, γ) + c + F = 5, hence all 6.
"""

from __future__ import annotations

import copy
import math
import threading
import time
from dataclasses import dataclass, replace
from functools import lru_cache

import heyoka as hy
import numpy as np
import sympy as sp
from scipy.linalg.lapack import dgeqrf, dorgqr

from nonholonomic.definition import MechanicalSystem
from nonholonomic.integration import (
    MACHINE_EPSILON,
    IntegrationCancelled,
    IntegrationError,
    ProgressCallback,
)
from nonholonomic.kernels import VectorKernel, numeric, vectorize
from nonholonomic.taylor import taylor_system

#: Seed of the fixed (reproducible) random orthonormal frame the tangent vectors start from.
FRAME_SEED = 1980
#: At most this many rows of the running estimates are kept (evenly thinned, last one always).
MAX_CONVERGENCE_ROWS = 1000
#: A run may not need more re-orthonormalisations than this (``interval`` too small for ``t_final``).
MAX_QR_STEPS = 5_000_000
#: Relative tolerance of the numerical rank of the integrals' gradients (normalised rows).
RANK_TOLERANCE = 1e-7
#: A constraint counts as a first integral if ``|∇c · f| ≤ this · |∇c| |f|`` on and off its level.
LIE_TOLERANCE = 1e-9
#: Relative mismatch (to ``max(1, Σ|λ_i|)``) between the exponents' sum and the measure's
#: prediction −[ln ρ]/T beyond which the claimed measure is reported as contradicted.
MEASURE_TOLERANCE = 1e-6
#: Same, between the sum and the quadrature of div f (the variational integration's accuracy).
QUADRATURE_TOLERANCE = 1e-8
#: A running estimate that still moves by more than this fraction of max|λ_i| over the last 20 %
#: of the run is reported as not converged.
CONVERGENCE_WARNING = 0.05


@dataclass(frozen=True)
class ExpectedZero:
    """One structural reason for a vanishing exponent.

    Attributes
    ----------
    reason : ``"time direction"``, ``"first integral energy (eq. 2604-2)"``, ``"constraint |gamma| = 1
        (eq. 2604-2)"`` or ``"invariant measure (eq. 2604-3)"``.
    formula : the integral's or constraint's formula (empty for the time direction).
    counted : whether it adds a zero exponent (False: dependent on those above, not conserved off
        its level set, or the orbit is an equilibrium).
    note : why it counts or not.
    """

    reason: str
    formula: str
    counted: bool
    note: str


@dataclass(frozen=True)
class Spectrum:
    """A Lyapunov spectrum, its convergence and its structural evidence.

    Attributes
    ----------
    exponents : the ``count`` largest exponents, descending, in 1/s (per unit of physical time t).
    all_exponents : the whole spectrum (``system.dimension`` values, descending); the variational
        equations always carry all n tangent vectors, ``count`` only truncates ``exponents``.
    convergence_t : times of the kept QR steps after the transient (at most ~1000, evenly thinned,
        the last one at ``t_final``).
    convergence : shape ``(len(convergence_t), count)``: the running estimates
        ``Σ_{t_k ≤ t} log|R_ii| / (t − transient)``.
    sum : Σ of the whole spectrum (= (1/T)∫ div f dt by Liouville).
    sum_expected : 0 (the limit T → ∞ the invariant measure predicts); ``None`` never for the
        systems here (each claims a measure).
    sum_reason : the argument, with the measure's formula and equation.
    divergence_average : (1/T) ∫ div f dt along the orbit by quadrature (an integrated variable,
        independent of R and of the claimed measure).
    measure_average : −[ln ρ]_{transient}^{t_final} / T: what the claimed measure predicts for the
        sum at this T (``None`` if ρ is not positive and finite at both ends).
    measure_consistent : whether ``sum`` equals ``measure_average`` (relative
        :data:`MEASURE_TOLERANCE`); False means the claimed measure is not invariant.
    expected_zero : every reason considered, counted or not.
    zero_count : how many exponents must vanish (the counted reasons).
    zero_indices : indices into ``all_exponents`` of the ``zero_count`` smallest in magnitude.
    zero_observed : their values (they decay like ln T / T, not faster).
    moved_last_20pct : per reported exponent, max − min of its running estimate over the last
        20 % of the run (how far it still moves).
    symmetry_residual : for a reversible field (see :func:`reversing_involution`),
        ``max_i |λ_i + λ_{n+1−i}|`` of the whole spectrum: how far it is from symmetric; else None.
    method : how it was computed.
    interval, transient, t_final, tolerance : as requested (tolerance as used).
    steps : QR re-orthonormalisations after the transient.
    integrator_steps : heyoka's accepted steps (transient included).
    wall_time_s : wall time of the run (compilation excluded).
    warnings : anything a reader must know (contradicted measure, not converged, equilibrium ...).
    """

    exponents: np.ndarray
    all_exponents: np.ndarray
    convergence_t: np.ndarray
    convergence: np.ndarray
    sum: float
    sum_expected: float | None
    sum_reason: str
    divergence_average: float | None
    measure_average: float | None
    measure_consistent: bool | None
    expected_zero: tuple[ExpectedZero, ...]
    zero_count: int
    zero_indices: np.ndarray
    zero_observed: np.ndarray
    moved_last_20pct: np.ndarray
    symmetry_residual: float | None
    method: str
    interval: float
    transient: float
    t_final: float
    tolerance: float
    steps: int
    integrator_steps: int
    wall_time_s: float
    warnings: tuple[str, ...]


# --- the variational system ------------------------------------------------------------------------


@lru_cache(maxsize=16)
def variational_equations(system: MechanicalSystem) -> tuple[tuple[hy.expression, hy.expression], ...]:
    """The heyoka equations of the tangent flow of ``system``: x, then Φ, then s = ∫ div f dt.

    Φ is ``hy.var_ode_sys(state_equations, hy.var_args.vars, order=1)``'s matrix ∂x_i/∂x_j(t₀),
    stored row-major after the n state variables (entry ``n + i n + j``); the layout is checked
    against heyoka's names for the partials.

    Raises
    ------
    RuntimeError
        If heyoka's layout of the partials is not the documented row-major one.
    """
    ts = taylor_system(system)
    n = ts.n_state
    vs = hy.var_ode_sys(ts.state_equations, hy.var_args.vars, order=1)
    eqs = list(vs.sys)
    names = [str(v) for v in ts.variables[:n]]
    for i in range(n):
        for j in range(n):
            lhs = str(eqs[n + i * n + j][0])
            if lhs != f"∂[({j}, 1)]{names[i]}":
                raise RuntimeError(f"unexpected heyoka variational layout: entry {n + i * n + j} is {lhs}")
    divergence = hy.sum([hy.diff(rhs, var) for var, rhs in ts.state_equations])
    s = hy.make_vars("lyapunov_div_f")
    return tuple(eqs) + ((s, divergence),)


@lru_cache(maxsize=16)
def variational_template(system: MechanicalSystem, tolerance: float) -> hy.taylor_adaptive:
    """Compile the tangent-flow integrator at ``tolerance``, once per process.

    Compact mode: Chaplygin's ball in a linear field (43 variables) compiles in about a second;
    without it, in about two minutes, for a propagation only ~1.6× faster.
    """
    eqs = list(variational_equations(system))
    return hy.taylor_adaptive(eqs, np.zeros(len(eqs)), tol=tolerance, compact_mode=True)


@lru_cache(maxsize=16)
def variational_batch_template(system: MechanicalSystem, tolerance: float, lanes: int) -> hy.taylor_adaptive_batch:
    """Compile the batch-mode tangent-flow integrator (``lanes`` members), once per process."""
    eqs = list(variational_equations(system))
    return hy.taylor_adaptive_batch(eqs, np.zeros((len(eqs), lanes)), tol=tolerance, compact_mode=True)


_per_thread = threading.local()


def _integrator(system: MechanicalSystem, tolerance: float, lanes: int = 0) -> hy.taylor_adaptive:
    """This thread's own copy of the compiled integrator (``lanes`` 0: scalar)."""
    cache: dict[tuple[object, ...], object] = _per_thread.__dict__.setdefault("cache", {})
    key = (system, tolerance, lanes)
    if key not in cache:
        template = (variational_template(system, tolerance) if lanes == 0
                    else variational_batch_template(system, tolerance, lanes))
        cache[key] = copy.deepcopy(template)
    return cache[key]  # type: ignore[return-value]


def initial_frame(n: int) -> np.ndarray:
    """The orthonormal n×n frame the tangent vectors start from (fixed seed: reproducible, and
    generic, unlike the coordinate axes, which may lie in an invariant subspace)."""
    q, r = np.linalg.qr(np.random.default_rng(FRAME_SEED).standard_normal((n, n)))
    return q * np.sign(np.diag(r))


def _qr_times(t_final: float, interval: float, transient: float) -> tuple[np.ndarray, int]:
    """The QR times (transient phase, then the averaged phase) and where the averaged phase starts."""

    def segment(start: float, end: float) -> np.ndarray:
        span = end - start
        if span <= 0:
            return np.empty(0)
        k = max(int(math.ceil(span / interval * (1 - 1e-12))), 1)
        return np.append(start + np.arange(1, k) * interval, end)

    before, after = segment(0.0, transient), segment(transient, t_final)
    return np.concatenate([before, after]), len(before)


class _Accumulator:
    """The log|R_ii| sums of one member after the transient, the thinned running estimates and the
    range of the estimates over the last 20 % of the run."""

    def __init__(self, n: int, times: np.ndarray, first: int, transient: float) -> None:
        self.n, self.times, self.first, self.transient = n, times, first, transient
        steps = len(times) - first
        stride = max(1, math.ceil(steps / MAX_CONVERGENCE_ROWS))
        kept = np.arange(first, len(times), stride)
        if kept[-1] != len(times) - 1:
            kept = np.append(kept, len(times) - 1)
        self.kept = set(kept.tolist())
        self.rows_t: list[float] = []
        self.rows: list[np.ndarray] = []
        self.late_from = transient + 0.8 * (times[-1] - transient)
        self.late_min = np.full(n, np.inf)
        self.late_max = np.full(n, -np.inf)
        self.logs = np.zeros(n)
        self.divergence = 0.0
        self.state_start: np.ndarray | None = None

    def add(self, k: int, logs: np.ndarray, divergence: float) -> None:
        """QR step ``k`` (index into ``times``) gave ``logs``; ``divergence`` = ∫ div f over the interval."""
        if k < self.first:
            return
        self.logs += logs
        self.divergence += divergence
        t = float(self.times[k])
        estimate = self.logs / (t - self.transient)
        if k in self.kept:
            self.rows_t.append(t)
            self.rows.append(estimate.copy())
        if t >= self.late_from:
            np.minimum(self.late_min, estimate, out=self.late_min)
            np.maximum(self.late_max, estimate, out=self.late_max)


def _reorthonormalise(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """QR of the evolved frame: the new orthonormal frame and log|R_ii| (Householder: LAPACK's
    dgeqrf/dorgqr, called directly, a sixth of numpy.linalg.qr's overhead on a 6×6 matrix)."""
    qr, tau, _, info = dgeqrf(V)
    if info != 0:
        raise IntegrationError(f"QR factorisation failed (LAPACK info {info})")
    with np.errstate(divide="ignore"):
        logs = np.log(np.abs(np.diag(qr)))
    q, _, info = dorgqr(qr, tau)
    return q, logs


# --- structure: which exponents must vanish --------------------------------------------------------


@dataclass(frozen=True)
class _StructureKernels:
    gradients: VectorKernel  # rows: integrals, then constraints; n columns each (flattened)
    n_integrals: int
    n_constraints: int


@lru_cache(maxsize=16)
def _structure_kernels(system: MechanicalSystem) -> _StructureKernels:
    exprs = [i.expression for i in system.integrals] + [c.expression for c in system.constraints]
    flat = [sp.diff(e, x) for e in exprs for x in system.state_symbols] or [sp.Integer(0)]
    return _StructureKernels(vectorize(flat, system.state_symbols + system.parameter_symbols),
                             len(system.integrals), len(system.constraints))


def _rank(rows: np.ndarray) -> int:
    """Numerical rank of gradient rows (each normalised; zero rows do not count)."""
    norms = np.linalg.norm(rows, axis=1)
    rows = rows[norms > 0] / norms[norms > 0, None]
    if len(rows) == 0:
        return 0
    s = np.linalg.svd(rows, compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * s[0]))


def reversing_involution(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> str | None:
    """A linear reversing involution G that flips the sign of some state vectors, if the field has one:
    ``f(G x) = −G f(x)`` (so t → −t, x → G x maps orbits to orbits), checked numerically at ``states``
    and at random points near them. Returns e.g. ``"M -> -M"`` or None.
    """
    X = np.atleast_2d(states)
    probes = np.vstack([X, X + 1e-2 * (1 + np.abs(X)) * np.random.default_rng(FRAME_SEED).standard_normal(X.shape)])
    kernels = numeric(system)
    sizes = [len(v.symbols) for v in system.state]
    with np.errstate(all="ignore"):
        f = kernels.rhs(probes, parameters)
    for mask in range(1, 2 ** len(system.state)):
        signs = np.concatenate([np.full(k, -1.0 if mask >> i & 1 else 1.0) for i, k in enumerate(sizes)])
        with np.errstate(all="ignore"):
            g = kernels.rhs(probes * signs, parameters)
        residual = np.linalg.norm(g + f * signs, axis=1)
        if np.all(np.isfinite(residual)) and np.all(residual <= 1e-12 * np.maximum(np.linalg.norm(f, axis=1), 1e-300)):
            return ", ".join(f"{v.name} -> -{v.name}" for i, v in enumerate(system.state) if mask >> i & 1)
    return None


def expected_zeros(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray,
                   measure_holds: bool | None) -> tuple[ExpectedZero, ...]:
    """The structural reasons for vanishing exponents of the orbit through ``states`` (its ends).

    Parameters
    ----------
    system, parameters : the system and its parameter vector.
    states : a few states of the orbit, shape ``(k, n)`` (the gradients' independence is judged
        at each; a reason counts if it adds rank at any of them).
    measure_holds : whether the observed sum agrees with the claimed measure (None: unknown).

    Returns
    -------
    tuple of ExpectedZero
        Time direction, each first integral, each constraint and, where it decides the last one,
        the invariant measure; ``counted`` marks those that add a zero exponent.
    """
    n = system.dimension
    p = np.asarray(parameters, dtype=float)
    X = np.atleast_2d(states)
    kernels = numeric(system)
    sk = _structure_kernels(system)
    with np.errstate(all="ignore"):
        f = kernels.rhs(X, p)
        grads = sk.gradients(X, p).reshape(len(X), -1, n) if sk.n_integrals + sk.n_constraints else None
    out: list[ExpectedZero] = []
    moving = bool(np.all(np.isfinite(f)) and np.all(np.linalg.norm(f, axis=1) > 0))
    out.append(ExpectedZero(
        "time direction", "f(x)", moving,
        "the flow carries f(x(t0)) into f(x(t)), bounded and non-zero on a bounded orbit off equilibria"
        if moving else "f vanishes at the orbit (an equilibrium): no time direction"))
    basis: list[np.ndarray] = [np.empty((0, n)) for _ in X]

    def try_add(row_index: int) -> tuple[bool, str]:
        rows = grads[:, row_index, :]  # type: ignore[index]
        if not np.all(np.isfinite(rows)):
            return False, "its gradient is not finite at the orbit"
        gained = False
        for k in range(len(X)):
            extended = np.vstack([basis[k], rows[k]])
            if _rank(extended) > _rank(basis[k]):
                gained = True
        if not gained:
            return False, "functionally dependent on the ones above at the orbit (adds no rank)"
        for k in range(len(X)):
            basis[k] = np.vstack([basis[k], rows[k]])
        return True, "independent: the adjoint flow keeps its gradient, one exponent vanishes"

    for i, integral in enumerate(system.integrals):
        counted, note = try_add(i)
        out.append(ExpectedZero(f"first integral {integral.name} (eq. {integral.equation})", integral.formula,
                                counted, note))
    rng = np.random.default_rng(FRAME_SEED)
    for j, constraint in enumerate(system.constraints):
        row = sk.n_integrals + j
        # A constraint is a first integral of the ambient flow only if ∇c · f vanishes off its level too.
        probes = np.vstack([X, X + 1e-2 * (1 + np.abs(X)) * rng.standard_normal(X.shape)])
        with np.errstate(all="ignore"):
            g = sk.gradients(probes, p).reshape(len(probes), -1, n)[:, row, :]
            fp = kernels.rhs(probes, p)
        lie = np.abs(np.einsum("ij,ij->i", g, fp))
        scale = np.linalg.norm(g, axis=1) * np.linalg.norm(fp, axis=1)
        conserved = bool(np.all(np.isfinite(lie)) and np.all(lie <= LIE_TOLERANCE * np.maximum(scale, 1e-300)))
        if not conserved:
            out.append(ExpectedZero(f"constraint {constraint.formula} (eq. {constraint.equation})", constraint.formula,
                                    False, "not conserved off its level set (an invariant manifold only): "
                                           "the exponent transverse to it need not vanish"))
            continue
        counted, note = try_add(row)
        out.append(ExpectedZero(f"constraint {constraint.formula} (eq. {constraint.equation})", constraint.formula,
                                counted, "conserved by the ambient flow; " + note))
    zeros = sum(z.counted for z in out)
    reversing = reversing_involution(system, p, X)
    if reversing is not None:
        out.append(ExpectedZero(
            f"reversibility ({reversing}, t -> -t)", reversing, False,
            "not counted: if the orbit's ergodic component is invariant under the involution (typical of a chaotic "
            "sea that meets its fixed set), the spectrum is symmetric, {lambda_i} = {-lambda_i}; with an odd "
            f"number ({n - zeros}) left beside the counted zeros one more then vanishes" if (n - zeros) % 2 else
            "not counted: if the orbit's ergodic component is invariant under the involution (typical of a chaotic "
            "sea that meets its fixed set), the spectrum is symmetric, {lambda_i} = {-lambda_i}"))
    if measure_holds and n - zeros == 1:
        out.append(ExpectedZero(
            f"invariant measure (eq. {system.measure.equation})", system.measure.formula, True,
            "the spectrum sums to 0 and only one exponent is left, so it vanishes too"))
    return tuple(out)


# --- one run ---------------------------------------------------------------------------------------


def _validate(system: MechanicalSystem, t_final: float, count: int | None, interval: float, transient: float,
              tolerance: float | None) -> tuple[int, float]:
    n = system.dimension
    if not (math.isfinite(t_final) and t_final > 0):
        raise ValueError(f"t_final: must be a finite number > 0, got {t_final}")
    if not (math.isfinite(interval) and interval > 0):
        raise ValueError(f"interval: must be a finite number > 0, got {interval}")
    if not (math.isfinite(transient) and 0 <= transient < t_final):
        raise ValueError(f"transient: must satisfy 0 <= transient < t_final = {t_final:g}, got {transient}")
    if t_final / interval > MAX_QR_STEPS:
        raise ValueError(f"interval: {interval:g} needs more than {MAX_QR_STEPS} re-orthonormalisations up to "
                         f"t_final = {t_final:g}")
    c = n if count is None else count
    if isinstance(c, bool) or int(c) != c or not 1 <= c <= n:
        raise ValueError(f"count: must be an integer between 1 and the dimension {n}, got {count}")
    tol = MACHINE_EPSILON if tolerance is None else float(tolerance)
    if not (math.isfinite(tol) and 0 < tol < 1):
        raise ValueError(f"tolerance: must be a number in (0, 1), got {tolerance}")
    return int(c), tol


def _check_inputs(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> None:
    n_user = len(system.parameter_symbols)
    if parameters.shape[-1] != n_user:
        raise ValueError(f"parameters: {system.kind} needs {n_user} parameters, got shape {parameters.shape}")
    if states.shape[-1] != system.dimension:
        raise ValueError(f"initial_state: {system.kind} needs {system.dimension} components, got shape {states.shape}")
    if not (np.all(np.isfinite(parameters)) and np.all(np.isfinite(states))):
        raise ValueError("parameters/initial_state: non-finite number")


def _method(system: MechanicalSystem, tol: float, interval: float) -> str:
    n = system.dimension
    return (f"heyoka {hy.__version__} Taylor integrator (tol = {tol:.3g}, compact mode) of the variational "
            f"equations hy.var_ode_sys(state equations, var_args.vars, order=1) generated from the symbolic "
            f"definition: the state, the {n}x{n} tangent matrix and the quadrature of div f; the tangent frame "
            f"(a fixed random orthonormal one at t = 0) is re-orthonormalised by Householder QR every "
            f"{interval:g} (Benettin et al. 1980), lambda_i = sum log|R_ii| / (t_final - transient)")


def _finish(system: MechanicalSystem, p: np.ndarray, acc: _Accumulator, end_state: np.ndarray, count: int,
            interval: float, transient: float, t_final: float, tol: float, integrator_steps: int,
            wall: float) -> Spectrum:
    """The :class:`Spectrum` of one member from its accumulated sums."""
    span = t_final - transient
    values = acc.logs / span
    order = np.argsort(-values, kind="stable")
    values = values[order]
    rows = np.asarray(acc.rows)[:, order]
    moved = (acc.late_max - acc.late_min)[order]
    total = float(np.sum(acc.logs) / span)
    divergence_average = acc.divergence / span
    scale = max(1.0, float(np.sum(np.abs(values))))

    measure = system.measure
    with np.errstate(all="ignore"):
        rho = (np.full(2, np.nan) if measure.density is None else
               numeric(system).density(np.vstack([acc.state_start, end_state]), p)[:, 0])
    if np.all(np.isfinite(rho)) and np.all(rho > 0):
        measure_average: float | None = float(-(math.log(rho[1]) - math.log(rho[0])) / span)
        consistent: bool | None = abs(total - measure_average) <= MEASURE_TOLERANCE * scale
    else:
        measure_average, consistent = None, None
    sum_reason = (f"invariant measure rho d(state), {measure.formula} (eq. {measure.equation}): "
                  "div(rho f) = 0 => div f = -d/dt ln rho along the orbit => the sum of the full spectrum, "
                  "(1/T) int div f dt (Liouville: d/dt ln det Phi = div f), equals -[ln rho]_0^T / T -> 0 "
                  "(rho positive and bounded on a bounded orbit)")

    warnings: list[str] = []
    if consistent is False:
        warnings.append(f"the sum of the spectrum {total:.6g} (quadrature of div f: {divergence_average:.6g}) "
                        f"contradicts the claimed invariant measure {measure.formula} "
                        f"(eq. {measure.equation}), which predicts -[ln rho]/T = {measure_average:.6g}: "
                        "div(rho f) != 0 along this orbit")
    elif consistent is None:
        warnings.append("the density rho is not positive and finite at both ends of the orbit: "
                        "no measure prediction for the sum")
    if abs(total - divergence_average) > QUADRATURE_TOLERANCE * scale:
        warnings.append(f"the sum of the exponents {total:.12g} differs from the quadrature of div f "
                        f"{divergence_average:.12g}: the variational integration is inaccurate")

    zeros = expected_zeros(system, p, np.vstack([acc.state_start, end_state]), consistent)
    zero_count = sum(z.counted for z in zeros)
    zero_indices = np.sort(np.argsort(np.abs(values), kind="stable")[:zero_count])
    if not next(z for z in zeros if z.reason == "time direction").counted:
        warnings.append("the orbit is an equilibrium (f = 0): no exponent is forced to vanish by the time direction")
    reach = float(np.max(np.abs(values)))
    if reach > 0 and float(np.max(moved[:count])) > CONVERGENCE_WARNING * reach:
        worst = int(np.argmax(moved[:count]))
        warnings.append(f"not converged: exponent {worst + 1} still moves by {moved[worst]:.3g} over the last 20 % "
                        f"of the run (max |lambda| = {reach:.3g}); run longer")
    if len(acc.rows) and not np.all(np.isfinite(values)):
        warnings.append("non-finite exponents")
    return Spectrum(
        exponents=values[:count].copy(), all_exponents=values, convergence_t=np.asarray(acc.rows_t),
        convergence=rows[:, :count].copy(), sum=total, sum_expected=0.0, sum_reason=sum_reason,
        divergence_average=float(divergence_average), measure_average=measure_average,
        measure_consistent=consistent, expected_zero=zeros, zero_count=zero_count, zero_indices=zero_indices,
        zero_observed=values[zero_indices], moved_last_20pct=moved[:count].copy(),
        symmetry_residual=(float(np.max(np.abs(values + values[::-1])))
                           if any(z.reason.startswith("reversibility") for z in zeros) else None),
        method=_method(system, tol, interval), interval=float(interval), transient=float(transient),
        t_final=float(t_final), tolerance=tol, steps=len(acc.times) - acc.first,
        integrator_steps=int(integrator_steps), wall_time_s=wall, warnings=tuple(warnings))


def spectrum(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_state: np.ndarray,
    t_final: float,
    *,
    count: int | None = None,
    interval: float = 1.0,
    transient: float = 0.0,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> Spectrum:
    """The Lyapunov spectrum of the orbit through ``initial_state`` (QR method on heyoka's
    variational equations).

    Parameters
    ----------
    system : the symbolic definition.
    parameters : the system's parameters, in the order of ``system.parameter_symbols``.
    initial_state : x(0), in the order of ``system.state_symbols``.
    t_final : end of the run; the exponents average over ``[transient, t_final]``.
    count : how many exponents to report (the largest; default the whole spectrum,
        ``system.dimension``).
    interval : time between re-orthonormalisations (the last one may be shorter).
    transient : time integrated first (with re-orthonormalisation, so the frame aligns too) and
        left out of the averages.
    tolerance : heyoka's tolerance (default machine epsilon).
    progress : ``progress(t / t_final) -> keep_going`` after each re-orthonormalisation; False
        cancels (raises :class:`IntegrationCancelled`).

    Returns
    -------
    Spectrum

    Raises
    ------
    ValueError
        Naming the field (``t_final``, ``interval``, ``transient``, ``count``, ``tolerance``,
        ``parameters``, ``initial_state``).
    IntegrationError
        If heyoka stops early (non-finite state ...).
    IntegrationCancelled
    """
    count_, tol = _validate(system, float(t_final), count, float(interval), float(transient), tolerance)
    p = np.asarray(parameters, dtype=float)
    y0 = np.asarray(initial_state, dtype=float)
    _check_inputs(system, p, y0)
    if p.ndim != 1 or y0.ndim != 1:
        raise ValueError("parameters/initial_state: need one vector each")
    n = system.dimension
    ts = taylor_system(system)
    ta = _integrator(system, tol)  # compiled once per process, copied once per thread; not timed
    start = time.perf_counter()
    times, first = _qr_times(float(t_final), float(interval), float(transient))
    acc = _Accumulator(n, times, first, float(transient))
    if first == 0:
        acc.state_start = y0.copy()
    Q = initial_frame(n)
    ta.time = 0.0
    ta.pars[:] = ts.runtime_parameters(p)[: len(ta.pars)]
    state = ta.state
    state[:n] = y0
    steps = 0
    for k, t in enumerate(times):
        state[n: n + n * n] = Q.reshape(-1)
        state[-1] = 0.0
        outcome, _, _, nsteps, _, _ = ta.propagate_until(float(t))
        steps += nsteps
        if outcome != hy.taylor_outcome.time_limit:
            raise IntegrationError(f"heyoka stopped at t = {ta.time:g} with outcome {outcome.name}")
        Q, logs = _reorthonormalise(state[n: n + n * n].reshape(n, n))
        if not np.all(np.isfinite(logs)):
            raise IntegrationError(f"degenerate tangent frame at t = {t:g} (log|R_ii| = {logs.tolist()})")
        acc.add(k, logs, float(state[-1]))
        if k + 1 == first:
            acc.state_start = state[:n].copy()
        if progress is not None and not progress(min(float(t) / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {t:g}")
    return _finish(system, p, acc, state[:n].copy(), count_, float(interval), float(transient), float(t_final),
                   tol, steps, time.perf_counter() - start)


def largest_batch(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_states: np.ndarray,
    t_final: float,
    *,
    interval: float = 1.0,
    transient: float = 0.0,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> list[Spectrum | IntegrationError]:
    """The largest exponent of each member (``count = 1``) with heyoka's batch mode.

    ``hy.recommended_simd_size()`` members share one batch integrator of the same variational
    equations as :func:`spectrum` (the last batch padded with copies of its last member); each
    member's :class:`Spectrum` is the one :func:`spectrum` gives it with ``count = 1``, equal up to
    rounding in the last bits (heyoka's vectorised code may round differently; on a chaotic orbit
    that difference grows like the trajectories' own), except ``wall_time_s``: the batch's wall time
    divided among its members. A member whose lane fails fails alone: its entry is the
    :class:`IntegrationError` that integrating it alone gives; the batch is then run again without it.

    Parameters
    ----------
    parameters : shape ``(n_members, n_parameters)``.
    initial_states : shape ``(n_members, dimension)``.
    t_final, interval, transient, tolerance : as for :func:`spectrum`.
    progress : ``progress(fraction of the members' work done) -> keep_going``; False cancels.

    Returns
    -------
    list
        One :class:`Spectrum` or :class:`IntegrationError` per member, in order.

    Raises
    ------
    ValueError, IntegrationCancelled
    """
    _, tol = _validate(system, float(t_final), 1, float(interval), float(transient), tolerance)
    P = np.asarray(parameters, dtype=float)
    Y0 = np.asarray(initial_states, dtype=float)
    if P.ndim != 2 or Y0.ndim != 2 or len(P) != len(Y0):
        raise ValueError(f"parameters/initial_states: need shapes (n_members, n_parameters) and (n_members, "
                         f"dimension) with the same n_members, got {P.shape} and {Y0.shape}")
    _check_inputs(system, P, Y0)
    lanes = hy.recommended_simd_size()
    results: list[Spectrum | IntegrationError] = []
    for first in range(0, len(P), lanes):
        members = list(range(first, min(first + lanes, len(P))))

        def lane_progress(fraction: float, first: int = first, count: int = len(members)) -> bool:
            return True if progress is None else bool(progress((first + count * fraction) / len(P)))

        results.extend(_batch(system, P[members], Y0[members], float(t_final), float(interval), float(transient),
                              tol, lanes, lane_progress))
    return results


def _batch(system: MechanicalSystem, P: np.ndarray, Y0: np.ndarray, t_final: float, interval: float,
           transient: float, tol: float, lanes: int, progress: ProgressCallback) -> list[Spectrum | IntegrationError]:
    """Up to ``lanes`` members in one batch; a failing member is integrated alone for its error and
    the batch is run again without it (lanes do not influence each other)."""
    failed: dict[int, IntegrationError] = {}
    while True:
        healthy = [i for i in range(len(P)) if i not in failed]
        if not healthy:
            return [failed[i] for i in range(len(P))]
        source = [i if i in healthy else healthy[-1] for i in range(len(P))] + [healthy[-1]] * (lanes - len(P))
        start = time.perf_counter()
        outcome = _run_lanes(system, P[source], Y0[source], t_final, interval, transient, tol, progress)
        if isinstance(outcome, list):
            wall = (time.perf_counter() - start) / len(P)
            return [failed[i] if i in failed else _with_wall(outcome[i], wall) for i in range(len(P))]
        for lane in outcome:
            i = source[lane]
            try:
                spectrum(system, P[i], Y0[i], t_final, count=1, interval=interval, transient=transient, tolerance=tol)
                failed[i] = IntegrationError("batch lane failed; integrated alone it succeeded")
            except IntegrationError as exc:
                failed[i] = exc


def _with_wall(s: Spectrum, wall: float) -> Spectrum:
    return replace(s, wall_time_s=wall)


def _run_lanes(system: MechanicalSystem, P: np.ndarray, Y0: np.ndarray, t_final: float, interval: float,
               transient: float, tol: float, progress: ProgressCallback) -> list[Spectrum] | set[int]:
    """One batch: every lane's spectrum, or the set of lanes that failed."""
    n, lanes = system.dimension, len(P)
    ts = taylor_system(system)
    ta = _integrator(system, tol, lanes)
    times, first = _qr_times(t_final, interval, transient)
    accs = [_Accumulator(n, times, first, transient) for _ in range(lanes)]
    frames = [initial_frame(n) for _ in range(lanes)]
    ta.set_time(0.0)
    ta.pars[:] = ts.runtime_parameters(P.T)[: ta.pars.shape[0]]
    state = ta.state
    state[:n] = Y0.T
    if first == 0:
        for j in range(lanes):
            accs[j].state_start = Y0[j].copy()
    steps = np.zeros(lanes, dtype=np.int64)
    bad: set[int] = set()
    for k, t in enumerate(times):
        for j in range(lanes):
            state[n: n + n * n, j] = frames[j].reshape(-1)
        state[-1] = 0.0
        ta.propagate_until(float(t))
        for j, (outcome, _, _, nsteps) in enumerate(ta.propagate_res):
            steps[j] += nsteps
            if outcome != hy.taylor_outcome.time_limit:
                bad.add(j)
        if bad:
            return bad
        for j in range(lanes):
            frames[j], logs = _reorthonormalise(state[n: n + n * n, j].reshape(n, n))
            if not np.all(np.isfinite(logs)):
                bad.add(j)
            accs[j].add(k, logs, float(state[-1, j]))
            if k + 1 == first:
                accs[j].state_start = state[:n, j].copy()
        if bad:
            return bad
        if not progress(min(float(t) / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {t:g}")
    return [_finish(system, P[j], accs[j], state[:n, j].copy(), 1, interval, transient, t_final, tol,
                    int(steps[j]), 0.0) for j in range(lanes)]
