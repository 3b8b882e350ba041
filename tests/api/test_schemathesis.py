"""Schemathesis over every operation of the app (embedded mode): no server error, every answer
conforms to the OpenAPI document (status code, content type, body schema), and a request the document
calls valid is not refused (``positive_data_acceptance``, schemathesis' ST202) except by the rules a
JSON Schema cannot state, listed per operation in :data:`SEMANTIC_422` with the reason. The document
is the one of an app with the test's limits: it states them (``maximum`` of ``t_final`` ...).

Bounded so that it runs in about a minute on two cores: small service limits (``t_final`` ≤ 100,
200 samples, 16 ensemble members) keep validation cheap; jobs and ensembles the cases submit are
accepted (202) but not run (the embedded backend's runners are stubbed: integrating fuzzed systems
tests the integrators, not the API, and their kernel compilation cannot be interrupted); the symbolic
requests' work limits are capped at a tenth of the defaults (deterministic: the same case, the same
answer); the symbolic routes and the paper report get fewer examples. Cases that name a job or an
ensemble run twice: with the generated id (404) and with the id of a real finished one (a ball job
with a section and exponents, an ensemble, a one-claim paper report), so the success answers are
checked too.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest
import schemathesis
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    positive_data_acceptance,
    response_schema_conformance,
    status_code_conformance,
)

from nonholonomic.numerics.integration import IntegrationCancelled
from schemas.settings import Settings, get_settings
from service.backends import embedded
from service.main import create_app

CHECKS = [not_a_server_error, status_code_conformance, content_type_conformance, response_schema_conformance,
          positive_data_acceptance]
LIMITS = {"NONHOLONOMIC_MAX_T_FINAL": "100", "NONHOLONOMIC_MAX_SAMPLES": "200",
          "NONHOLONOMIC_MAX_SECTION_POINTS": "100", "NONHOLONOMIC_MAX_ENSEMBLE_MEMBERS": "16",
          "NONHOLONOMIC_MAX_ENSEMBLE_VALUES": "400", "NONHOLONOMIC_MAX_ENSEMBLE_SECTION_POINTS": "1000"}
#: Operations that may refuse a schema-valid request with 422 (positive_data_acceptance), and why no
#: JSON Schema of theirs can say it. Everywhere else a schema-valid request must be accepted.
SEMANTIC_422 = {
    "jobs-list": "the cursor is opaque: only a page's next_cursor is one",
    "ensembles-list": "the cursor is opaque: only a page's next_cursor is one",
    "jobs-submit": "physics across fields: the initial state on the constraint manifold, a potential's "
                   "expression and the claims' expressions must parse and be finite at the start",
    "ensembles-submit": "as jobs-submit, and members x samples and members x max_points are bounded together",
    "maps-apply": "the states must satisfy the system's constraints; expression potentials must parse",
    "symbolic-hamiltonize": "expressions must parse and be consistent (names, dimensions)",
    "symbolic-brackets-verify": "expressions must parse; the matrix must be square in the variables",
    "paper-report-submit": "claim ids are the catalog's (GET /v1/paper/claims); the schema has no enum of them yet",
    "explore-plane": "the section's components and level must be the system's, and fix finitely many states",
    "explore-orbit": "as explore-plane, and the point must lie inside the level (a state crosses there)",
    "explore-periodic-orbit": "as explore-orbit",
    "jobs-plot": "the trajectory's window (t_from, t_to) must lie within the job's own run, 0 <= t_from < t_to <= "
                 "t_final",
    "jobs-page": "as jobs-plot",
}
#: The largest work limits of a fuzzed symbolic request (the schema allows up to 10x the defaults; a tenth
#: of them keeps every case within seconds, and the safety cap's 503 out of the fuzz).
SYMBOLIC_LIMITS = {"max_proof_ops": 2000, "max_integrate_ops": 40, "max_tidy_ops": 400}
#: Fewer examples for the expensive operations (per operation id; fuzzing phase).
FEW = {"paper-report-submit": 4, "symbolic-hamiltonize": 10, "symbolic-brackets-verify": 10,
       "explore-periodic-orbit": 6}  # a valid one runs a Newton search in the request
MAX_EXAMPLES = 12

BALL_JOB = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
            "initial_state": {"M": [0.5, -0.2, 0.1], "gamma": [0.0, 0.6, 0.8]}, "t_final": 20.0, "samples": 21,
            "poincare": {"surface": "gamma3", "coordinates": ["gamma1", "gamma2"], "max_points": 20},
            "lyapunov": {"count": 2, "interval": 1.0}}
ENSEMBLE = {"system": {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7},
            "members": {"sample": {"count": 4, "seed": 1, "level": {"energy": 1.0, "area": 0.0}}},
            "t_final": 20.0, "samples": 2, "poincare": {"surface": "gamma3", "max_points": 20},
            "lyapunov": {"count": 1}}


def _config() -> schemathesis.Config:
    accepted = ["2xx", "3xx", "401", "403", "404", "409", "429", "5xx"]  # schemathesis' default
    return schemathesis.Config.from_dict({
        "generation": {"max-examples": MAX_EXAMPLES, "deterministic": True},
        "operations": [{"include-operation-id": op, "generation": {"max-examples": n}} for op, n in FEW.items()]
        + [{"include-operation-id": op,
            "checks": {"positive_data_acceptance": {"expected-statuses": [*accepted, "422"]}}}
           for op in SEMANTIC_422],
    })


def _settings() -> Settings:
    """The settings of the app under test (:data:`LIMITS`), for the document the cases come from."""
    return Settings.model_validate({name.removeprefix("NONHOLONOMIC_").lower(): value
                                    for name, value in LIMITS.items()})


class _WithoutLifespan:
    """The app as schemathesis calls it: HTTP goes to the app, lifespan events are answered here.

    Schemathesis' pytest plugin starts the app's lifespan on a test's first call and ends it after
    every test: each operation would get a new backend, without the module's finished work.
    """

    def __init__(self, app: Any) -> None:
        self.app = app

    async def __call__(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        if scope["type"] != "lifespan":
            await self.app(scope, receive, send)
            return
        while True:
            message = await receive()
            if message["type"] == "lifespan.startup":
                await send({"type": "lifespan.startup.complete"})
            elif message["type"] == "lifespan.shutdown":
                await send({"type": "lifespan.shutdown.complete"})
                return


def _not_run(*args: Any, **kwargs: Any) -> str:
    """Stands for the job and chunk runners of the embedded backend during the fuzz."""
    raise IntegrationCancelled("not run by the schemathesis test")


def _wait(client: TestClient, location: str, timeout: float = 120.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        view = client.get(location).json()
        if view["status"] in ("succeeded", "failed", "cancelled"):
            return view
        time.sleep(0.02)
    raise TimeoutError(location)


@pytest.fixture(scope="module")
def api() -> Iterator[dict[str, Any]]:
    """The app in embedded mode with small limits, its schema, and ids of finished work."""
    with pytest.MonkeyPatch.context() as mp:
        mp.delenv("REDIS_URL", raising=False)
        mp.delenv("NONHOLONOMIC_REDIS_URL", raising=False)
        mp.setenv("NONHOLONOMIC_WARM_UP", "false")
        for name, value in LIMITS.items():
            mp.setenv(name, value)
        get_settings.cache_clear()
        app = create_app()
        setup = TestClient(app)
        setup.__enter__()  # the lifespan: app.state.backend, for every test of the module
        try:
            # the catalog derives every definition on first use (~11 s on a loaded machine with an empty
            # memo): not within the fuzzed calls' read timeout
            assert setup.get("/v1/systems").status_code == 200
            locations = {"job": setup.post("/v1/jobs", json=BALL_JOB).headers["location"],
                         "ensemble": setup.post("/v1/ensembles", json=ENSEMBLE).headers["location"],
                         "report": setup.post("/v1/paper/report",
                                              json={"claims": ["veselova.multiplier"]}).headers["location"]}
            views = {name: _wait(setup, location) for name, location in locations.items()}
            assert {name: v["status"] for name, v in views.items()} == dict.fromkeys(views, "succeeded"), views
            # From here on, accepted jobs and ensemble chunks are not run: the fuzz checks the HTTP answers;
            # running its jobs would only compile kernels (not interruptible) on the two cores.
            mp.setattr(embedded, "run_job", _not_run)
            mp.setattr(embedded, "run_ensemble_chunk", _not_run)
            yield {"app": _WithoutLifespan(app), "job_id": views["job"]["id"], "ensemble_id": views["ensemble"]["id"],
                   "report_id": views["report"]["id"]}
        finally:
            setup.__exit__(None, None, None)
            get_settings.cache_clear()


#: The document as the app under test serves it (read at collection, with the same limits).
schema = schemathesis.openapi.from_dict(create_app(_settings()).openapi(), config=_config())


@schema.parametrize()
@settings(deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
def test_every_operation_conforms(case, api):
    if case.operation.path in ("/v1/brackets/verify", "/v1/hamiltonize") and isinstance(case.body, dict):
        limits = case.body.get("limits")
        given = limits if isinstance(limits, dict) else {}
        case.body["limits"] = {name: min(value, top) if isinstance(value, int) and not isinstance(value, bool) else top
                               for name, top in SYMBOLIC_LIMITS.items()
                               for value in [given.get(name, top)]}
    case.call_and_validate(app=api["app"], checks=CHECKS)
    real = {"job_id": api["report_id"] if case.operation.path.startswith("/v1/paper/") else api["job_id"],
            "ensemble_id": api["ensemble_id"]}
    names = set(case.path_parameters or {}) & set(real)
    if names:  # again with a real, finished job or ensemble
        case.path_parameters = {**case.path_parameters, **{n: real[n] for n in names}}
        case.call_and_validate(app=api["app"], checks=CHECKS)
