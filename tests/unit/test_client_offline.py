"""The client without a service: the progress bar, ApiError, polling against a mock transport, the CLI's
argument and input errors, the serve/worker commands."""

from __future__ import annotations

import io
import sys

import httpx
import pytest

from nonholonomic_client import ApiError, Client, JobFailed, ProgressBar
from nonholonomic_client.cli import main
from nonholonomic_client.processes import serve_command, worker_command
from nonholonomic_client.progress import render_bar

PROBLEM = {"type": "/problems/invalid-request", "title": "Invalid request", "status": 422,
           "detail": "system.inertia[0]: Input should be greater than 0", "instance": "/v1/jobs",
           "errors": [{"field": "system.inertia[0]", "reason": "Input should be greater than 0"}]}


class FakeTTY(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_render_bar():
    assert render_bar(0.5, "running", width=10) == "[#####-----]  50% running"
    assert render_bar(1.0, "succeeded", 2.345, width=4) == "[####] 100% succeeded 2.3 s"
    assert render_bar(-1.0, "queued", width=4) == "[----]   0% queued"
    assert render_bar(float("nan"), "queued", width=4) == "[----]   0% queued"


def test_progress_bar_writes_a_line_per_tenth_when_not_a_terminal():
    out = io.StringIO()
    bar = ProgressBar(out, label="job x", tty=False, clock=lambda: 0.0)
    for f in (0.0, 0.01, 0.05, 0.12, 0.19, 0.5, 0.51, 1.0):
        bar(f, "running")
    bar(1.0, "succeeded")
    bar.close()
    lines = out.getvalue().splitlines()
    assert [line.split("] ")[1] for line in lines] == ["  0% running 0.0 s", " 12% running 0.0 s", " 50% running 0.0 s",
                                                       "100% running 0.0 s", "100% succeeded 0.0 s"]
    assert all(line.startswith("job x [") for line in lines)


def test_progress_bar_redraws_in_place_on_a_terminal():
    out = FakeTTY()
    with ProgressBar(out, clock=lambda: 0.0) as bar:
        assert bar.tty
        bar(0.25, "running")
        bar(1.0, "succeeded")
    text = out.getvalue()
    assert text.count("\r") == 2 and text.endswith("succeeded 0.0 s\n") and text.count("\n") == 1


def test_api_error_formats_the_problem():
    err = ApiError(PROBLEM)
    assert (err.status, err.type, err.title) == (422, "/problems/invalid-request", "Invalid request")
    assert err.errors == [{"field": "system.inertia[0]", "reason": "Input should be greater than 0"}]
    assert str(err) == "422 Invalid request: system.inertia[0]: Input should be greater than 0"
    assert err.problem == PROBLEM and not err.unreachable
    bare = ApiError({"status": 422, "title": "Invalid request", "errors": [{"field": "t_final", "reason": "> 0"}]})
    assert str(bare) == "422 Invalid request: t_final: > 0"


def test_an_answer_that_is_not_problem_json_still_gives_an_api_error():
    request = httpx.Request("GET", "http://x/v1/jobs/1")
    err = ApiError.from_response(httpx.Response(502, text="<html>Bad gateway</html>", request=request))
    assert err.status == 502 and err.title == "Bad Gateway" and "Bad gateway" in err.detail
    err = ApiError.from_response(httpx.Response(500, request=request))
    assert err.status == 500 and "without a body" in err.detail


def _views(*views: dict) -> httpx.MockTransport:
    pending = list(views)

    def handler(request: httpx.Request) -> httpx.Response:
        if request.url.path == "/health":
            return httpx.Response(503, json={"status": "degraded", "broker": "unreachable"})
        if request.url.path == "/v1/jobs/missing":
            return httpx.Response(404, json={**PROBLEM, "status": 404, "title": "Unknown job", "errors": []},
                                  headers={"content-type": "application/problem+json"})
        return httpx.Response(200, json=pending.pop(0) if len(pending) > 1 else pending[0])

    return httpx.MockTransport(handler)


def test_wait_polls_the_summary_view_and_fetches_the_samples_once():
    """The polls ask for the summary view (no samples); the samples come in one last request, or not at
    all with ``trajectory=False``."""
    asked: list[str | None] = []
    states = iter(["running", "succeeded", "succeeded", "succeeded", "succeeded"])

    def handler(request: httpx.Request) -> httpx.Response:
        summary = request.url.params.get("trajectory")
        asked.append(summary)
        result = {"t_final": 1.0, **({"trajectory_location": "/v1/jobs/j/trajectory"} if summary == "false"
                                     else {"trajectory": {"t": [0.0, 1.0]}})}
        status = next(states)
        return httpx.Response(200, json={"id": "j", "status": status, "progress": 1.0 if status == "succeeded" else 0.5,
                                         "result": result if status == "succeeded" else None})

    with Client("http://api", transport=httpx.MockTransport(handler)) as client:
        view = client.wait("j", poll=0.0)
        assert asked == ["false", "false", None] and view["result"]["trajectory"] == {"t": [0.0, 1.0]}
        asked.clear()
        summary = client.wait("j", poll=0.0, trajectory=False)
        assert asked == ["false"] and "trajectory" not in summary["result"]
        asked.clear()
        assert "trajectory" not in client.job("j", trajectory=False)["result"] and asked == ["false"]


def test_wait_polls_until_done_and_reports_progress():
    transport = _views({"id": "j", "status": "queued", "progress": 0.0},
                       {"id": "j", "status": "running", "progress": 0.4},
                       {"id": "j", "status": "succeeded", "progress": 1.0, "result": {"t_final": 1.0}})
    calls: list[tuple[float, str]] = []
    with Client("http://api", transport=transport) as client:
        view = client.wait("j", poll=0.0, progress=lambda f, s: calls.append((f, s)))
        assert client.result("j") == {"t_final": 1.0}
        assert client.health()["status"] == "degraded"  # a 503 is returned, not raised
        with pytest.raises(ApiError) as caught:
            client.job("missing")
    assert view["status"] == "succeeded"
    assert calls == [(0.0, "queued"), (0.4, "running"), (1.0, "succeeded")]
    assert caught.value.status == 404 and str(caught.value).startswith("404 Unknown job: ")


def test_wait_raises_job_failed_with_the_job_s_error_and_times_out():
    failed = {"id": "j", "status": "failed", "progress": 0.3,
              "error": {"type": "InvalidJob", "message": "initial_state.gamma: not a unit vector"}}
    with Client("http://api", transport=_views(failed)) as client, pytest.raises(JobFailed) as caught:
        client.wait("j", poll=0.0)
    err = caught.value
    assert isinstance(err, ApiError) and err.status is None and err.job_status == "failed"
    assert str(err) == "Job failed: InvalidJob: initial_state.gamma: not a unit vector"
    cancelled = _views({"id": "e", "status": "cancelled", "progress": 0.5})
    with Client("http://api", transport=cancelled) as client, pytest.raises(JobFailed, match="ensemble e was cancel"):
        client.wait_ensemble("e", poll=0.0)
    running = _views({"id": "j", "status": "running", "progress": 0.1})
    with Client("http://api", transport=running) as client, pytest.raises(TimeoutError, match="still running"):
        client.wait("j", timeout=0.05, poll=0.01)


def test_a_transport_error_is_an_api_error_with_status_0(tmp_path):
    def refuse(request: httpx.Request) -> httpx.Response:
        raise httpx.ConnectError("[Errno 111] Connection refused", request=request)

    with Client("http://api:1/", transport=httpx.MockTransport(refuse)) as client:
        with pytest.raises(ApiError) as caught:
            client.systems()
        assert caught.value.status == 0 and caught.value.unreachable
        assert caught.value.detail == "cannot reach http://api:1/v1/systems: [Errno 111] Connection refused"
        with pytest.raises(ApiError):
            client.trajectory("j", "csv", out=tmp_path / "t.csv")
    assert not list(tmp_path.iterdir())


def test_cli_usage_errors_exit_2_without_contacting_anything(tmp_path, capsys, monkeypatch):
    (tmp_path / "broken.json").write_text('{"t_final": 1,\n "samples": }')
    assert main(["run", str(tmp_path / "broken.json")]) == 2
    assert "broken.json is not JSON: Expecting value at line 2 column 13 (character 27)" in capsys.readouterr().err
    assert main(["run", str(tmp_path / "absent.json")]) == 2
    assert "cannot read" in capsys.readouterr().err
    (tmp_path / "spec.json").write_text("{}")
    assert main(["run", str(tmp_path / "spec.json"), "--out", "traj.txt"]) == 2
    assert "suffix must be one of .csv, .npz, .json" in capsys.readouterr().err
    assert main(["ensemble", str(tmp_path / "spec.json"), "--out", "s.csv"]) == 2
    assert "poincare" in capsys.readouterr().err
    assert main([]) == 2
    assert main(["report"]) == 2  # --out is required
    monkeypatch.setattr(sys, "stdin", io.StringIO("not json"))
    assert main(["run", "-"]) == 2
    assert "stdin is not JSON" in capsys.readouterr().err


def test_serve_and_worker_commands():
    argv, env, banner = serve_command("127.0.0.1", 8123, False, {"REDIS_URL": "redis://r/0", "PATH": "/bin"})
    assert argv == [sys.executable, "-m", "uvicorn", "service.main:app", "--host", "127.0.0.1", "--port", "8123"]
    assert "REDIS_URL" not in env and env["PATH"] == "/bin" and "http://127.0.0.1:8123" in banner
    argv, env, banner = serve_command("127.0.0.1", 0, True, {})
    port = int(argv[-1])
    assert port > 0 and f"http://127.0.0.1:{port}" in banner and env["REDIS_URL"] == "redis://127.0.0.1:6379/0"
    argv, env, banner = worker_command(3, {"REDIS_URL": "redis://:secret@h:6379/1", "NONHOLONOMIC_QUEUE": "q"})
    assert argv == [sys.executable, "-m", "celery", "-A", "workers.celery_app:app", "worker", "-Q", "q",
                    "--loglevel", "INFO", "--concurrency", "3"]
    assert "secret" not in banner and "'q'" in banner and env["REDIS_URL"].endswith("h:6379/1")
    argv, env, _ = worker_command(None, {})
    assert argv[argv.index("-Q") + 1] == "nonholonomic" and env["REDIS_URL"] == "redis://127.0.0.1:6379/0"
    assert "--concurrency" not in argv



def _cli_against(monkeypatch, handler) -> None:
    from nonholonomic_client import commands

    monkeypatch.setattr(commands, "_client", lambda args: Client(args.url, transport=httpx.MockTransport(handler)))


def test_cli_exit_codes_for_a_failed_job_and_a_server_error(tmp_path, capsys, monkeypatch):
    (tmp_path / "spec.json").write_text("{}")
    failed = {"id": "j", "status": "failed", "progress": 0.2, "result": None,
              "error": {"type": "FloatingPointError", "message": "the integration blew up at t = 3.1"}}

    def job_fails(request: httpx.Request) -> httpx.Response:
        if request.method == "POST":
            return httpx.Response(202, json={"id": "j", "status": "queued", "location": "/v1/jobs/j"})
        return httpx.Response(200, json=failed)

    _cli_against(monkeypatch, job_fails)
    assert main(["--url", "http://api", "run", str(tmp_path / "spec.json"), "--wait"]) == 1
    out, err = capsys.readouterr()
    assert out.startswith("job j\nlocation http://api/v1/jobs/j\n")
    assert "error: Job failed: FloatingPointError: the integration blew up at t = 3.1" in err

    _cli_against(monkeypatch, lambda request: httpx.Response(
        500, json={"type": "/problems/internal-error", "title": "Internal error", "status": 500,
                   "detail": "KeyError: the server failed; this is a bug"}))
    assert main(["--url", "http://api", "systems"]) == 3
    assert capsys.readouterr().err == "error: Internal error: KeyError: the server failed; this is a bug\n"
    _cli_against(monkeypatch, lambda request: httpx.Response(
        503, headers={"X-Request-ID": "r-503"},
        json={"type": "/problems/unavailable", "title": "Unavailable", "status": 503, "detail": "no broker"}))
    assert main(["--url", "http://api", "systems"]) == 3
    assert capsys.readouterr().err == ("error: Unavailable: no broker\n"
                                       "  request id: r-503 (the service's logs carry it)\n")

    _cli_against(monkeypatch, lambda request: httpx.Response(
        422, json={"type": "/problems/invalid-request", "title": "Invalid request", "status": 422,
                   "detail": "system.kind: unknown; t_final: must be > 0",
                   "errors": [{"field": "system.kind", "reason": "unknown"},
                              {"field": "t_final", "reason": "must be > 0"}]}))
    assert main(["--url", "http://api", "run", str(tmp_path / "spec.json")]) == 2
    # each error once (the detail, which only joins them, is not printed beside them)
    assert capsys.readouterr().err == "error: Invalid request\n  system.kind: unknown\n  t_final: must be > 0\n"


def test_the_client_sends_its_api_key_as_a_bearer_token(monkeypatch):
    import httpx

    from nonholonomic_client import Client

    seen: list[str | None] = []

    def handler(request: httpx.Request) -> httpx.Response:
        seen.append(request.headers.get("authorization"))
        return httpx.Response(200, json={"systems": []})

    with Client("http://api.test", api_key="k-1", transport=httpx.MockTransport(handler)) as api:
        api.systems()
    monkeypatch.setenv("NONHOLONOMIC_API_KEY", "k-2")
    with Client("http://api.test", transport=httpx.MockTransport(handler)) as api:
        api.systems()
    monkeypatch.delenv("NONHOLONOMIC_API_KEY")
    with Client("http://api.test", transport=httpx.MockTransport(handler)) as api:
        api.systems()
    assert seen == ["Bearer k-1", "Bearer k-2", None]


def test_wait_honours_retry_after_of_a_429_and_503(monkeypatch):
    import httpx

    import nonholonomic_client.base as api_module
    from nonholonomic_client import ApiError, Client

    answers = [
        httpx.Response(429, json={"title": "Rate limit", "status": 429, "detail": "slow down"},
                       headers={"Retry-After": "2"}),
        httpx.Response(503, json={"title": "Unavailable", "status": 503, "detail": "restart"},
                       headers={"Retry-After": "1"}),
        httpx.Response(200, json={"id": "j", "status": "succeeded", "progress": 1.0, "result": {}}),
    ]
    slept: list[float] = []
    monkeypatch.setattr(api_module.time, "sleep", slept.append)
    with Client("http://api.test", transport=httpx.MockTransport(lambda request: answers.pop(0))) as api:
        assert api.wait("j", trajectory=False)["status"] == "succeeded"  # the polls only
    assert slept == [2.0, 1.0]
    without = httpx.MockTransport(lambda request: httpx.Response(503, json={"title": "Unavailable", "status": 503}))
    with Client("http://api.test", transport=without) as api, pytest.raises(ApiError) as raised:
        api.wait("j")
    assert raised.value.status == 503 and raised.value.retry_after is None
