"""τ = ∫ N dt where Theorem 1's N is not analytic or not positive on the orbit (issue 33, items 1 and 2): each
against a closed form, not the service's own path. The Chaplygin skate on an inclined plane (θ = θ₀ + ωt exactly,
N = √(1 − sin θ)·√(1 + sin θ) = |cos θ|: a kink at every zero); the Suslov problem with ω₁ = 0 (the body's ω is
constant, N = sin ψ sin θ = γ₁ oscillates about a mean and changes sign); a synthetic dense output for a
multiplier that stops being real."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy.optimize import brentq

from nonholonomic.evidence.time_change import domain_json, time_change_evidence
from nonholonomic.expressions.smoothness import analytic_and_positive, kink_arguments
from nonholonomic.lagrangian.parse import parse_system
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.reduced_time import DensityQuadrature
from nonholonomic.systems.lagrangian import define
from nonholonomic.systems.lagrangian_classics import _SUSLOV_L

SKATE = {"kind": "lagrangian", "coordinates": ["x", "y", "theta"],
         "L": "J*theta_dot**2/2 + g*m*s*x + m*(x_dot**2 + y_dot**2)/2",
         "constraints": ["-x_dot*sin(theta) + y_dot*cos(theta)"],
         "parameters": {"m": 1.5, "J": 0.2, "g": 9.81, "s": 0.3}}
SKATE_STATE = [0.2, 0.1, 0.4, 0.46053049700144255, 0.19470917115432526, 1.7]


@pytest.fixture(scope="module")
def skate():
    data = parse_system(SKATE)
    return define(data), np.array(data.values, dtype=float)


def _skate_tau(t: np.ndarray) -> np.ndarray:
    """∫₀ᵗ |cos(0.4 + 1.7 s)| ds in closed form: ∫|cos u| du = 2k + sin(u − kπ), k = ⌊(u + π/2)/π⌋."""
    def primitive(u):
        k = np.floor((u + np.pi / 2) / np.pi)
        return 2 * k + np.sin(u - k * np.pi)
    return (primitive(0.4 + 1.7 * t) - primitive(0.4)) / 1.7


def test_theorem_1_multipliers_that_may_vanish_are_not_regular():
    q, p, a = sp.symbols("theta psi a")
    assert not analytic_and_positive(sp.sqrt(1 - sp.sin(q)) * sp.sqrt(1 + sp.sin(q)))
    assert not analytic_and_positive(sp.sin(p) * sp.sin(q))
    assert not analytic_and_positive(sp.sqrt(1 + a**2 * sp.sin(q)))  # positive only for |a| < 1
    assert analytic_and_positive(sp.exp(sp.cos(q)) / sp.sqrt(1 + p**2))
    assert not analytic_and_positive(1 / sp.sqrt(2 + sp.sin(q)))  # not proven by sympy: by quadrature (exact too)
    assert kink_arguments(sp.sqrt(1 - sp.sin(q)) * sp.Abs(p)) == [1 - sp.sin(q), p]


@pytest.mark.parametrize("engine", ["heyoka", "scipy"])
def test_the_skate_s_tau_is_the_closed_form_across_every_zero_of_cos_theta(skate, engine):
    system, p = skate
    assert system.reduced_time is not None and system.reduced_time.regular is False
    tr = integrate(system, p, np.array(SKATE_STATE), 20.0, 201, engine=engine)
    # θ = 0.4 + 1.7 t exactly (J θ'' = 0); before: tau[-1] = 12.583977 (Taylor across the kinks)
    assert np.max(np.abs(tr.tau - _skate_tau(tr.t))) < 1e-12
    assert tr.tau[-1] == pytest.approx(12.6198312133193770051, abs=1e-12)  # mpmath.quad at 30 digits
    report = tr.reduced_time
    exact_zeros = (np.pi / 2 + np.pi * np.arange(11) - 0.4) / 1.7
    assert report.zero_count == 11 and report.sign_change_count == 0 and report.not_real_from is None
    assert np.max(np.abs(np.array(report.zeros) - exact_zeros)) < 1e-12
    residual, tolerance, passed = tr.reduced_time_check
    assert passed and residual < 1e-11 and report.unconverged == 0


def test_a_long_skate_orbit_finds_all_1082_zeros_and_keeps_tau_to_1e_11(skate):
    system, p = skate
    tr = integrate(system, p, np.array(SKATE_STATE), 2000.0, 2001)
    report = tr.reduced_time
    assert report.zero_count == int(np.sum((np.pi / 2 + np.pi * np.arange(2000) - 0.4) / 1.7 < 2000.0)) == 1082
    assert len(report.zeros) == 50  # listed; all counted
    assert np.max(np.abs(tr.tau - _skate_tau(tr.t))) < 1e-10  # θ ~ 3400: cos θ is known to ~1e-13 only
    assert tr.reduced_time_check[2] is True


def test_the_skate_s_result_says_where_the_hamiltonization_is_singular(skate):
    system, p = skate
    tr = integrate(system, p, np.array(SKATE_STATE), 5.0, 51)
    checks, warnings = time_change_evidence(system, tr)
    assert [c.name for c in checks] == ["reduced_time"] and checks[0].passed is True
    assert len(warnings) == 1 and "vanishes at t = 0.6887037216, 2.5366994, 4.384695079" in warnings[0]
    block = domain_json(tr.reduced_time)
    assert block["zero_count"] == 3 and block["nonzero_until"] == pytest.approx(0.6887037216440568, abs=1e-12)


def test_suslov_with_omega_1_zero_reports_every_sign_change_of_gamma_1():
    """ω₁ = 0 makes Euler's equations give ω̇ = 0: γ̇ = γ × ω rotates γ about ω, so N = γ₁ = a + b cos wt − c sin wt."""
    data = parse_system({"kind": "lagrangian", "coordinates": ["phi", "theta", "psi"], "L": _SUSLOV_L,
                         "constraints": ["phi_dot*sin(theta)*sin(psi) + theta_dot*cos(psi)"],
                         "parameters": {"I1": 1.0, "I2": 2.0, "I3": 3.0}})
    system = define(data)
    assert str(system.reduced_time.density) == "sin(psi)*sin(theta)"
    phi, theta, psi, phi_dot, psi_dot = 0.1, 1.0, 0.2, 0.3, 0.4
    theta_dot = -phi_dot * math.sin(theta) * math.sin(psi) / math.cos(psi)
    tr = integrate(system, np.array(data.values, dtype=float),
                   np.array([phi, theta, psi, phi_dot, theta_dot, psi_dot]), 30.0, 301)
    omega = np.array([phi_dot * math.sin(theta) * math.sin(psi) + theta_dot * math.cos(psi),
                      phi_dot * math.sin(theta) * math.cos(psi) - theta_dot * math.sin(psi),
                      phi_dot * math.cos(theta) + psi_dot])
    gamma0 = np.array([math.sin(theta) * math.sin(psi), math.sin(theta) * math.cos(psi), math.cos(theta)])
    w = float(np.linalg.norm(omega))
    k = omega / w
    along, side = k * (k @ gamma0), np.cross(k, gamma0)
    across = gamma0 - along

    def gamma_1(t):
        return along[0] + across[0] * np.cos(w * t) - side[0] * np.sin(w * t)

    tau = along[0] * tr.t + across[0] * np.sin(w * tr.t) / w + side[0] * (np.cos(w * tr.t) - 1) / w
    assert np.max(np.abs(tr.tau - tau)) < 1e-12
    fine = np.linspace(0, 30, 30001)
    values = gamma_1(fine)
    roots = [brentq(gamma_1, fine[i], fine[i + 1], xtol=1e-15) for i in np.flatnonzero(values[:-1] * values[1:] < 0)]
    report = tr.reduced_time
    assert report.sign_change_count == len(roots) == 6 and report.zero_count == 0
    assert np.max(np.abs(np.array(report.sign_changes) - roots)) < 1e-12
    assert tr.tau.min() < 0  # τ runs backwards where N < 0, and the result says so
    _, warnings = time_change_evidence(system, tr)
    assert any("changes sign at t = 4.58213590" in w and "tau runs backwards" in w for w in warnings)


def _line(t: np.ndarray) -> np.ndarray:
    """A dense output of x(t) = t."""
    return np.asarray(t, dtype=float)[:, None]


def test_a_multiplier_that_stops_being_real_ends_tau_there():
    quadrature = DensityQuadrature(lambda x: np.sqrt(1.0 - x[:, 0]),
                                   lambda x: np.stack([1.0 - x[:, 0], -np.ones(len(x))], axis=1))
    grid = np.linspace(0.0, 2.0, 21)
    with np.errstate(invalid="ignore"):
        tau = quadrature.add(_line, np.linspace(0.0, 2.0, 7), grid)
    exact = 2 / 3 * (1 - (1 - grid[grid <= 1]) ** 1.5)
    assert np.max(np.abs(tau[grid <= 1] - exact)) < 1e-12
    assert np.all(np.isnan(tau[grid > 1])) and quadrature.report.not_real_from == pytest.approx(1.0, abs=1e-14)


def test_kinks_inside_a_step_are_cut_and_an_absolute_value_integrates_exactly():
    """N = |sin 3t| + 0.5 (positive: no zero, only kinks) and N = |sin 3t| (a zero at each kink)."""
    for offset, zeros in ((0.5, 0), (0.0, 3)):
        quadrature = DensityQuadrature(lambda x, c=offset: np.abs(np.sin(3 * x[:, 0])) + c,
                                       lambda x: np.stack([np.sin(3 * x[:, 0]), 3 * np.cos(3 * x[:, 0])], axis=1))
        grid = np.array([0.0, 1.3, 3.5])
        tau = quadrature.add(_line, np.array([0.0, 3.5]), grid)
        exact = [0.0, (2 + (1 - math.cos(3 * 1.3 - math.pi))) / 3, (6 + (1 - math.cos(3 * 3.5 - 3 * math.pi))) / 3]
        assert np.max(np.abs(tau - np.array(exact) - offset * grid)) < 1e-13
        assert quadrature.report.zero_count == zeros
        assert quadrature.check_passed()


def test_the_skate_s_integrals_are_claimed_in_a_form_regular_where_cos_theta_vanishes(skate):
    """Issue 33, item 5: the searches found the energy as (... + 1500 x_dot²)/(2000 cos² θ), singular on the orbit;
    it is claimed as 3/4 (x_dot cos θ + y_dot sin θ)² + θ_dot²/10 − g s x m/2 ..., equal on the manifold, and every
    integral holds to 1e-12 across the 11 zeros of cos θ."""
    from nonholonomic.simulation import simulate

    system, p = skate
    found = {i["name"]: i for i in system.structure["integrals"]["found"]}
    for name in ("energy", "F1", "F2"):
        assert "cos(theta)**2)" in found[name]["expression_on_manifold"]  # the singular form, kept beside
        assert "/(" not in found[name]["expression"] and "/cos" not in found[name]["expression"]
    result = simulate(system, dict(zip(map(str, system.parameter_symbols), p)),
                      {"q": SKATE_STATE[:3], "q_dot": SKATE_STATE[3:]},
                      20.0, 201)
    drifts = {i.name: i.max_rel_drift for i in result.integrals}
    assert {"F1", "F2", "F3"} <= set(drifts) and max(drifts.values()) < 1e-12
    # on the manifold the two forms agree (an independent evaluation of each text)
    symbols = {str(s): s for s in system.state_symbols}
    rng = np.random.default_rng(2)
    for theta, speed, rate, x in rng.uniform(-1.4, 1.4, (5, 4)):
        at = {symbols["x"]: x, symbols["y"]: 0.3, symbols["theta"]: theta, symbols["theta_dot"]: rate,
              symbols["x_dot"]: speed * math.cos(theta), symbols["y_dot"]: speed * math.sin(theta)}
        for name in ("energy", "F1", "F2"):
            regular, singular = (float(sp.sympify(found[name][key], locals=symbols).xreplace(at))
                                 for key in ("expression", "expression_on_manifold"))
            assert regular == pytest.approx(singular, rel=1e-12, abs=1e-12)
