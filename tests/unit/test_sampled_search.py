"""Structure of a system too large for the exact elimination (issue 33, item 4): Chaplygin's sphere written as a
Lagrangian in (x, y) and z-x-z Euler angles. Its measure and its three integrals linear in the velocities, found by
the sampled ansatz, against what is known independently: the classical density sin²θ √(1 − D(γ, J⁻¹γ)) (J = I + D,
D = mR²; Chaplygin 1903, in these coordinates), Liouville's theorem on DOP853 orbits, and the angular momentum about
the contact point computed from the Euler angles by hand (conserved in space for the balanced sphere)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from nonholonomic.lagrangian.parse import parse_system
from nonholonomic.systems.lagrangian import define
from tests.lagrangian_examples import CHAPLYGIN_SPHERE
from tests.unit.test_measure_from_multiplier import _liouville_ratio

P = CHAPLYGIN_SPHERE["parameters"]
J = np.array([P["I1"], P["I2"], P["I3"]]) + P["m"] * P["R"] ** 2


@pytest.fixture(scope="module")
def sphere():
    data = parse_system(CHAPLYGIN_SPHERE)
    return data, define(data)


def _symbols(data):
    return {str(s): s for s in (*data.q, *data.v, *data.parameters)}


def _gamma(theta, psi):
    return np.array([np.sin(theta) * np.sin(psi), np.sin(theta) * np.cos(psi), np.cos(theta)])


def test_the_sphere_s_measure_is_chaplygin_s_density(sphere):
    data, system = sphere
    measure = system.structure["measure"]
    assert measure["verdict"] == "found" and "randomized identity test" in measure["reason"]
    assert measure["independent_velocities"] == ["phi_dot", "theta_dot", "psi_dot"]
    symbols = _symbols(data)
    density = sp.sympify(measure["density"], locals=symbols).xreplace(dict(zip(data.parameters, data.values)))
    rng = np.random.default_rng(5)
    ratios = []
    for theta, psi in rng.uniform(0.2, 2.9, (12, 2)):
        g = _gamma(theta, psi)
        classical = math.sin(theta) ** 2 * math.sqrt(1 - P["m"] * P["R"] ** 2 * float(g @ (g / J)))
        ratios.append(float(density.xreplace({symbols["theta"]: theta, symbols["psi"]: psi})) / classical)
    assert np.ptp(ratios) <= 1e-12 * abs(ratios[0])
    start = {"x": 0.0, "y": 0.0, "phi": 0.1, "theta": 1.0, "psi": 0.3, "phi_dot": 0.4, "theta_dot": -0.3,
             "psi_dot": 0.8}
    ratio, wrong = _liouville_ratio(CHAPLYGIN_SPHERE, [density, density * sp.cos(symbols["psi"]) ** 2],
                                    ["phi_dot", "theta_dot", "psi_dot"], start, 1.0)
    assert ratio == pytest.approx(1.0, abs=1e-7) and abs(wrong - 1.0) > 1e-3


def _momentum_in_space(phi, theta, psi, phi_dot, theta_dot, psi_dot):
    """K = I ω + mR² (ω − γ (γ, ω)) in the body, turned into space: R = Rz(φ) Rx(θ) Rz(ψ)."""
    omega = np.array([phi_dot * np.sin(theta) * np.sin(psi) + theta_dot * np.cos(psi),
                      phi_dot * np.sin(theta) * np.cos(psi) - theta_dot * np.sin(psi),
                      phi_dot * np.cos(theta) + psi_dot])
    g = _gamma(theta, psi)
    inertia = np.array([P["I1"], P["I2"], P["I3"]])
    body = inertia * omega + P["m"] * P["R"] ** 2 * (omega - g * (g @ omega))

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    rx = np.array([[1, 0, 0], [0, np.cos(theta), -np.sin(theta)], [0, np.sin(theta), np.cos(theta)]])
    return rz(phi) @ rx @ rz(psi) @ body


def test_the_sphere_s_linear_integrals_span_the_angular_momentum_about_the_contact_point(sphere):
    data, system = sphere
    found = system.structure["integrals"]["found"]
    assert [i["name"] for i in found] == ["energy", "F1", "F2", "F3"]
    assert all(i["proof"].startswith("proven by a randomized identity test") for i in found[1:])
    symbols = _symbols(data)
    exprs = [sp.sympify(i["expression"], locals=symbols) for i in found[1:]]
    fns = [sp.lambdify([symbols[n] for n in ("phi", "theta", "psi", "phi_dot", "theta_dot", "psi_dot")], e)
           for e in exprs]
    rng = np.random.default_rng(7)
    rows_F, rows_K = [], []
    for state in rng.uniform(-1.0, 1.0, (20, 6)) + np.array([0, 1.5, 0, 0, 0, 0]):
        rows_F.append([f(*state) for f in fns])
        rows_K.append(_momentum_in_space(*state))
    F, K = np.array(rows_F), np.array(rows_K)
    # F = K C for a constant 3 x 3 matrix C of rank 3: the found integrals are the momentum's components, combined
    C, residual, rank, _ = np.linalg.lstsq(K, F, rcond=None)
    assert rank == 3 and np.linalg.matrix_rank(C) == 3
    assert np.max(np.abs(K @ C - F)) <= 1e-12 * np.max(np.abs(F))


def test_a_sphere_job_checks_its_measure_and_integrals_along_the_orbit(sphere):
    from nonholonomic.simulation import simulate

    data, system = sphere
    phi, theta, psi, phi_dot, theta_dot, psi_dot, R = 0.1, 1.0, 0.3, 0.4, -0.3, 0.8, P["R"]
    x_dot = R * (theta_dot * math.sin(phi) - psi_dot * math.cos(phi) * math.sin(theta))
    y_dot = -R * (theta_dot * math.cos(phi) + psi_dot * math.sin(phi) * math.sin(theta))
    result = simulate(system, dict(zip(map(str, data.parameters), data.values)),
                      {"q": [0.0, 0.0, phi, theta, psi], "q_dot": [x_dot, y_dot, phi_dot, theta_dot, psi_dot]},
                      20.0, 201)
    drifts = {i.name: i.max_rel_drift for i in result.integrals}
    assert set(drifts) >= {"energy", "F1", "F2", "F3"} and max(drifts.values()) < 1e-12
    checks = {c.method: c for c in result.checks if c.name == "invariant_measure"}
    assert checks["randomized identity test"].passed is True
    assert checks["pointwise"].passed is True and checks["pointwise"].residual < 1e-12
