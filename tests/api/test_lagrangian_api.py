"""A Lagrangian system of the user's own (kind ``lagrangian``) through the API: Chaplygin's sleigh and the
nonholonomic particle against independent integrations (the sleigh's reduced closed form; sympy.physics.mechanics'
LagrangesMethod), their integrals, the catalog entry, the measure verdict, the page, plots and exports, and the
422s naming the field."""

from __future__ import annotations

import copy
import io
import json

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from nonholonomic.systems.lagrangian import EXAMPLE_JOB as SLEIGH_JOB
from tests.support import poll_job

PARTICLE = {"kind": "lagrangian", "coordinates": ["x", "y", "z"],
            "L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - k*(x**2 + y**2)/2", "constraints": ["z_dot - y*x_dot"],
            "parameters": {"k": 1.0}}
PARTICLE_Q, PARTICLE_V = [0.3, -0.2, 0.1], [0.5, 0.4, -0.2 * 0.5]  # z_dot = y x_dot


def _run(client, body) -> tuple[str, dict]:
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=600.0)
    assert view["status"] == "succeeded", view["error"]
    return r.headers["location"], view["result"]


def _errors(client, body) -> dict[str, str]:
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json", r.text
    return {e["field"]: e["reason"] for e in r.json()["errors"]}


def test_the_sleigh_agrees_with_its_reduced_closed_form(client):
    """v' = a ω², ω' = −m a v ω/(J + m a²) (v = cos θ ẋ + sin θ ẏ, ω = θ̇), integrated by scipy DOP853 apart."""
    location, result = _run(client, SLEIGH_JOB)
    assert set(result["final_state"]) >= {"q", "q_dot"}
    (_, _, theta), (xd, yd, thetad) = result["final_state"]["q"], result["final_state"]["q_dot"]
    p = SLEIGH_JOB["system"]["parameters"]
    m, a, J = p["m"], p["a"], p["J"]
    q0, v0 = SLEIGH_JOB["initial_state"]["q"], SLEIGH_JOB["initial_state"]["q_dot"]
    start = [np.cos(q0[2]) * v0[0] + np.sin(q0[2]) * v0[1], v0[2]]
    reference = solve_ivp(lambda t, s: [a * s[1] ** 2, -m * a * s[0] * s[1] / (J + m * a * a)], (0.0, 20.0), start,
                          method="DOP853", rtol=1e-13, atol=1e-13)
    v, omega = reference.y[:, -1]
    assert abs(np.cos(theta) * xd + np.sin(theta) * yd - v) < 1e-9
    assert abs(thetad - omega) < 1e-9
    integrals = {i["name"]: i for i in result["integrals"]}
    assert set(integrals) == {"energy", "constraint 1"}
    assert integrals["constraint 1"]["max_abs_drift"] <= 1e-12 and abs(integrals["constraint 1"]["final"]) <= 1e-12
    assert integrals["energy"]["max_rel_drift"] <= 1e-12 and all(i["passed"] for i in integrals.values())
    (measure,) = [c for c in result["checks"] if c["name"] == "invariant_measure"]
    assert measure["passed"] is None and "verdict none" in measure["detail"] and "not closed" in measure["detail"]
    structure = result["system"]["structure"]["measure"]
    assert structure["verdict"] == "none" and structure["independent_velocities"] == ["x_dot", "theta_dot"]
    assert structure["dependent_velocities"] == {"y_dot": "x_dot*sin(theta)/cos(theta)"}

    page = client.get(f"{location}/page")
    assert page.status_code == 200 and "lagrangian" in page.text and "not checked" in page.text
    assert "<dt>q</dt><dd><code>x, y, theta</code></dd>" in page.text
    assert "<dt>constraint 1</dt><dd><code>-sin(theta)*x_dot + cos(theta)*y_dot = 0</code></dd>" in page.text
    for name in ("trajectory", "integrals"):
        plot = client.get(f"{location}/plots/{name}.png")
        assert plot.status_code == 200 and plot.headers["content-type"] == "image/png", plot.text
    for fmt, magic in (("csv", b"t ["), ("npz", b"PK"), ("netcdf", b"\x89HDF")):
        export = client.get(f"{location}/trajectory", params={"format": fmt})
        assert export.status_code == 200 and export.content.startswith(magic), (fmt, export.text[:300])
    # the exports name the components as the user did (issue 33, item 5), the numbers those of the JSON
    own = ["x", "y", "theta", "x_dot", "y_dot", "theta_dot"]
    assert result["system"]["components"] == {"q": own[:3], "q_dot": own[3:]}
    header = client.get(f"{location}/trajectory", params={"format": "csv"}).text.splitlines()[0]
    assert [c.split(" [")[0] for c in header.split(",")] == ["t", *own]
    with np.load(io.BytesIO(client.get(f"{location}/trajectory", params={"format": "npz"}).content)) as arrays:
        assert json.loads(str(arrays["components_json"])) == result["system"]["components"]
    import xarray as xr

    ds = xr.open_dataset(client.get(f"{location}/trajectory", params={"format": "netcdf"}).content,
                         engine="netcdf4").load()
    assert set(ds.data_vars) == set(own) and ds["theta_dot"].attrs["vector"] == "q_dot"
    assert np.array_equal(ds["theta"].values, np.asarray(result["trajectory"]["q"])[:, 2])


def _lagranges_method_reference(t_final: float) -> np.ndarray:
    """The particle's (q, q̇) at ``t_final`` from sympy.physics.mechanics' LagrangesMethod, integrated by scipy."""
    from sympy.physics.mechanics import LagrangesMethod, dynamicsymbols

    q = dynamicsymbols("x y z")
    qd = [sp.diff(qi, dynamicsymbols._t) for qi in q]
    L = (qd[0] ** 2 + qd[1] ** 2 + qd[2] ** 2) / 2 - (q[0] ** 2 + q[1] ** 2) / 2
    method = LagrangesMethod(L, q, nonhol_coneqs=[qd[2] - q[1] * qd[0]])
    method.form_lagranges_equations()
    state = [*q, *qd]
    plain = sp.symbols("s0:6")
    rhs = method.rhs().xreplace(dict(zip(reversed(state), reversed(plain))))  # derivatives before their functions
    field = sp.lambdify([plain], list(rhs[:6]), "numpy")
    solution = solve_ivp(lambda t, s: field(s), (0.0, t_final), [*PARTICLE_Q, *PARTICLE_V], method="DOP853",
                         rtol=1e-13, atol=1e-13)
    return solution.y[:, -1]


def test_the_nonholonomic_particle_agrees_with_lagranges_method(client):
    body = {"system": PARTICLE, "initial_state": {"q": PARTICLE_Q, "q_dot": PARTICLE_V}, "t_final": 20.0,
            "samples": 51}
    _, result = _run(client, body)
    final = np.array([*result["final_state"]["q"], *result["final_state"]["q_dot"]])
    assert np.max(np.abs(final - _lagranges_method_reference(20.0))) < 1e-9
    integrals = {i["name"]: i for i in result["integrals"]}
    assert integrals["energy"]["max_rel_drift"] <= 1e-12 and integrals["constraint 1"]["max_abs_drift"] <= 1e-12


def _particle(**system) -> dict:
    return {"system": {**PARTICLE, **system}, "initial_state": {"q": PARTICLE_Q, "q_dot": PARTICLE_V},
            "t_final": 1.0, "samples": 11}


@pytest.mark.parametrize(("system", "field", "words"), [
    ({"constraints": ["z_dot*x_dot - y*x_dot"]}, "system.constraints[0]", "linear and homogeneous"),
    ({"L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - c*x**2"}, "system.L", "unknown name 'c'"),
    ({"L": "(x_dot + y_dot)**2/2 + z_dot**2/2 - k*x**2"}, "system.L", "singular"),
    ({"L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - k*t*x**2"}, "system.L", "time t"),
    ({"parameters": {"k": 1.0, "unused": 2.0}}, "system.parameters.unused", "not used"),
])
def test_bad_systems_are_422s_naming_the_field(client, system, field, words):
    assert words in _errors(client, _particle(**system))[field]


def test_bad_initial_states_are_422s_naming_the_field(client):
    body = _particle()
    body["initial_state"]["q_dot"] = [0.5, 0.4, 0.3]  # z_dot - y x_dot = 0.4
    reason = _errors(client, body)["initial_state.q_dot"]
    assert "constraint 1" in reason and "value 0.4" in reason and "project_initial_state" in reason
    body["project_initial_state"] = True  # moved onto the constraint instead
    assert client.post("/v1/jobs", json=body).status_code == 202
    body = _particle()
    body["initial_state"]["q"] = [0.3, -0.2]
    assert "needs 3 components, got 2" in _errors(client, body)["initial_state.q"]
    body = _particle()
    body["initial_state"]["q_dot"] = [0.5, 0.4, -0.1, 0.0]
    assert "needs 3 components, got 4" in _errors(client, body)["initial_state.q_dot"]


def test_the_catalog_serves_the_lagrangian_entry(client):
    r = client.get("/v1/systems/lagrangian")
    assert r.status_code == 200, r.text
    entry = r.json()
    assert entry == client.get("/v1/systems").json()["lagrangian"]
    assert entry["kind"] == "lagrangian" and entry["state"] == ["q", "q_dot"] and entry["example"] == SLEIGH_JOB
    assert {"coordinates", "L", "constraints", "parameters"} <= set(entry["fields"])
    assert "found" in entry["measure"] and "undecided" in entry["measure"]
    body = copy.deepcopy(entry["example"])
    body.update(t_final=1.0, samples=11)
    assert client.post("/v1/jobs", json=body).status_code == 202


def test_a_derivation_sympy_fails_on_is_the_jobs_failure_not_a_refusal_nor_a_500(monkeypatch):
    """The request path only parses and outlines the system (no derivation: the same answer at any load);
    the derivation runs with the job, and sympy's failure there fails the job naming it."""
    from nonholonomic.lagrangian import DerivationError
    from nonholonomic.systems import lagrangian as lag
    from schemas.jobs import JobRequest
    from workers.jobs import run_job

    def fails(data):
        raise DerivationError("the equations of motion could not be derived: sympy said no")

    monkeypatch.setattr(lag, "derive", fails)
    body = _particle(parameters={"k": 1.0 + 2.0**-40})  # a system no earlier test defined (define is cached)
    assert JobRequest.model_validate(body).problems() == []
    with pytest.raises(DerivationError, match="sympy said no"):
        run_job(body)


def test_the_sleighs_spectrum_sums_to_its_phase_volume_contraction_and_expects_no_zero_sum(client):
    """No measure is claimed for the sleigh (it has none: the heading's motion is asymptotically stable),
    so the spectrum's sum is reported against nothing; it equals the time average of div f, which is
    negative: the flow contracts phase volume."""
    location, result = _run(client, {**SLEIGH_JOB, "t_final": 30.0, "lyapunov": {"interval": 1.0}})
    spectrum = result["lyapunov"]
    assert spectrum["sum_expected"] is None and spectrum["sum_reason"].startswith("no invariant measure is claimed")
    assert spectrum["sum"] < -0.1 and abs(spectrum["sum"] - spectrum["divergence_average"]) <= 1e-6
    assert not any("contradicts" in w or "not positive and finite" in w for w in spectrum["warnings"])
    page = client.get(f"{location}/page")
    assert page.status_code == 200 and "no measure claimed, no expected value" in page.text
    assert client.get(f"{location}/plots/lyapunov.svg").status_code == 200
