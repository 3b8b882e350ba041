"""Lyapunov spectra (:mod:`nonholonomic.analysis.lyapunov`): the QR method on heyoka's variational
equations against known spectra, and the structure that constrains them (the sum against the
invariant measure, eq. 2604-3 / 2804-3; the zeros from the time direction and the integrals)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from nonholonomic import get_system
from nonholonomic.analysis.lyapunov import Spectrum, largest_batch, reversing_involution, spectrum
from nonholonomic.definition import InvariantMeasure, MechanicalSystem, StateConstraint, StateVector
from nonholonomic.numerics.integration import IntegrationCancelled, IntegrationError
from nonholonomic.numerics.kernels import parameter_vector

x1, x2, x3 = sp.symbols("x1 x2 x3", real=True)
X = StateVector("x", (x1, x2, x3), "state", "1")
UNIT_DENSITY = InvariantMeasure(sp.Integer(1), "rho = 1 (claimed, test-only)", "test")


def toy_system(kind: str, rhs: tuple[sp.Expr, ...], constraints: tuple[StateConstraint, ...] = ()) -> MechanicalSystem:
    """A test-only system in R³ without parameters or integrals, claiming the density 1."""
    return MechanicalSystem(kind=kind, potential="none", title=kind, equation="test", parameters=(), state=(X,),
                            rhs=rhs, integrals=(), measure=UNIT_DENSITY, reduced_time=None, potential_formula="",
                            constraints=constraints)


SIGMA, RHO, BETA = 10, 28, sp.Rational(8, 3)
LORENZ = toy_system("lorenz", (SIGMA * (x2 - x1), x1 * (RHO - x3) - x2, x1 * x2 - BETA * x3))
#: Reference spectrum of the Lorenz attractor (σ = 10, ρ = 28, β = 8/3); λ3 = −(σ + 1 + β) − λ1.
LORENZ_SPECTRUM = (0.9056, 0.0, -14.5723)
#: Rotation about e3 plus a radial term: the sphere |x| = 1 is invariant (a manifold), not conserved.
ROTOR = toy_system("rotor", (-x2 + (x1**2 + x2**2 + x3**2 - 1) * x1, x1 + (x1**2 + x2**2 + x3**2 - 1) * x2,
                            (x1**2 + x2**2 + x3**2 - 1) * x3),
                  (StateConstraint("x", sp.sqrt(x1**2 + x2**2 + x3**2), 1.0, "|x| = 1", "test"),))
#: dx1/dt = x1²: blows up at t = 1/x1(0) for x1(0) > 0, decays for x1(0) < 0.
BLOWUP = toy_system("blowup", (x1**2, -x2, x1 * x3 / 10))

BALL = {"inertia": [2.0, 3.0, 4.5], "D": 0.7}
BALL_STATE = np.array([0.5, -0.2, 0.1, 0.0, 0.6, 0.8])
B = np.diag([1.0, 2.0, 3.0])


def ball(potential: str) -> tuple[MechanicalSystem, np.ndarray]:
    system = get_system("chaplygin_ball", potential)
    extra = {"a": [0.3, -0.2, 0.5]} if potential == "linear" else {}
    return system, parameter_vector(system, {**BALL, **extra})


def quadric_linear() -> tuple[MechanicalSystem, np.ndarray, np.ndarray]:
    system = get_system("ball_on_quadric", "linear")
    p = parameter_vector(system, {"D0": 0.036, "m": 1.0, "R": 0.3, "B": B, "a": [0.1, -0.2, 0.3]})
    x = np.array([0.5, 0.6, 0.7])
    x /= np.sqrt(x @ np.linalg.solve(B, x))
    return system, p, np.concatenate([x, [1.2, -0.8, 2.0]])


def growth_power(s: Spectrum, t_from: float) -> float:
    """Slope of λ1(t)·t = ln|v1(t)| against ln t over t ≥ t_from: |v1| ~ t^slope."""
    keep = s.convergence_t >= t_from
    t = s.convergence_t[keep]
    return float(np.polyfit(np.log(t), s.convergence[keep, 0] * t, 1)[0])


def test_lorenz_spectrum_and_a_contradicted_measure() -> None:
    s = spectrum(LORENZ, np.empty(0), np.array([1.0, 1.0, 20.0]), 5010.0, transient=10.0, interval=0.5)
    assert np.allclose(s.exponents, LORENZ_SPECTRUM, atol=1e-2), s.exponents
    # div f = −(σ + 1 + β) everywhere: the sum and the quadrature equal it, whatever the claim says.
    assert s.divergence_average == pytest.approx(-(SIGMA + 1 + 8 / 3), abs=1e-10)
    assert s.sum == pytest.approx(-(SIGMA + 1 + 8 / 3), abs=1e-6)
    # The claimed density 1 predicts −[ln ρ]/T = 0: the routine reports the contradiction.
    assert s.sum_expected == 0.0 and s.measure_average == 0.0 and s.measure_consistent is False
    assert any("contradicts the claimed invariant measure" in w for w in s.warnings)
    # One zero (the time direction; no integrals, no reversing involution).
    assert s.zero_count == 1 and [z.reason for z in s.expected_zero] == ["time direction"]
    assert abs(s.zero_observed[0]) < 1e-2 and s.zero_indices.tolist() == [1]
    assert reversing_involution(LORENZ, np.empty(0), np.array([[1.0, 1.0, 20.0]])) is None
    assert s.convergence.shape == (len(s.convergence_t), 3) and len(s.convergence_t) <= 1001
    assert s.convergence_t[-1] == 5010.0 and s.steps == 10000
    assert np.all(s.moved_last_20pct < 1e-2)


def test_integrable_ball_exponents_fall_like_ln_t_over_t() -> None:
    system, p = ball("zero")
    s = spectrum(system, p, BALL_STATE, 10_000.0)
    # time + H + (γ, γ) + c + F = 5 zeros, and the measure's zero sum forces the sixth.
    assert s.zero_count == 6 and s.measure_consistent is True
    counted = [z.reason for z in s.expected_zero if z.counted]
    assert counted == ["time direction", "first integral energy (eq. 2604-2)", "first integral geometric (eq. 2604-2)",
                       "first integral area (eq. 2604-2)", "first integral F (eq. 2604-4)",
                       "invariant measure (eq. 2604-3)"]
    assert np.all(np.abs(s.exponents) < 2e-3)
    # Tangent vectors grow linearly on the tori: λ1(t) t = ln|v1(t)| ≈ ln t + c.
    assert 0.8 < growth_power(s, 300.0) < 1.2
    t, lam = s.convergence_t, s.convergence[:, 0]
    late = t >= 1000.0
    slope = np.polyfit(np.log(t[late]), np.log(lam[late]), 1)[0]
    assert -1.2 < slope < -0.7  # −1 + 1/ln t: 1/t up to the logarithm
    assert s.sum == pytest.approx(s.measure_average, abs=1e-12)


def test_chaotic_ball_pairs_and_four_zeros() -> None:
    system, p = ball("linear")
    s = spectrum(system, p, BALL_STATE, 2000.0)
    assert s.exponents[0] > 0.03
    assert growth_power(s, 300.0) > 20  # linear growth of ln|v1|, not logarithmic
    # time + H + (γ, γ) + c: 4 zeros; |γ| = 1 is the same as (γ, γ); the sum 0 leaves ±λ.
    assert s.zero_count == 4 and s.zero_indices.tolist() == [1, 2, 3, 4]
    constraint = next(z for z in s.expected_zero if z.reason.startswith("constraint"))
    assert not constraint.counted and "dependent" in constraint.note
    assert np.all(np.abs(s.zero_observed) < 0.1 * s.exponents[0])
    assert s.exponents[5] == pytest.approx(-s.exponents[0], abs=0.1 * s.exponents[0])
    assert s.symmetry_residual is not None and s.symmetry_residual < 0.01
    assert abs(s.sum) < 1e-4 and s.sum == pytest.approx(s.measure_average, abs=1e-10)
    assert s.sum == pytest.approx(s.divergence_average, abs=1e-10)
    assert s.measure_consistent is True and not any("measure" in w for w in s.warnings)


def test_ball_on_quadric_in_a_linear_field_is_chaotic() -> None:
    # The finite-time estimate depends on the rounding of the compiled code (AVX2 or AVX-512 machines
    # follow the chaotic orbit differently after a few Lyapunov times): measured 0.066 on one machine
    # at T = 2000, and 0.036 (T = 2000), 0.039 (4000), 0.054 (8000) on another; positive throughout.
    system, p, y0 = quadric_linear()
    s = spectrum(system, p, y0, 4000.0)
    lam = s.exponents[0]
    assert lam > 0.03 and s.moved_last_20pct[0] < 0.2 * lam
    late = s.convergence_t >= 0.8 * 4000.0
    assert np.all(s.convergence[late, 0] > 0.03)
    assert growth_power(s, 300.0) > 20
    # time + Φ + H: 3 zeros (the constraint Φ = 0 is the integral Φ); the measure |∇Φ| (2804-3) sums them to 0.
    assert s.zero_count == 3
    assert [z.reason for z in s.expected_zero if z.counted] == [
        "time direction", "first integral quadric (eq. 2804-2)", "first integral energy (eq. 2804-2)"]
    assert np.all(np.abs(s.zero_observed) < 0.1 * lam)
    assert abs(s.sum) < 1e-4 and s.sum == pytest.approx(s.measure_average, abs=1e-10)
    assert s.measure_consistent is True
    # Reversible (ω → −ω, t → −t): the whole spectrum is close to symmetric.
    assert any(z.reason.startswith("reversibility (omega -> -omega") for z in s.expected_zero)
    assert s.symmetry_residual is not None and s.symmetry_residual < 0.1 * lam


def test_invariant_manifold_is_not_a_zero() -> None:
    # On |x| = 1 the field rotates about e3; off it the radial term pushes away at rate 2.
    # (Short: round-off off the sphere grows like e^(2t) and must stay small.)
    s = spectrum(ROTOR, np.empty(0), np.array([0.6, 0.0, 0.8]), 14.0, transient=4.0)
    assert s.exponents == pytest.approx([2.0, 0.0, 0.0], abs=0.02)
    assert s.zero_count == 1
    constraint = s.expected_zero[1]
    assert not constraint.counted and "not conserved off its level set" in constraint.note
    assert s.divergence_average == pytest.approx(2.0, abs=1e-4)  # div f = 5|x|² − 3 = 2 on the sphere
    assert s.sum == pytest.approx(s.divergence_average, abs=1e-9)


def test_count_truncates_the_same_spectrum() -> None:
    system, p = ball("linear")
    full = spectrum(system, p, BALL_STATE, 200.0)
    two = spectrum(system, p, BALL_STATE, 200.0, count=2, interval=1.0)
    assert two.exponents.shape == (2,) and two.convergence.shape == (len(two.convergence_t), 2)
    assert two.moved_last_20pct.shape == (2,)
    assert np.array_equal(two.exponents, full.exponents[:2])
    assert np.array_equal(two.convergence, full.convergence[:, :2])
    assert np.array_equal(two.all_exponents, full.all_exponents) and two.sum == full.sum
    assert np.all(np.diff(full.exponents) <= 0)


def test_transient_is_left_out() -> None:
    system, p = ball("linear")
    s = spectrum(system, p, BALL_STATE, 120.0, count=1, transient=20.0, interval=0.5)
    assert s.steps == 200 and s.convergence_t[0] == 20.5 and s.convergence_t[-1] == 120.0
    assert s.transient == 20.0


def test_largest_batch_agrees_with_spectrum_and_is_reproducible() -> None:
    system, p = ball("linear")
    P = np.array([p + np.r_[np.zeros(4), 0.0, 0.0, -0.1 * k] for k in range(5)])
    Y = np.array([BALL_STATE + np.r_[0.05 * k, 0, 0, 0, 0, 0] for k in range(5)])
    batch = largest_batch(system, P, Y, 150.0, interval=0.5)
    again = largest_batch(system, P, Y, 150.0, interval=0.5)
    for i, member in enumerate(batch):
        assert isinstance(member, Spectrum)
        alone = spectrum(system, P[i], Y[i], 150.0, count=1, interval=0.5)
        assert member.exponents.shape == (1,)
        assert member.exponents[0] == pytest.approx(alone.exponents[0], abs=1e-10)
        assert np.max(np.abs(member.convergence - alone.convergence)) <= 1e-10
        other = again[i]
        assert isinstance(other, Spectrum)
        assert np.array_equal(member.all_exponents, other.all_exponents)
        assert np.array_equal(member.convergence, other.convergence)


def test_a_failing_member_fails_alone() -> None:
    Y = np.array([[-1.0, 1.0, 1.0], [0.5, 1.0, 1.0], [-0.5, 2.0, 1.0]])
    out = largest_batch(BLOWUP, np.empty((3, 0)), Y, 5.0)
    assert isinstance(out[1], IntegrationError)
    for i in (0, 2):
        member = out[i]
        assert isinstance(member, Spectrum)
        assert member.exponents[0] == pytest.approx(spectrum(BLOWUP, np.empty(0), Y[i], 5.0, count=1).exponents[0],
                                                    abs=1e-12)
    with pytest.raises(IntegrationError):
        spectrum(BLOWUP, np.empty(0), Y[1], 5.0)


def test_progress_and_cancel() -> None:
    seen: list[float] = []
    spectrum(LORENZ, np.empty(0), np.array([1.0, 1.0, 20.0]), 10.0, progress=lambda f: seen.append(f) or True)
    assert len(seen) == 10 and seen[-1] == 1.0 and np.all(np.diff(seen) > 0)
    with pytest.raises(IntegrationCancelled):
        spectrum(LORENZ, np.empty(0), np.array([1.0, 1.0, 20.0]), 10.0, progress=lambda f: f < 0.5)


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"interval": 0.0}, "interval"), ({"interval": float("nan")}, "interval"), ({"transient": 10.0}, "transient"),
    ({"transient": -1.0}, "transient"), ({"count": 0}, "count"), ({"count": 4}, "count"),
    ({"count": 1.5}, "count"), ({"tolerance": 0.0}, "tolerance"), ({"t_final": -1.0}, "t_final"),
    ({"parameters": np.ones(2)}, "parameters"), ({"initial_state": np.ones(4)}, "initial_state"),
])
def test_validation_names_the_field(kwargs: dict, field: str) -> None:
    args = {"parameters": np.empty(0), "initial_state": np.array([1.0, 1.0, 20.0]), "t_final": 10.0, **kwargs}
    with pytest.raises(ValueError, match=field):
        spectrum(LORENZ, args.pop("parameters"), args.pop("initial_state"), args.pop("t_final"), **args)
