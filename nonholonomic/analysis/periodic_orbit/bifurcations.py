"""Bifurcations along a branch of periodic orbits: test functions, their zeros located, and the switch onto
the period-2k branch at a period doubling.

Between two consecutive points a and b of a branch (:mod:`.branch`), a bifurcation is a sign change of its
**test function** (Kuznetsov, *Elements of Applied Bifurcation Theory*, §10.2; AUTO-07p's and MatCont's):

* ``fold``: t_λ, the λ-component of the branch's tangent (the branch turns back in λ; a section multiplier
  is +1 there);
* ``tangent``: P(+1) = Π(1 − μᵢ) over the section multipliers without a turn in λ (a multiplier through +1
  where the branch goes on: a pitchfork or transcritical branch point);
* ``period_doubling``: P(−1) = Π(−1 − μᵢ) (a multiplier through −1: a period-2k orbit is born or dies);
* ``resonance_1:3``, ``resonance_1:4``: an elliptic pair e^{±iθ} of a two-dimensional section map through
  θ = 2π/3 (trace −1), π/2 (trace 0), where an island chain of period 3 or 4 is born;
* ``neimark_sacker``: a complex pair through |μ| = 1 (det − 1 of a two-dimensional section map that does not
  preserve a measure); ``krein_collision``: two pairs on the unit circle collide and leave it (the count of
  multipliers on the circle changes, section maps of dimension 4 and more).

For a two-dimensional section map the test functions are computed from the trace and determinant of Φ(T)
(trace of the section map = tr Φ − the trivial count, det = det Φ), smooth in z where the individual
eigenvalues are not (at a double multiplier). Each zero is located by the Illinois variant of regula falsi
in the arclength s from a, every trial a corrected point, to |test| ≤ :data:`LOCATE_TOLERANCE` or a bracket
below :data:`LOCATE_BRACKET` of the step; the count of the Krein test by bisection.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nonholonomic.analysis.periodic_orbit.arclength import ArcClosing, Correction, correct, tangent

#: A located zero: |test function| below this ...
LOCATE_TOLERANCE = 1e-9
#: ... or its bracket in arclength below this fraction of the step.
LOCATE_BRACKET = 1e-9
#: Corrected trial points one location may spend.
LOCATE_ITERATIONS = 24
#: |μ| within this of 1: on the unit circle (the Krein count).
ON_CIRCLE = 1e-7
#: The resonances flagged: q with θ = 2π/q.
RESONANCES = (3, 4)


@dataclass(frozen=True)
class Tests:
    """The test functions at one point (None: not defined there, e.g. a resonance of a hyperbolic orbit)."""

    fold: float
    plus_one: float
    minus_one: float
    resonance: dict[int, float | None]
    neimark_sacker: float | None
    on_circle: int


def section_trace_det(monodromy: np.ndarray, trivial_count: int) -> tuple[float, float]:
    """Trace and determinant of a two-dimensional section map from Φ(T): tr Φ − k and det Φ."""
    return float(np.trace(monodromy)) - trivial_count, float(np.linalg.det(monodromy))


def bifurcation_tests(t_lambda: float, monodromy: np.ndarray, trivial_count: int, section_mu: np.ndarray,
                      measure_preserving: bool) -> Tests:
    """The test functions of a point with tangent λ-component ``t_lambda`` and the section multipliers."""
    on_circle = int(np.sum((np.abs(np.abs(section_mu) - 1.0) <= ON_CIRCLE) & (np.abs(section_mu.imag) > 1e-12)))
    if len(section_mu) == 2:
        tr, det = section_trace_det(monodromy, trivial_count)
        plus, minus = 1.0 - tr + det, 1.0 + tr + det
        elliptic = tr * tr < 4.0 * det
        resonance: dict[int, float | None] = {
            q: (tr / 2.0 - float(np.cos(2 * np.pi / q)) if elliptic and measure_preserving else None)
            for q in RESONANCES}
        ns = det - 1.0 if elliptic and not measure_preserving else None
    else:
        plus, minus = float(np.prod(1.0 - section_mu).real), float(np.prod(-1.0 - section_mu).real)
        resonance, ns = {q: None for q in RESONANCES}, None
    return Tests(t_lambda, plus, minus, resonance, ns, on_circle)


@dataclass(frozen=True)
class Crossing:
    """A test function that changed sign between two points: its kind and how to evaluate it at a point."""

    kind: str
    value: Callable[[Tests], float]
    smooth: bool = True


def crossings(a: Tests, b: Tests) -> list[Crossing]:
    """The bifurcations between consecutive points with tests ``a`` and ``b``."""
    found: list[Crossing] = []
    fold = a.fold * b.fold < 0
    if fold:
        found.append(Crossing("fold", lambda t: t.fold))
    elif a.plus_one * b.plus_one < 0:
        found.append(Crossing("tangent", lambda t: t.plus_one))
    if a.minus_one * b.minus_one < 0:
        found.append(Crossing("period_doubling", lambda t: t.minus_one))
    for q in RESONANCES:
        ra, rb = a.resonance[q], b.resonance[q]
        if ra is not None and rb is not None and ra * rb < 0:
            found.append(Crossing(f"resonance_1:{q}", _resonance(q)))
    if a.neimark_sacker is not None and b.neimark_sacker is not None and a.neimark_sacker * b.neimark_sacker < 0:
        found.append(Crossing("neimark_sacker", lambda t: t.neimark_sacker if t.neimark_sacker is not None
                              else float("nan")))
    elif a.on_circle != b.on_circle and not found:
        count = a.on_circle
        found.append(Crossing("krein_collision", lambda t: -1.0 if t.on_circle == count else 1.0, smooth=False))
    return found


def _resonance(q: int) -> Callable[[Tests], float]:
    def value(t: Tests) -> float:
        r = t.resonance[q]
        return float("nan") if r is None else r
    return value


@dataclass(frozen=True)
class Located:
    """A zero of a test function: the corrected point, its test value, the bracket in arclength and the
    trials spent (``located`` False: the budget ran out or a trial did not converge; the best point)."""

    correction: Correction
    tangent: np.ndarray
    tests: Tests
    test_value: float
    arclength: float
    bracket: float
    trials: int
    located: bool


def locate(closing: ArcClosing, z_a: np.ndarray, t_a: np.ndarray, step: float, crossing: Crossing,
           evaluate_tests: Callable[[Correction, np.ndarray], Tests], at_b: Correction, tests_b: Tests,
           t_b: np.ndarray, tests_a: Tests) -> Located:
    """The zero of ``crossing``'s test function between a (arclength 0) and b (``step``), along a's
    pseudo-arclength hyperplanes."""
    lo, hi = 0.0, step
    f_lo, f_hi = crossing.value(tests_a), crossing.value(tests_b)
    best = Located(at_b, t_b, tests_b, f_hi, step, step, 0, False)
    side = 0
    for trial in range(1, LOCATE_ITERATIONS + 1):
        if crossing.smooth and np.isfinite(f_lo) and np.isfinite(f_hi) and f_hi != f_lo:
            s = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
            if not lo < s < hi:
                s = 0.5 * (lo + hi)
        else:
            s = 0.5 * (lo + hi)
        pred = z_a + s * t_a
        corr = correct(closing, pred, t_a, float(t_a @ pred))
        if not corr.converged:
            return Located(best.correction, best.tangent, best.tests, best.test_value, best.arclength, hi - lo,
                           trial, False)
        t_s, _ = tangent(corr.J, t_a)
        tests = evaluate_tests(corr, t_s)
        f = crossing.value(tests)
        best = Located(corr, t_s, tests, f, s, hi - lo, trial, False)
        if (crossing.smooth and abs(f) <= LOCATE_TOLERANCE) or hi - lo <= LOCATE_BRACKET * step:
            return Located(corr, t_s, tests, f, s, hi - lo, trial, True)
        if f * f_lo > 0:
            lo, f_lo = s, f
            if side == -1:
                f_hi *= 0.5  # Illinois: the end that stays is halved
            side = -1
        else:
            hi, f_hi = s, f
            if side == 1:
                f_lo *= 0.5
            side = 1
    return Located(best.correction, best.tangent, best.tests, best.test_value, best.arclength, hi - lo,
                   LOCATE_ITERATIONS, hi - lo <= 1e-6 * step)


def doubled_tangent(J2: np.ndarray, old: np.ndarray) -> tuple[np.ndarray, float]:
    """The period-2k branch's tangent at a period doubling: the kernel of the doubled closing equations' J_λ is
    two-dimensional there (the old branch, traversed twice, and the new one); the new tangent is the kernel
    vector orthogonal to ``old`` (the old tangent with dT doubled). Also the ratio σ₋₂/σ₀ (small: the kernel is
    two-dimensional, as it must be)."""
    _, sv, vt = np.linalg.svd(J2)
    kernel = vt[-2:]
    u = old / np.linalg.norm(old)
    c = kernel @ u
    new = kernel.T @ np.array([-c[1], c[0]])
    new -= (new @ u) * u
    return new / np.linalg.norm(new), float(sv[-2] / sv[0])
