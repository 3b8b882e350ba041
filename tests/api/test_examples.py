"""Every kind's catalog example is a valid request that runs and passes all its checks."""

from __future__ import annotations

import pytest

from nonholonomic.systems import SYSTEMS
from tests.support import poll_job


@pytest.mark.parametrize("kind", sorted(SYSTEMS))
def test_catalog_example_runs_and_every_check_passes(client, kind):
    entry = client.get(f"/v1/systems/{kind}").json()
    example = entry["example"]
    assert example is not None and example["system"]["kind"] == kind
    r = client.post("/v1/jobs", json={**example, "samples": 11})
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=120)
    assert view["status"] == "succeeded", view["error"]
    result = view["result"]
    assert result["integrals"] and all(i["passed"] for i in result["integrals"]), result["integrals"]
    assert result["checks"] and all(c["passed"] is not False for c in result["checks"]), result["checks"]
    assert any(c["method"] == "pointwise" and c["passed"] for c in result["checks"])
    names = {i["name"] for i in entry["integrals"]
             if example["system"]["potential"]["kind"] in i["claimed_for_potentials"]}
    assert {i["name"] for i in result["integrals"]} == names
