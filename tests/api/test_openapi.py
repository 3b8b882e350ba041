"""The OpenAPI document tells the truth: stable operation ids, every answer declared with its real
status and media type (problems as ``application/problem+json``), and a client generated from it
with openapi-python-client works against the service."""

from __future__ import annotations

import copy
import importlib
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi import APIRouter
from fastapi.testclient import TestClient

from nonholonomic.systems import SYSTEMS
from schemas.jobs import JobRequest as ServerJobRequest
from schemas.settings import Settings, get_settings
from service.main import create_app
from service.openapi import OPERATION_ID, SETTING_LIMITS, operation_id

PROBLEM_REF = "#/components/schemas/Problem"
#: Package name of the generated client (a directory on sys.path for this module only).
CLIENT_PACKAGE = "nonholonomic_generated_client"
#: No formatter hooks (no ruff needed); nothing else: the generator's defaults (no content_type_overrides),
#: the client as anyone would generate it.
GENERATOR_CONFIG = """\
post_hooks: []
"""
BALL_KINDS = ("chaplygin_ball", "chaplygin_ball_veselova", "rubber_ball")


@pytest.fixture(scope="module")
def spec() -> Iterator[dict[str, Any]]:
    """The live ``/openapi.json`` of the app in embedded mode."""
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("REDIS_URL", raising=False)
        mp.delenv("NONHOLONOMIC_REDIS_URL", raising=False)
        mp.setenv("NONHOLONOMIC_WARM_UP", "false")
        get_settings.cache_clear()
        with TestClient(create_app()) as c:
            r = c.get("/openapi.json")
        get_settings.cache_clear()
    assert r.status_code == 200
    yield r.json()


def _operations(spec: dict[str, Any]) -> Iterator[tuple[str, str, dict[str, Any]]]:
    for path, item in spec["paths"].items():
        for method, operation in item.items():
            yield method.upper(), path, operation


def test_operation_ids_are_unique_and_stable(spec):
    ids = {f"{method} {path}": op["operationId"] for method, path, op in _operations(spec)}
    assert len(set(ids.values())) == len(ids), ids
    assert [i for i in ids.values() if not OPERATION_ID.match(i)] == []
    assert ids["POST /v1/jobs"] == "jobs-submit"
    assert ids["GET /v1/jobs/{job_id}"] == "jobs-get"
    assert ids["DELETE /v1/jobs/{job_id}"] == "jobs-cancel"
    assert ids["GET /v1/jobs/{job_id}/trajectory"] == "jobs-trajectory"
    assert ids["GET /v1/jobs/{job_id}/section"] == "jobs-section"
    assert ids["GET /v1/jobs/{job_id}/plots/{name}.{fmt}"] == "jobs-plot"
    assert ids["GET /v1/ensembles/{ensemble_id}/plots/{name}.{fmt}"] == "ensembles-plot"
    assert ids["POST /v1/ensembles"] == "ensembles-submit" and ids["GET /v1/ensembles/{ensemble_id}"] == "ensembles-get"
    assert ids["DELETE /v1/ensembles/{ensemble_id}"] == "ensembles-cancel"
    assert ids["GET /v1/ensembles/{ensemble_id}/poincare"] == "ensembles-section"
    assert ids["GET /v1/ensembles/{ensemble_id}/members"] == "ensembles-members"
    assert ids["GET /v1/systems"] == "systems-list" and ids["GET /v1/systems/{kind}"] == "systems-get"
    assert ids["GET /health"] == "health-get"
    assert ids["GET /v1/paper/claims"] == "paper-claims" and ids["POST /v1/paper/report"] == "paper-report-submit"
    assert ids["GET /v1/maps"] == "maps-list" and ids["POST /v1/maps/{name}"] == "maps-apply"
    assert ids["POST /v1/hamiltonize"] == "symbolic-hamiltonize"
    assert ids["POST /v1/brackets/verify"] == "symbolic-brackets-verify"
    assert ids["GET /v1/hamiltonize/examples"] == "symbolic-hamiltonize-examples"
    assert ids["GET /v1/paper/report/{job_id}"] == "paper-report-page"


def test_a_route_without_an_operation_id_gets_one_of_the_same_shape():
    router = APIRouter(tags=["paper report"], generate_unique_id_function=operation_id)

    @router.get("/a")
    def list_claims() -> None: ...

    @router.post("/b")
    def paper() -> None: ...

    assert [route.unique_id for route in router.routes] == ["paper-list-claims", "paper-post"]


def test_every_error_is_declared_as_problem_json(spec):
    """Every non-2xx answer declares the Problem schema as application/problem+json (``/health``'s 503
    also declares its usual body, which it sends with status 'degraded')."""
    wrong = []
    for method, path, op in _operations(spec):
        for status, response in op["responses"].items():
            if status.startswith("2"):
                continue
            content = response.get("content", {})
            problem = content.get("application/problem+json", {}).get("schema", {}).get("$ref")
            others = set(content) - {"application/problem+json"}
            if (method, path, status) == ("GET", "/health", "503"):
                others -= {"application/json"}
            if problem != PROBLEM_REF or others:
                wrong.append((method, path, status, sorted(content)))
    assert wrong == []
    schemas = spec["components"]["schemas"]
    assert {"Problem", "FieldError"} <= set(schemas)
    assert not {"HTTPValidationError", "ValidationError"} & set(schemas)


def test_declared_statuses_are_the_real_ones(spec):
    paths = spec["paths"]
    cancel = paths["/v1/jobs/{job_id}"]["delete"]["responses"]
    assert "202" in cancel and "200" not in cancel and {"404", "409"} <= set(cancel)
    kind = paths["/v1/systems/{kind}"]["get"]["responses"]
    assert "404" in kind and "422" not in kind
    health = paths["/health"]["get"]["responses"]
    assert health["503"]["content"]["application/json"]["schema"] == {"$ref": "#/components/schemas/Health"}
    assert "422" in paths["/v1/jobs"]["post"]["responses"] and "404" not in paths["/v1/jobs"]["post"]["responses"]
    assert "422" in paths["/v1/jobs/{job_id}"]["get"]["responses"]  # ?trajectory=maybe (the id itself cannot be)
    assert "503" in paths["/v1/hamiltonize"]["post"]["responses"]


def test_every_body_may_be_too_large(spec):
    """The body limit's 413 (problem+json) is declared wherever a body is read, and only there."""
    for method, path, op in _operations(spec):
        declared = op["responses"].get("413")
        if "requestBody" in op:
            assert declared is not None, (method, path)
            assert declared["content"]["application/problem+json"]["schema"] == {"$ref": PROBLEM_REF}
        else:
            assert declared is None, (method, path)


def test_the_document_states_the_deployments_limits(monkeypatch):
    """Each limit of the settings is the ``maximum`` (or ``maxItems``) of the request fields it bounds,
    and the app holds to it: at the limit accepted, above it a 422 naming the field."""
    monkeypatch.delenv("REDIS_URL", raising=False)
    monkeypatch.delenv("NONHOLONOMIC_REDIS_URL", raising=False)
    monkeypatch.setenv("NONHOLONOMIC_WARM_UP", "false")
    limits = {"max_t_final": 50.0, "max_samples": 300, "max_section_points": 40, "max_ensemble_members": 7}
    for name, value in limits.items():
        monkeypatch.setenv(f"NONHOLONOMIC_{name.upper()}", str(value))
    get_settings.cache_clear()
    try:
        with TestClient(create_app(Settings(**limits))) as c:
            schemas = c.get("/openapi.json").json()["components"]["schemas"]
            for (schema, prop), (setting, keyword) in SETTING_LIMITS.items():
                field = schemas[schema]["properties"][prop]
                branches = [b for b in field.get("anyOf", []) if b.get("type") != "null"] or [field]
                assert [b[keyword] for b in branches] == [limits[setting]], (schema, prop, field)
            body = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
                    "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 50.0,
                    "samples": 300}
            assert c.post("/v1/jobs", json=body).status_code == 202
            for field, above in (("t_final", 50.5), ("samples", 301)):
                r = c.post("/v1/jobs", json={**body, field: above})
                assert r.status_code == 422 and [e["field"] for e in r.json()["errors"]] == [field], r.text
    finally:
        get_settings.cache_clear()


BYTES = {"type": "string", "format": "binary"}
#: Every download: its path, and the media types its 200 declares (application/octet-stream first).
DOWNLOADS = {
    "/v1/jobs/{job_id}/trajectory": ["application/octet-stream", "application/json", "text/csv",
                                     "application/x-netcdf"],
    "/v1/jobs/{job_id}/section": ["application/octet-stream", "application/json", "text/csv", "application/x-netcdf"],
    "/v1/ensembles/{ensemble_id}/poincare": ["application/octet-stream", "text/csv", "application/x-netcdf"],
    "/v1/jobs/{job_id}/plots/{name}.{fmt}": ["application/octet-stream", "image/png", "image/svg+xml"],
    "/v1/ensembles/{ensemble_id}/plots/{name}.{fmt}": ["application/octet-stream", "image/png", "image/svg+xml"],
}


def test_binary_and_text_answers_declare_their_media_types(spec):
    """A download's 200 lists application/octet-stream first (a generated client reads the bytes), then every
    media type the route answers, each a binary string but the JSON (its model)."""
    paths = spec["paths"]
    for path, media_types in DOWNLOADS.items():
        content = paths[path]["get"]["responses"]["200"]["content"]
        assert list(content) == media_types, path
        assert all(content[m]["schema"] == BYTES for m in media_types if m != "application/json"), path
    assert paths["/v1/jobs/{job_id}/trajectory"]["get"]["responses"]["200"]["content"]["application/json"][
        "schema"] == {"$ref": "#/components/schemas/TrajectoryExport"}
    assert paths["/v1/jobs/{job_id}/section"]["get"]["responses"]["200"]["content"]["application/json"][
        "schema"] == {"$ref": "#/components/schemas/SectionExport"}
    for path in ("/v1/jobs/{job_id}/trajectory", "/v1/jobs/{job_id}/section"):
        (fmt,) = [p for p in paths[path]["get"]["parameters"] if p["name"] == "format"]
        assert fmt["schema"]["enum"] == ["json", "csv", "npz", "netcdf"] and fmt["in"] == "query"
    assert set(paths["/v1/paper/report/{job_id}"]["get"]["responses"]["200"]["content"]) == {"text/html"}


def test_sections_and_spectra_have_models(spec):
    """A job's and a member's ``poincare`` and ``lyapunov`` are typed, and the models hold every field the
    core's Section and Spectrum give (nothing the service sends goes undocumented)."""
    from dataclasses import fields

    from nonholonomic.analysis.lyapunov import Spectrum
    from nonholonomic.analysis.poincare import Section

    schemas = spec["components"]["schemas"]
    for model in ("SimulationResultModel", "MemberResultModel"):
        props = schemas[model]["properties"]
        assert {"$ref": "#/components/schemas/SectionResult"} in props["poincare"]["anyOf"], model
        assert {"$ref": "#/components/schemas/SpectrumResult"} in props["lyapunov"]["anyOf"], model
    assert set(schemas["SectionResult"]["properties"]) == {"count", *(f.name for f in fields(Section))}
    assert set(schemas["SpectrumResult"]["properties"]) == {f.name for f in fields(Spectrum)}
    assert set(schemas["SectionExport"]["properties"]) == {*schemas["SectionResult"]["properties"], "units"}


def test_typed_answers(spec):
    """The catalog, the symbolic routes, the maps, the claims, health and the members page have models."""
    refs = {("GET", "/v1/systems"): "Catalog",
            ("POST", "/v1/brackets/verify"): "BracketVerifyResult", ("POST", "/v1/hamiltonize"): "HamiltonizeResult",
            ("GET", "/v1/hamiltonize/examples"): "HamiltonizeExamples", ("GET", "/v1/maps"): "MapList",
            ("POST", "/v1/maps/{name}"): "MapResult", ("GET", "/v1/paper/claims"): "ClaimList",
            ("GET", "/health"): "Health", ("GET", "/v1/ensembles/{ensemble_id}/members"): "MembersPage"}
    for (method, path), name in refs.items():
        schema = spec["paths"][path][method.lower()]["responses"]["200"]["content"]["application/json"]["schema"]
        assert schema == {"$ref": f"#/components/schemas/{name}"}, (method, path)
    # a kind of the catalog, or a generalized Chaplygin or Lagrangian system of one's own
    # (GET /v1/systems/generalized_chaplygin, /v1/systems/lagrangian)
    kind = spec["paths"]["/v1/systems/{kind}"]["get"]["responses"]["200"]["content"]["application/json"]["schema"]
    assert kind["anyOf"] == [{"$ref": "#/components/schemas/SystemDescription"},
                             {"$ref": "#/components/schemas/CatalogLagrangian"},
                             {"$ref": "#/components/schemas/CatalogGeneralizedChaplygin"}]


def test_the_ball_parameter_keeps_its_name(spec):
    """``D`` stays ``D`` in the request schema; the lower-case guard admits no value."""
    for name in ("ChaplyginBallSpec", "ChaplyginBallVeselovaSpec", "RubberBallSpec"):
        schema = spec["components"]["schemas"][name]
        assert "D" in schema["required"] and "d" not in schema["required"]
        assert list(schema["properties"])[-1] == "d" and schema["properties"]["d"]["not"] == {}


# --------------------------------------------------------------------------------------------------
# a client generated from the document


def _generator() -> list[str]:
    """``python -m openapi_python_client`` with this interpreter, else the script next to it."""
    probe = subprocess.run([sys.executable, "-m", "openapi_python_client", "--version"], check=False,
                           capture_output=True)
    if probe.returncode == 0:
        return [sys.executable, "-m", "openapi_python_client"]
    script = Path(sys.executable).with_name("openapi-python-client")
    if not script.exists():
        pytest.skip("openapi-python-client is not installed (extra 'test')")
    return [str(script)]


@pytest.fixture(scope="module")
def generated(spec, tmp_path_factory) -> Iterator[Any]:
    """A client package generated from the live document (once per module), imported."""
    root = tmp_path_factory.mktemp("generated-client")
    (root / "spec.json").write_text(json.dumps(spec))
    (root / "config.yaml").write_text(GENERATOR_CONFIG)
    out = root / CLIENT_PACKAGE
    done = subprocess.run([*_generator(), "generate", "--path", str(root / "spec.json"), "--output-path", str(out),
                           "--meta", "none", "--config", str(root / "config.yaml"), "--fail-on-warning"],
                          check=False, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    sys.path.insert(0, str(root))
    try:
        yield importlib.import_module(CLIENT_PACKAGE)
    finally:
        sys.path.remove(str(root))
        for name in [m for m in sys.modules if m == CLIENT_PACKAGE or m.startswith(CLIENT_PACKAGE + ".")]:
            del sys.modules[name]


def _ball_jobs(kind: str) -> list[dict[str, Any]]:
    """The catalog's example job of ``kind`` (short), with its potential, without one, and with a linear one."""
    example = {**copy.deepcopy(SYSTEMS[kind].EXAMPLE), "t_final": 2.0, "samples": 11}
    bare = copy.deepcopy(example)
    del bare["system"]["potential"]
    linear = copy.deepcopy(example)
    linear["system"]["potential"] = {"kind": "linear", **{par.name: [0.3, -0.2, 0.5]  # a (and b for the E-term)
                                                          for par in SYSTEMS[kind].POTENTIALS["linear"].parameters}}
    return [example, bare, linear]


@pytest.mark.parametrize("kind", BALL_KINDS)
def test_generated_job_request_round_trips_the_balls(generated, kind):
    JobRequest = importlib.import_module(f"{CLIENT_PACKAGE}.models.job_request").JobRequest
    for body in _ball_jobs(kind):
        parsed = JobRequest.from_dict(body)
        assert parsed.system.D == body["system"]["D"] and parsed.system.kind == kind
        assert parsed.to_dict() == body
        ServerJobRequest.model_validate(parsed.to_dict())  # and the service takes it


def test_generated_client_submits_polls_and_reads_a_ball_job(generated, client):
    from importlib import import_module

    jobs_submit = import_module(f"{CLIENT_PACKAGE}.api.jobs.jobs_submit")
    jobs_get = import_module(f"{CLIENT_PACKAGE}.api.jobs.jobs_get")
    jobs_trajectory = import_module(f"{CLIENT_PACKAGE}.api.jobs.jobs_trajectory")
    systems_get = import_module(f"{CLIENT_PACKAGE}.api.systems.systems_get")
    JobRequest = import_module(f"{CLIENT_PACKAGE}.models.job_request").JobRequest
    Problem = import_module(f"{CLIENT_PACKAGE}.models.problem").Problem

    api = generated.Client(base_url=str(client.base_url))
    api.set_httpx_client(client)  # the TestClient is an httpx.Client: requests go to the app in-process
    body = _ball_jobs("chaplygin_ball")[1]
    accepted = jobs_submit.sync_detailed(client=api, body=JobRequest.from_dict(body))
    assert accepted.status_code == 202 and accepted.headers["location"] == f"/v1/jobs/{accepted.parsed.id}"
    deadline = time.monotonic() + 60
    while True:
        view = jobs_get.sync(accepted.parsed.id, client=api)
        if str(view.status) in ("succeeded", "failed", "cancelled") or time.monotonic() > deadline:
            break
        time.sleep(0.01)
    assert str(view.status) == "succeeded", view
    assert view.request.to_dict()["system"]["D"] == body["system"]["D"]
    result = view.result
    assert result.system.kind == "chaplygin_ball" and result.t_final == pytest.approx(2.0)
    assert {i.name for i in result.integrals} >= {"energy", "area"} and all(i.passed for i in result.integrals)
    assert len(result.trajectory.t) == 11 and result.system.units["t"] == "s"
    samples = jobs_trajectory.sync(accepted.parsed.id, client=api)  # the JSON's bytes
    assert json.loads(samples.payload.read())["t"] == result.trajectory.t
    # problems parse into the generated Problem
    missing = jobs_get.sync_detailed("no-such-job", client=api)
    assert missing.status_code == 404 and isinstance(missing.parsed, Problem) and missing.parsed.status == 404
    unknown = systems_get.sync_detailed("suslov", client=api)
    assert unknown.status_code == 404 and isinstance(unknown.parsed, Problem)
    ball = systems_get.sync("chaplygin_ball", client=api)
    assert [p.name for p in ball.parameters] == ["inertia", "D"]


def test_generated_client_reads_every_typed_answer(generated, client):
    from importlib import import_module

    api = generated.Client(base_url=str(client.base_url))
    api.set_httpx_client(client)
    catalog = import_module(f"{CLIENT_PACKAGE}.api.systems.systems_list").sync(client=api)
    assert {s.kind for s in catalog.systems} >= set(BALL_KINDS)
    health = import_module(f"{CLIENT_PACKAGE}.api.health.health_get").sync(client=api)
    assert str(health.status) == "ok" and str(health.mode) == "embedded"
    maps = import_module(f"{CLIENT_PACKAGE}.api.maps.maps_list").sync(client=api)
    assert "chaplygin_ball_to_clebsch" in {m.name for m in maps.maps}
    claims = import_module(f"{CLIENT_PACKAGE}.api.paper_report.paper_claims").sync(client=api)
    assert "general.theorem_1" in claims.claims
    examples = import_module(f"{CLIENT_PACKAGE}.api.symbolic.symbolic_hamiltonize_examples").sync(client=api)
    assert examples.examples["chaplygin_ball"].monopole.shift == ["0", "c*N*cos(theta)"]


#: A ball job with a section (a dozen crossings) and two exponents; an ensemble with both.
SECTION_JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
               "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 200.0, "samples": 21,
               "poincare": {"surface": "gamma3", "direction": "both", "coordinates": ["gamma1", "gamma2"],
                            "max_points": 50},
               "lyapunov": {"count": 2, "interval": 1.0}}
SECTION_ENSEMBLE = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
                    "members": {"sample": {"count": 3, "seed": 7, "level": {"energy": 1.0, "area": 0.0}}},
                    "t_final": 60.0, "samples": 3, "poincare": {"surface": "gamma3"}, "lyapunov": {"count": 1}}


def _finished(client, path: str, body: dict[str, Any]) -> str:
    r = client.post(path, json=body)
    assert r.status_code == 202, r.text
    deadline = time.monotonic() + 120
    while (view := client.get(r.headers["location"]).json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, view
        time.sleep(0.02)
    assert view["status"] == "succeeded", view
    return view["id"]


def test_generated_client_downloads_every_file_as_its_exact_bytes(generated, client):
    """Every download route through the generated client (default generator settings): trajectory and
    section in every format, the ensemble's section, every plot; the bytes are what httpx gets directly,
    and the section, spectrum and generalized Chaplygin entry parse into their models."""
    from importlib import import_module

    def api_module(tag: str, name: str) -> Any:
        return import_module(f"{CLIENT_PACKAGE}.api.{tag}.{name}")

    def model(module: str, name: str) -> Any:
        return getattr(import_module(f"{CLIENT_PACKAGE}.models.{module}"), name)

    File = import_module(f"{CLIENT_PACKAGE}.types").File
    api = generated.Client(base_url=str(client.base_url))
    api.set_httpx_client(client)
    job_id = _finished(client, "/v1/jobs", SECTION_JOB)
    ensemble_id = _finished(client, "/v1/ensembles", SECTION_ENSEMBLE)

    calls = []  # (what, the generated call's answer, the direct GET's path and params)
    for op, path in (("jobs_trajectory", "trajectory"), ("jobs_section", "section")):
        Format = model(f"{op}_format", "".join(w.title() for w in op.split("_")) + "Format")
        for fmt in ("json", "csv", "npz", "netcdf"):
            answer = api_module("jobs", op).sync_detailed(job_id, client=api, format_=Format(fmt))
            calls.append((f"{path} {fmt}", answer, f"/v1/jobs/{job_id}/{path}", {"format": fmt}))
    Format = model("ensembles_section_format", "EnsemblesSectionFormat")
    for fmt in ("csv", "npz", "netcdf"):
        answer = api_module("ensembles", "ensembles_section").sync_detailed(ensemble_id, client=api,
                                                                              format_=Format(fmt))
        calls.append((f"ensemble section {fmt}", answer, f"/v1/ensembles/{ensemble_id}/poincare", {"format": fmt}))
    for tag, ident, names in (("jobs", job_id, ("trajectory", "integrals", "poincare", "lyapunov")),
                              ("ensembles", ensemble_id, ("poincare", "exponents"))):
        Name, Fmt = (model(f"{tag}_plot_name", f"{tag.title()}PlotName"),
                     model(f"{tag}_plot_fmt", f"{tag.title()}PlotFmt"))
        for name in names:
            for fmt in ("png", "svg"):
                answer = api_module(tag, f"{tag}_plot").sync_detailed(ident, Name(name), Fmt(fmt), client=api)
                calls.append((f"{tag} plot {name}.{fmt}", answer, f"/v1/{tag}/{ident}/plots/{name}.{fmt}", {}))

    magic = {"npz": b"PK", "netcdf": b"\x89HDF", "png": b"\x89PNG", "svg": b"<?xml"}
    for what, answer, path, params in calls:
        direct = client.get(path, params=params)
        assert answer.status_code == 200 == direct.status_code, (what, answer.content[:300])
        assert isinstance(answer.parsed, File), (what, type(answer.parsed))
        data = answer.parsed.payload.read()
        assert data == direct.content and data, what
        suffix = what.rsplit(" ", 1)[1].rsplit(".", 1)[-1]
        assert data.startswith(magic.get(suffix, b"")), what
    assert len(calls) == 8 + 3 + 12

    # typed: the job's section and spectrum, a member's, the generalized Chaplygin entry
    SectionResult, SpectrumResult = model("section_result", "SectionResult"), model("spectrum_result", "SpectrumResult")
    view = api_module("jobs", "jobs_get").sync(job_id, client=api)
    section, spectrum = view.result.poincare, view.result.lyapunov
    assert isinstance(section, SectionResult) and isinstance(spectrum, SpectrumResult)
    served = client.get(f"/v1/jobs/{job_id}").json()["result"]
    assert section.count == served["poincare"]["count"] >= 5 and section.t == served["poincare"]["t"]
    assert section.points["gamma"] == served["poincare"]["points"]["gamma"]
    assert str(section.direction) == "both" and section.coordinate_names == ["gamma1", "gamma2"]
    assert spectrum.exponents == served["lyapunov"]["exponents"] and len(spectrum.exponents) == 2
    assert spectrum.expected_zero[0].reason == served["lyapunov"]["expected_zero"][0]["reason"]
    assert section.to_dict() == served["poincare"] and spectrum.to_dict() == served["lyapunov"]
    page = api_module("ensembles", "ensembles_members").sync(ensemble_id, client=api)
    assert all(isinstance(m.poincare, SectionResult) and isinstance(m.lyapunov, SpectrumResult)
               for m in page.members)
    entry = api_module("systems", "systems_get").sync("generalized_chaplygin", client=api)
    assert isinstance(entry, model("catalog_generalized_chaplygin", "CatalogGeneralizedChaplygin"))
    assert entry.kind == "generalized_chaplygin" and entry.to_dict() == client.get(
        "/v1/systems/generalized_chaplygin").json()
    entry = api_module("systems", "systems_get").sync("lagrangian", client=api)
    assert isinstance(entry, model("catalog_lagrangian", "CatalogLagrangian"))
    assert entry.kind == "lagrangian" and entry.to_dict() == client.get("/v1/systems/lagrangian").json()
    ball = api_module("systems", "systems_get").sync("chaplygin_ball", client=api)
    assert isinstance(ball, model("system_description", "SystemDescription"))
