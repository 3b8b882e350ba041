"""A generalized Chaplygin system of the user's own (eq. 2704-7, Theorem 1): the worked examples in Euler
angles against the vector kinds, the evidence in t and in tau, a system Theorem 1 gives no multiplier for,
and the refusals."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest
import sympy as sp
from pydantic import ValidationError

from nonholonomic import simulate
from nonholonomic.definition import InvariantMeasure
from nonholonomic.evidence.measure import pointwise_divergence_residual
from nonholonomic.hamiltonization.local_forms import (
    chaplygin_ball_generalized_chaplygin,
    euler_angles_and_rates,
    veselova_generalized_chaplygin,
)
from nonholonomic.systems import generalized_chaplygin as gc, get_system
from schemas.jobs import JobRequest
from workers.jobs import run_job

INERTIA = {"I1": 2.0, "I2": 3.0, "I3": 4.5}
GAMMA0 = np.array([0.48, 0.6, 0.64])


def euler_system(example: dict[str, str], parameters: tuple[str, ...]):
    return gc.define(gc.chaplygin_data(example["L"], ("theta", "phi"), ("thetadot", "phidot"),
                                       example["a1"], example["a2"], example["b"], None, parameters))


def gamma_of(q: np.ndarray) -> np.ndarray:
    """γ = (sinθ sinφ, sinθ cosφ, cosθ) (eq. 2904-1)."""
    th, ph = q[:, 0], q[:, 1]
    return np.stack([np.sin(th) * np.sin(ph), np.sin(th) * np.cos(ph), np.cos(th)], axis=1)


def test_veselova_in_euler_angles_rolls_as_the_vector_kind():
    omega0 = np.cross(GAMMA0, [0.3, -0.5, 0.2])  # (ω, γ) = 0
    vector = simulate(get_system("veselova", "zero"), {"inertia": list(INERTIA.values())},
                      {"omega": omega0, "gamma": GAMMA0}, 30.0, 61)
    th, ph, thd, phd, _, _ = euler_angles_and_rates(omega0[None, :], GAMMA0[None, :])
    system = euler_system(veselova_generalized_chaplygin(), ("I1", "I2", "I3"))
    euler = simulate(system, INERTIA, {"q": [th[0], ph[0]], "q_dot": [thd[0], phd[0]]}, 30.0, 61,
                     checks=["integrals", "measure", "bracket"])
    assert np.max(np.abs(gamma_of(euler.state("q")) - vector.state("gamma"))) < 1e-9
    # Theorem 2: N = (γ, I⁻¹γ)^(-1/2) up to a constant, so τ grows as ∫ N dt along the vector orbit too.
    g = vector.state("gamma")
    rho = 1 / np.sqrt(np.sum(g * g / np.array(list(INERTIA.values())), axis=1))
    N = euler.trajectory.tau[1:] - euler.trajectory.tau[:-1]
    ratio = (N / (0.5 * (rho[1:] + rho[:-1]) * np.diff(euler.trajectory.t)))
    assert np.ptp(ratio) < 0.05 * np.mean(ratio)  # trapezoid rule on a 0.5 s grid
    assert all(c.passed for c in euler.checks), [(c.name, c.method, c.passed) for c in euler.checks]
    assert {c.name for c in euler.checks} >= {"invariant_measure", "hamiltonian_flow", "jacobi_identity",
                                              "energy_equals_hamiltonian"}
    assert euler.integrals[0].max_rel_drift < 1e-12


def test_the_ball_in_euler_angles_rolls_as_the_vector_kind():
    D = 0.7
    ball = get_system("chaplygin_ball", "zero")
    omega0 = np.array([0.4, -0.3, 0.25])
    vector = simulate(ball, {"inertia": list(INERTIA.values()), "D": D}, {"omega": omega0, "gamma": GAMMA0},
                      30.0, 61)
    c = float(vector.state("M")[0] @ GAMMA0)  # the constant of areas (M, γ) (eq. 004)
    th, ph, thd, phd, _, _ = euler_angles_and_rates(omega0[None, :], GAMMA0[None, :])
    system = euler_system(chaplygin_ball_generalized_chaplygin(), ("D", "I1", "I2", "I3", "c"))
    # The measure's symbolic proof takes ~19 s alone (a large rational function of tan(q/2)): here it
    # is checked pointwise only; a job runs the proof to its end (within the work limits).
    euler = simulate(system, {**INERTIA, "D": D, "c": c}, {"q": [th[0], ph[0]], "q_dot": [thd[0], phd[0]]},
                     30.0, 61, checks=["integrals", "bracket"])
    assert abs(c) > 0.1  # a non-trivial gyroscopic term b = -D c sin(theta)/G
    assert np.max(np.abs(gamma_of(euler.state("q")) - vector.state("gamma"))) < 1e-9
    assert all(c.passed for c in euler.checks), [(c.name, c.method, c.passed) for c in euler.checks]
    states = euler.trajectory.states
    assert pointwise_divergence_residual(system, euler.parameters, states) < 1e-10  # rho(q) det G, N = rho_mu
    wrong = dataclasses.replace(system, measure=InvariantMeasure(sp.Integer(1), "1", "-"))
    assert pointwise_divergence_residual(wrong, euler.parameters, states) > 1e-3
    S_bar = euler.system.hamiltonian_form.bracket.matrix[2, 3]
    assert S_bar != 0  # the monopole's 2-form (eq. 007): the bracket is not canonical


def test_no_multiplier_integrates_in_t_and_says_why():
    # a1 = q1 breaks the integrability condition dA1/dq1 + dA2/dq2 = 0 for L = (q1dot^2 + q2dot^2)/2.
    data = gc.chaplygin_data("(x1dot**2 + x2dot**2)/2 - k*(x1**2 + x2**2)/2", ("x1", "x2"), ("x1dot", "x2dot"),
                             "x1", "0", "1", None, ("k",))
    system = gc.define(data)
    assert system.reduced_time is None and system.hamiltonian_form is None
    assert "integrability condition" in system.measure.formula
    result = simulate(system, {"k": 1.0}, {"q": [0.3, 0.1], "q_dot": [0.2, -0.4]}, 20.0, 41,
                      checks=["integrals", "measure", "bracket"])
    assert result.integrals[0].passed and result.integrals[0].max_rel_drift < 1e-12
    assert [c.passed for c in result.checks] == [None, None]
    assert result.trajectory.tau is None


def test_the_printed_errata_would_be_caught():
    # The same Veselova data with the printed S (ERRATA 2: a2 without the corrected phidot term) is a
    # different system: its trajectory leaves the vector kind's within t = 30.
    example = veselova_generalized_chaplygin()
    wrong = dict(example, a2="sin(theta)**3*cos(theta)*(I1*sin(phi)**2 + I2*cos(phi)**2)")
    system = euler_system(wrong, ("I1", "I2", "I3"))
    right = euler_system(example, ("I1", "I2", "I3"))
    state = {"q": [0.9, 0.7], "q_dot": [0.3, -0.5]}
    a = simulate(system, INERTIA, state, 30.0, 31, checks=["integrals"])
    b = simulate(right, INERTIA, state, 30.0, 31, checks=["integrals"])
    assert np.max(np.abs(a.state("q") - b.state("q"))) > 1e-2


def test_a_job_runs_the_example_and_bad_fields_are_named():
    result = run_job(copy.deepcopy(gc.EXAMPLE_JOB))
    assert result["tau_final"] > 0 and all(c["passed"] for c in result["checks"])
    assert result["system"]["kind"] == "generalized_chaplygin" and len(result["trajectory"]["q"][0]) == 2

    def problems(**changes) -> dict[str, str]:
        body = copy.deepcopy(gc.EXAMPLE_JOB)
        body["system"].update(changes)
        try:
            request = JobRequest.model_validate(body)
        except ValidationError as exc:  # the cheap checks, while the body is read
            return {str(e["loc"][-1]): e["msg"] for e in exc.errors()}
        return {p.field.split(".", 1)[1]: p.reason for p in request.problems()}  # sympy's, off the event loop

    assert "polynomial of degree <= 2" in problems(L="sin(thetadot)")["L"]
    assert "may not depend on the velocities" in problems(a1="thetadot")["a1"]
    assert "unknown name 'I4'" in problems(b="I4")["b"]
    assert "reserved" in problems(coordinates=["t", "phi"])["coordinates"]
    assert "used twice" in problems(velocities=["theta", "phidot"])["velocities"]
    assert "use ** for powers" in problems(potential="theta^2")["potential"]
    unused = problems(parameters={"I1": 1.0, "I2": 2.0, "I3": 3.5, "k": 1.0})
    assert "not used by any expression" in unused["parameters.k"]  # heyoka refused it when the job ran (issue 19)


@pytest.mark.parametrize("state", [{"q": [0.7, 0.4, 0.1], "q_dot": [0.3, -0.5]},
                                   {"q": [0.0, 0.4], "q_dot": [0.3, 0.1]}])
def test_a_bad_initial_state_is_named(state):
    body = copy.deepcopy(gc.EXAMPLE_JOB) | {"initial_state": state}
    found = JobRequest.model_validate(body).problems()
    assert [p.field for p in found] == ["initial_state.q"]
