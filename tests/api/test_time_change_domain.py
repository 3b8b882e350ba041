"""Theorem 1's time change where N vanishes, through the API (issue 33, items 1 and 2): the Chaplygin skate on an
inclined plane, N = |cos θ| written as √(1 − sin θ)·√(1 + sin θ). τ against its closed form, the zeros in the
result (``time.tau_domain``, a warning), the ``reduced_time`` check and the job page."""

from __future__ import annotations

import numpy as np

from tests.support import poll_job
from tests.unit.test_reduced_time import SKATE, SKATE_STATE, _skate_tau


def test_the_skate_s_job_states_where_its_hamiltonization_is_singular(client):
    body = {"system": SKATE, "initial_state": {"q": SKATE_STATE[:3], "q_dot": SKATE_STATE[3:]},
            "t_final": 20.0, "samples": 201}
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=600)
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    t, tau = np.array(result["trajectory"]["t"]), np.array(result["trajectory"]["tau"])
    assert np.max(np.abs(tau - _skate_tau(t))) < 1e-12
    domain = result["time"]["tau_domain"]
    exact = (np.pi / 2 + np.pi * np.arange(11) - 0.4) / 1.7
    assert domain["zero_count"] == 11 and np.max(np.abs(np.array(domain["zeros"]) - exact)) < 1e-12
    assert domain["sign_change_count"] == 0 and domain["nonzero_until"] == domain["zeros"][0]
    # no contradictory pair: the measure's density in (q, q_dot) is written without its radicals (it is 1), so its
    # pointwise check holds at the zeros of cos(theta) too (it failed there at 5.8e-9 beside a symbolic proof)
    assert result["system"]["structure"]["measure"]["density_in_state"] == "1"
    assert all(c["passed"] is not False for c in result["checks"]), [c for c in result["checks"] if not c["passed"]]
    check = next(c for c in result["checks"] if c["name"] == "reduced_time")
    assert check["passed"] is True and check["residual"] < 1e-11
    assert any("vanishes at t = 0.6887037216" in w for w in result["warnings"])
    page = client.get(f"{r.headers['location']}/page").text
    assert 'id="tau-domain"' in page and "N vanishes 11 times, changes sign 0 times" in page
    assert "vanishes at t = 0.6887037216" in page
