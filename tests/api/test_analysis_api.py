"""A single job's analysis blocks through the API: the Poincaré section and the Lyapunov spectrum,
and every 422 they can give."""

from __future__ import annotations

import numpy as np
import pytest

from tests.api.conftest import BALL, job
from tests.support import poll_job

LINEAR = {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}


def test_job_with_section_and_spectrum(client):
    body = job(system=LINEAR, t_final=300.0, poincare={"surface": "gamma3", "direction": "increasing",
                                                        "coordinates": ["gamma1", "M3"]},
               lyapunov={"interval": 0.5})
    r = client.post("/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"])
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    section = result["poincare"]
    assert section["count"] == len(section["t"]) == len(section["tau"]) == len(section["coordinates"]) > 10
    assert section["coordinate_names"] == ["gamma1", "M3"]
    assert np.allclose(np.array(section["coordinates"])[:, 0], np.array(section["points"]["gamma"])[:, 0], atol=0)
    assert section["surface_residual_max"] <= 1e-13
    assert max(section["integral_drift_max"].values()) <= 1e-12
    assert np.all(np.diff(section["t"]) > 0) and np.all(np.diff(section["tau"]) > 0)
    spectrum = result["lyapunov"]
    exponents = np.array(spectrum["exponents"])
    assert exponents.shape == (6,) and np.all(np.diff(exponents) <= 0)
    # invariant measure (eq. 2604-3): the spectrum sums to the time average of div f, which is ~0
    assert abs(spectrum["sum"]) < 1e-3 and spectrum["sum_expected"] == 0.0
    # time direction, energy, |gamma|^2 and c: four exponents vanish
    assert spectrum["zero_count"] == 4
    assert np.sort(np.abs(exponents))[3] < 0.02


def test_max_points_stops_early_with_a_warning(client):
    body = job(t_final=1000.0, poincare={"surface": "gamma3", "max_points": 5})
    view = poll_job(client, client.post("/v1/jobs", json=body).headers["location"])
    section = view["result"]["poincare"]
    assert section["count"] == 5 and section["stopped_early"]
    assert any("max_points" in w for w in section["warnings"])


@pytest.mark.parametrize("block, field, words", [
    ({"poincare": {"surface": "gamma3 + x1"}}, "poincare.surface", ["x1", "position 9"]),
    ({"poincare": {"surface": "2*pi"}}, "poincare.surface", ["state"]),
    ({"poincare": {"surface": "gamma3", "coordinates": ["gamma1", "q"]}}, "poincare.coordinates[1]", ["q"]),
    ({"poincare": {"surface": "gamma3", "max_points": 10**9}}, "poincare.max_points", ["maximum"]),
    ({"poincare": {"surface": "gamma3", "direction": "sideways"}}, "poincare.direction", []),
    ({"poincare": {"surface": "__import__('os')"}}, "poincare.surface", []),
    ({"lyapunov": {"count": 9}}, "lyapunov.count", ["6"]),
    ({"lyapunov": {"interval": 50.0}}, "lyapunov.interval", []),
    ({"lyapunov": {"transient": 30.0}}, "lyapunov.transient", []),
    ({"lyapunov": {}, "integrator": {"engine": "scipy"}}, "integrator.engine", ["heyoka"]),
])
def test_bad_analysis_blocks_are_422_naming_the_field(client, block, field, words):
    r = client.post("/v1/jobs", json=job(**block))
    assert r.status_code == 422, r.text
    errors = r.json()["errors"]
    hit = [e for e in errors if e["field"] == field]
    assert hit, errors
    for word in words:
        assert word in hit[0]["reason"], hit[0]
