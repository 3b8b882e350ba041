"""The result of a Lyapunov run (:mod:`nonholonomic.analysis.lyapunov`): the :class:`Spectrum`, its
running estimates (convergence) and the checks of its sum.

Liouville: d/dt ln det Φ = div f, so Σ_i λ_i(T) = (1/T) ∫ div f dt exactly, for every T. A claimed
invariant measure ρ d(state) (``div(ρ f) = 0``; Chaplygin's ball eq. 2604-3, the ball on a quadric
eq. 2804-3) gives div f = −d/dt ln ρ along an orbit, so Σ_i λ_i(T) = −[ln ρ]_{t₀}^{T} / T → 0 on a
bounded orbit where ρ stays positive and finite. The sum of the exponents (from R), the quadrature
(1/T)∫div f dt and the claim's prediction −[ln ρ]/T are compared here; a mismatch is a warning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import heyoka as hy
import numpy as np

from nonholonomic.analysis.lyapunov.zeros import ExpectedZero, expected_zeros
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.kernels import numeric

#: At most this many rows of the running estimates are kept (evenly thinned, last one always).
MAX_CONVERGENCE_ROWS = 1000
#: Relative mismatch (to ``max(1, Σ|λ_i|)``) between the exponents' sum and the measure's
#: prediction −[ln ρ]/T beyond which the claimed measure is reported as contradicted.
MEASURE_TOLERANCE = 1e-6
#: Same, between the sum and the quadrature of div f (the variational integration's accuracy).
QUADRATURE_TOLERANCE = 1e-8
#: A running estimate that still moves by more than this fraction of max|λ_i| over the last 20 %
#: of the run is reported as not converged.
CONVERGENCE_WARNING = 0.05


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
    sum_expected : 0 (the limit T → ∞ the invariant measure predicts); ``None`` when the system claims
        no measure (a user's system without one found: then the sum need not vanish).
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

    start_state = acc.state_start
    assert start_state is not None  # recorded where the averaged phase starts (the transient is < t_final)
    measure = system.measure
    with np.errstate(all="ignore"):
        rho = (np.full(2, np.nan) if measure.density is None else
               numeric(system).density(np.vstack([start_state, end_state]), p)[:, 0])
    if np.all(np.isfinite(rho)) and np.all(rho > 0):
        average = float(-(math.log(rho[1]) - math.log(rho[0])) / span)
        measure_average: float | None = average
        consistent: bool | None = abs(total - average) <= MEASURE_TOLERANCE * scale
    else:
        measure_average, consistent = None, None
    if measure.density is None:  # nothing claimed: the sum is what the orbit gives, not a prediction
        sum_expected: float | None = None
        sum_reason = (f"no invariant measure is claimed ({measure.formula}): the sum of the full spectrum, "
                      "(1/T) int div f dt (Liouville: d/dt ln det Phi = div f), need not vanish; a flow without "
                      "an invariant measure can contract phase volume (e.g. Chaplygin's sleigh)")
    else:
        sum_expected = 0.0
        sum_reason = (f"invariant measure rho d(state), {measure.formula} (eq. {measure.equation}): "
                      "div(rho f) = 0 => div f = -d/dt ln rho along the orbit => the sum of the full spectrum, "
                      "(1/T) int div f dt (Liouville: d/dt ln det Phi = div f), equals -[ln rho]_0^T / T -> 0 "
                      "(rho positive and bounded on a bounded orbit)")

    warnings: list[str] = []
    if measure.density is None:
        pass
    elif consistent is False:
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

    zeros = expected_zeros(system, p, np.vstack([start_state, end_state]), consistent)
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
        convergence=rows[:, :count].copy(), sum=total, sum_expected=sum_expected, sum_reason=sum_reason,
        divergence_average=float(divergence_average), measure_average=measure_average,
        measure_consistent=consistent, expected_zero=zeros, zero_count=zero_count, zero_indices=zero_indices,
        zero_observed=values[zero_indices], moved_last_20pct=moved[:count].copy(),
        symmetry_residual=(float(np.max(np.abs(values + values[::-1])))
                           if any(z.reason.startswith("reversibility") for z in zeros) else None),
        method=_method(system, tol, interval), interval=float(interval), transient=float(transient),
        t_final=float(t_final), tolerance=tol, steps=len(acc.times) - acc.first,
        integrator_steps=int(integrator_steps), wall_time_s=wall, warnings=tuple(warnings))
