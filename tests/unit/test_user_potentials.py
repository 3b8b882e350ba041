"""Potentials written by the user (``{"kind": "expression", "U": ..., "parameters": {...}}``): parsed
without eval, compiled like the built-in ones, every claim still checked. A user's U equal to a
built-in one gives the same equations and the same trajectory; for every kind, the energy with the
user's U is conserved and the measure check passes; integrals that hold only for U = 0 are not
claimed; a U singular at the initial state is refused naming ``system.potential.U``."""

from __future__ import annotations

import copy

import numpy as np
import pydantic
import pytest
import sympy as sp

from nonholonomic.systems import SYSTEMS, get_system, user_potential
from schemas.jobs import JobRequest
from workers.jobs import run_job

#: A U of each kind's potential variables (smooth on the example's orbit) and its parameters.
USER_U = {
    "chaplygin_ball": ("q*gamma3**2 + r*gamma1*gamma2", {"q": 0.4, "r": -0.3}),
    "veselova": ("q*gamma3**2 + r*gamma1", {"q": 0.4, "r": -0.3}),
    "chaplygin_ball_veselova": ("q*gamma3**2 + r*gamma1*E2", {"q": 0.4, "r": -0.3}),
    "rubber_ball": ("q*gamma3**2 + r*gamma1", {"q": 0.4, "r": -0.3}),
    "ball_on_quadric": ("q*x3**2 + r*x1", {"q": 0.4, "r": -0.3}),
    "ball_on_surface": ("q*x3**2 + r*x1", {"q": 0.4, "r": -0.3}),
    "clebsch": ("q*s3**2 + r*s1*s2", {"q": 0.4, "r": -0.3}),
    "neumann": ("q*s1**3 + r*s2", {"q": 0.4, "r": -0.3}),
    "veselova_e3": ("q*Gamma3**2 + r*Gamma1", {"q": 0.4, "r": -0.3}),
}
#: Integrals that hold only without an added U, by kind.
ONLY_FOR_ZERO = {"chaplygin_ball": {"F"}, "clebsch": {"H_alpha", "H_beta"}, "veselova_e3": {"H_alpha", "H_beta"},
                 "neumann": {"uhlenbeck_1", "uhlenbeck_2", "uhlenbeck_3"}}


def _body(kind: str, potential: dict, t_final: float = 20.0) -> dict:
    body = copy.deepcopy(SYSTEMS[kind].EXAMPLE)
    body["system"]["potential"] = potential
    body.update(t_final=t_final, samples=21)
    return body


def test_every_kind_has_the_examples_u():
    assert set(USER_U) == set(SYSTEMS)


@pytest.mark.parametrize("kind", sorted(USER_U))
def test_a_users_potential_keeps_its_energy_and_measure(kind):
    text, parameters = USER_U[kind]
    body = _body(kind, {"kind": "expression", "U": text, "parameters": parameters})
    job = JobRequest.model_validate(body)
    assert job.problems() == []
    result = run_job(body)
    assert result["system"]["potential"] == "expression"
    assert result["system"]["potential_formula"].startswith(f"U = {text}")
    integrals = {i["name"]: i for i in result["integrals"]}
    assert integrals["energy"]["passed"] and integrals["energy"]["max_rel_drift"] <= 1e-11, integrals["energy"]
    assert all(i["passed"] for i in integrals.values()), integrals
    assert not ONLY_FOR_ZERO.get(kind, set()) & set(integrals)  # not claimed with a U
    assert all(c["passed"] for c in result["checks"]), result["checks"]
    zero = {i.name for i in get_system(kind, "zero").integrals}
    assert ONLY_FOR_ZERO.get(kind, set()) <= zero


def test_the_energy_depends_on_the_users_u():
    """The energy integral is H = T + U with the user's U: on the same state, two U give energies that
    differ by exactly U's difference (a potential silently dropped would fail this)."""
    text, parameters = USER_U["chaplygin_ball"]
    with_u = run_job(_body("chaplygin_ball", {"kind": "expression", "U": text, "parameters": parameters}, 1.0))
    without = run_job(_body("chaplygin_ball", {"kind": "zero"}, 1.0))
    g = SYSTEMS["chaplygin_ball"].EXAMPLE["initial_state"]["gamma"]
    u0 = parameters["q"] * g[2] ** 2 + parameters["r"] * g[0] * g[1]
    e = {r: {i["name"]: i["initial"] for i in res["integrals"]} for r, res in (("u", with_u), ("0", without))}
    assert e["u"]["energy"] - e["0"]["energy"] == pytest.approx(u0, abs=1e-15)


@pytest.mark.parametrize(("kind", "builtin", "text", "user_parameters", "tolerance"), [
    ("chaplygin_ball", {"kind": "linear", "a": [0.3, -0.2, 0.5]},
     "a1*gamma1 + a2*gamma2 + a3*gamma3", {"a1": 0.3, "a2": -0.2, "a3": 0.5}, 1e-13),
    # the inertia written as numbers: the same field, rounded in another order (so 1e-12 over t = 50)
    ("veselova", {"kind": "brun", "k": 0.7}, "kk/2*(I1*gamma1**2 + I2*gamma2**2 + I3*gamma3**2)", {"kk": 0.7}, 1e-12),
    ("ball_on_quadric", {"kind": "harmonic", "k": 0.9}, "q/2*(x1**2 + x2**2 + x3**2)", {"q": 0.9}, 1e-13),
])
def test_a_users_u_equal_to_a_builtin_gives_the_same_trajectory(kind, builtin, text, user_parameters, tolerance):
    if "I1" in text:  # Brun's field needs the inertia: the user writes its values
        inertia = SYSTEMS[kind].EXAMPLE["system"]["inertia"]
        text = text.replace("I1", repr(inertia[0])).replace("I2", repr(inertia[1])).replace("I3", repr(inertia[2]))
    reference = run_job(_body(kind, builtin, 50.0))
    mine = run_job(_body(kind, {"kind": "expression", "U": text, "parameters": user_parameters}, 50.0))
    for name, values in reference["final_state"].items():
        np.testing.assert_allclose(mine["final_state"][name], values, rtol=0, atol=tolerance)
    energy = {r: {i["name"]: i["initial"] for i in res["integrals"]}["energy"] for r, res in (("b", reference),
                                                                                                  ("u", mine))}
    assert energy["u"] == pytest.approx(energy["b"], rel=1e-14)


def test_the_same_u_is_the_same_system_and_symbols_equal_the_builtins():
    a = user_potential("chaplygin_ball", "a1*gamma1 + a2*gamma2 + a3*gamma3", ("a1", "a2", "a3"))
    assert user_potential("chaplygin_ball", "a1*gamma1 + a2*gamma2 + a3*gamma3", ("a1", "a2", "a3")) is a
    mine, builtin = get_system("chaplygin_ball", a), get_system("chaplygin_ball", "linear")
    assert get_system("chaplygin_ball", a) is mine
    assert all(sp.expand(x - y) == 0 for x, y in zip(mine.rhs, builtin.rhs))


@pytest.mark.parametrize(("potential", "field", "reason"), [
    ({"kind": "expression", "U": "q*gamma4", "parameters": {"q": 1.0}}, "U", "unknown name 'gamma4'"),
    ({"kind": "expression", "U": "q*M1", "parameters": {"q": 1.0}}, "U", "unknown name 'M1'"),
    ({"kind": "expression", "U": "__import__('os')", "parameters": {}}, "U", ""),
    ({"kind": "expression", "U": "q*gamma1", "parameters": {"gamma2": 1.0}}, "parameters", "already a name"),
    ({"kind": "expression", "U": "x" * 2001, "parameters": {}}, "U", "2000"),
])
def test_a_bad_users_u_is_refused_naming_the_field(potential, field, reason):
    with pytest.raises(pydantic.ValidationError) as caught:
        JobRequest.model_validate(_body("chaplygin_ball", potential))
    errors = [e for e in caught.value.errors() if e["loc"][-1] == field and "expression" in e["loc"]]
    assert errors and reason in errors[0]["msg"], caught.value.errors()


def test_a_parameter_named_as_the_systems_own_is_refused_off_the_event_loop():
    """The system's own names need its definition: checked with the expressions (issue 19), not while the
    body is read."""
    body = _body("chaplygin_ball", {"kind": "expression", "U": "q*gamma1", "parameters": {"D": 1.0, "q": 1.0}})
    problems = JobRequest.model_validate(body).problems()
    assert [p.field for p in problems] == ["system.potential.parameters"] and "already a name" in problems[0].reason


def test_a_u_singular_at_the_initial_state_is_refused():
    body = _body("chaplygin_ball", {"kind": "expression", "U": "q/gamma1", "parameters": {"q": 1.0}})
    assert body["initial_state"]["gamma"][0] == 0.0
    problems = JobRequest.model_validate(body).problems()
    assert [p.field for p in problems] == ["system.potential.U"] and "not finite" in problems[0].reason


# --- claims: a researcher's candidate integrals -------------------------------------------------------

def test_claims_are_checked_along_the_trajectory_and_symbolically():
    body = _body("chaplygin_ball", {"kind": "zero"}, 50.0)
    body["claims"] = [{"name": "area", "expression": "M1*gamma1 + M2*gamma2 + M3*gamma3"},
                      {"name": "F", "expression": "M1**2 + M2**2 + M3**2"},
                      {"name": "not one", "expression": "M1"}]
    claims = {c["name"]: c for c in run_job(body)["claims"]}
    for name in ("area", "F"):  # (M, gamma) and, for U = 0, F = (M, M) (eq. 2604-2, 2604-4)
        assert claims[name]["passed"] and claims[name]["max_rel_drift"] < 1e-13
        assert claims[name]["symbolic"]["identically_conserved"] is True
    assert not claims["not one"]["passed"] and claims["not one"]["max_rel_drift"] > 1e-3
    assert claims["not one"]["symbolic"]["identically_conserved"] is False


def test_a_claim_that_holds_only_without_the_potential_fails_with_it():
    """F = (M, M) is an integral of the ball for U = 0 only: with a user's U the claim fails, both ways."""
    text, parameters = USER_U["chaplygin_ball"]
    body = _body("chaplygin_ball", {"kind": "expression", "U": text, "parameters": parameters}, 50.0)
    body["claims"] = [{"name": "F", "expression": "M1**2 + M2**2 + M3**2"},
                      {"name": "energy", "expression": "q*gamma3**2"}]  # U alone: not conserved
    claims = {c["name"]: c for c in run_job(body)["claims"]}
    assert not claims["F"]["passed"] and claims["F"]["symbolic"]["identically_conserved"] is False
    assert not claims["energy"]["passed"]


def test_a_bad_claim_is_a_problem_naming_its_field():
    body = _body("chaplygin_ball", {"kind": "zero"})
    body["claims"] = [{"name": "ok", "expression": "D*M1"}, {"name": "bad", "expression": "M1*omega1"}]
    problems = JobRequest.model_validate(body).problems()
    assert [p.field for p in problems] == ["claims[1].expression"] and "unknown name 'omega1'" in problems[0].reason
