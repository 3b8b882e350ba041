"""``GET /v1/jobs?status=&limit=&cursor=`` in embedded mode: newest first, paging, status filter, 422s."""

from __future__ import annotations

import base64
import time

from tests.api.conftest import job

LONG = job(t_final=1e8, samples=2)  # runs until cancelled
QUICK = job(t_final=1.0, samples=11)


def _pages(client, **params) -> list[list[dict]]:
    pages, cursor = [], None
    while True:
        r = client.get("/v1/jobs", params={**params, **({"cursor": cursor} if cursor else {})})
        assert r.status_code == 200, r.text
        body = r.json()
        pages.append(body["items"])
        cursor = body["next_cursor"]
        if cursor is None:
            return pages
        assert len(pages) < 20, "the cursor does not advance"


def _wait(client, job_id: str, status: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while client.get(f"/v1/jobs/{job_id}").json()["status"] != status:
        assert time.monotonic() < deadline, f"job {job_id} not {status} after {timeout:g} s"
        time.sleep(0.02)


def test_list_pages_filters_and_refuses_bad_parameters(client):
    # One worker thread: the first (long) job runs, the next four wait behind it.
    ids = [client.post("/v1/jobs", json=LONG).json()["id"]]
    _wait(client, ids[0], "running")
    ids += [client.post("/v1/jobs", json=QUICK).json()["id"] for _ in range(4)]
    newest_first = ids[::-1]

    page = client.get("/v1/jobs").json()
    assert [item["id"] for item in page["items"]] == newest_first and page["next_cursor"] is None
    created = [item["created_at"] for item in page["items"]]
    assert created == sorted(created, reverse=True)
    first = page["items"][0]
    assert first == {"id": ids[-1], "status": "queued", "progress": 0.0, "created_at": first["created_at"],
                     "kind": "chaplygin_ball", "location": f"/v1/jobs/{ids[-1]}"}

    pages = _pages(client, limit=2)
    assert [len(p) for p in pages] == [2, 2, 1]
    assert [item["id"] for p in pages for item in p] == newest_first  # each exactly once, in order

    assert client.delete(f"/v1/jobs/{ids[2]}").status_code == 202
    by_status = {s: [i["id"] for p in _pages(client, status=s, limit=2) for i in p]
                 for s in ("queued", "running", "cancelled", "succeeded", "failed")}
    assert by_status == {"queued": [ids[4], ids[3], ids[1]], "running": [ids[0]], "cancelled": [ids[2]],
                         "succeeded": [], "failed": []}

    assert client.delete(f"/v1/jobs/{ids[0]}").status_code == 202  # frees the thread for the rest
    for job_id in (ids[1], ids[3], ids[4]):
        _wait(client, job_id, "succeeded")
    done = client.get("/v1/jobs", params={"status": "succeeded"}).json()
    assert [i["id"] for i in done["items"]] == [ids[4], ids[3], ids[1]] and done["next_cursor"] is None
    assert all(i["progress"] == 1.0 and "result" not in i for i in done["items"])
    assert [i["id"] for i in client.get("/v1/jobs", params={"status": "cancelled"}).json()["items"]] == \
        [ids[2], ids[0]]

    # A cursor continues after the last item of its page, whatever happened since.
    cursor = client.get("/v1/jobs", params={"limit": 3}).json()["next_cursor"]
    assert [i["id"] for i in client.get("/v1/jobs", params={"cursor": cursor}).json()["items"]] == [ids[1], ids[0]]


def test_paper_report_jobs_are_listed_with_their_kind(client):
    r = client.post("/v1/paper/report", json={"claims": ["veselova.multiplier"]})
    assert r.status_code == 202
    items = client.get("/v1/jobs").json()["items"]
    assert [(i["id"], i["kind"]) for i in items] == [(r.json()["id"], "paper_report")]


def test_empty_list(client):
    assert client.get("/v1/jobs").json() == {"items": [], "next_cursor": None}


def test_bad_cursor_status_or_limit_is_a_422_naming_the_field(client):
    client.post("/v1/jobs", json=QUICK)
    forged = base64.urlsafe_b64encode(b'["j1", "yesterday", "x"]').decode()
    for params, field in (({"cursor": "garbage"}, "cursor"), ({"cursor": forged}, "cursor"),
                          ({"cursor": ""}, "cursor"), ({"status": "done"}, "status"),
                          ({"status": "QUEUED"}, "status"), ({"limit": 0}, "query.limit"),
                          ({"limit": 501}, "query.limit")):
        r = client.get("/v1/jobs", params=params)
        assert r.status_code == 422, (params, r.text)
        assert r.headers["content-type"] == "application/problem+json"
        assert [e["field"] for e in r.json()["errors"]] == [field], params
    assert client.get("/v1/jobs", params={"limit": 500}).status_code == 200
