"""A sweep's orbit diagram (``GET /v1/ensembles/{id}/orbit-diagram``, the ``orbit_diagram`` plot): every member's
section points against the swept value, checked against the members' own sections."""

from __future__ import annotations

import csv
import io

from tests.api.conftest import BALL, STATE
from tests.api.test_ensembles_api import SAMPLED, _members
from tests.support import poll_job

#: The ball in a linear field, a3 swept; each member's crossings of gamma3 = 0 in (gamma1, M3).
SWEEP = {"system": {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}},
         "members": {"sweep": {"parameter": "potential.a[2]", "values": [0.4, 0.6, 0.8, 1.0],
                               "initial_state": dict(STATE)}},
         "t_final": 40.0, "samples": 3, "poincare": {"surface": "gamma3", "coordinates": ["gamma1", "M3"]},
         "chunk_size": 2}


def test_the_orbit_diagram_is_every_members_section_against_its_swept_value(client):
    r = client.post("/v1/ensembles", json=SWEEP)
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=120)
    assert view["status"] == "succeeded", view
    members = {m["index"]: m for m in _members(client, view["id"])}
    table = client.get(f"/v1/ensembles/{view['id']}/orbit-diagram")
    assert table.status_code == 200 and table.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(table.text)))
    assert list(rows[0]) == ["member", "potential.a[2] [kg m^2/s^2]", "crossing", "gamma1 [1]", "M3 [kg m^2/s]"]
    assert len(rows) == sum(m["poincare"]["count"] for m in members.values()) > 8
    for row in rows:
        member = members[int(row["member"])]
        assert float(row["potential.a[2] [kg m^2/s^2]"]) == SWEEP["members"]["sweep"]["values"][member["index"]]
        point = member["poincare"]["coordinates"][int(row["crossing"]) - 1]
        assert [float(row["gamma1 [1]"]), float(row["M3 [kg m^2/s]"])] == point  # exactly: repr floats
    as_json = client.get(f"/v1/ensembles/{view['id']}/orbit-diagram", params={"format": "json"}).json()
    assert as_json["parameter"] == "potential.a[2]" and len(as_json["value"]) == len(rows)
    image = client.get(f"/v1/ensembles/{view['id']}/plots/orbit_diagram.png")
    assert image.status_code == 200 and image.content[:4] == b"\x89PNG"
    page = client.get(f"/v1/ensembles/{view['id']}/page").text
    assert "plots/orbit_diagram.svg" in page and "the orbit diagram" in page


def test_an_ensemble_that_is_not_a_sweep_has_no_orbit_diagram(client):
    r = client.post("/v1/ensembles", json={**SAMPLED, "lyapunov": None, "members": {
        "sample": {"count": 2, "seed": 7, "level": {"energy": 1.0, "area": 0.0}}}})
    assert r.status_code == 202, r.text
    view = poll_job(client, r.headers["location"], timeout=120)
    answer = client.get(f"/v1/ensembles/{view['id']}/orbit-diagram")
    assert answer.status_code == 409 and "not a sweep" in answer.json()["detail"]
    assert client.get(f"/v1/ensembles/{view['id']}/plots/orbit_diagram.png").status_code == 409
