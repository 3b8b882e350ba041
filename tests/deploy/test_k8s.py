"""The Kubernetes deployment (deploy/k8s) and its monitoring (deploy/monitoring), offline.

Every kustomization is rendered with ``kubectl kustomize``; each built-in object is validated against
Kubernetes' own schemas (kubernetes-validate, strict: an unknown field is an error) and the KEDA objects
against KEDA's CRD schemas (vendored in tests/deploy/schemas, closed the way ``kubectl apply``'s strict
field validation closes them). Then the wiring that a schema cannot see: the ScaledObject scales the
worker Deployment on the queue the workers consume, at their concurrency; the grace period outlasts the
soft shutdown; API, workers and the migrations Job read the same settings, each a real setting; the
probes ask for routes the app serves; the KEDA query counts what it should in a migrated store; the alert
rules and the dashboard name only metrics the service exports (:data:`METRIC_CONTRACT`).
"""

from __future__ import annotations

import base64
import copy
import functools
import json
import os
import re
import shutil
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import yaml

from schemas.settings import Settings
from tests.support import ROOT, TEST_DATABASE_URL, drop_database, fresh_database_url

K8S = ROOT / "deploy" / "k8s"
MONITORING = ROOT / "deploy" / "monitoring"
SCHEMAS = Path(__file__).parent / "schemas"
#: The Kubernetes version the objects are validated for (the oldest one still widely run, 2026).
K8S_VERSION = "1.30"
KUSTOMIZATIONS = sorted(p.parent.relative_to(K8S).as_posix() for p in K8S.rglob("kustomization.yaml"))
#: The example overlay (the only kustomization with a Secret, Redis and PostgreSQL).
EXAMPLE = "overlays/example"
WORKER, API, MIGRATE = "nonholonomic-worker", "nonholonomic-api", "nonholonomic-migrate"
SECRET = "nonholonomic-secrets"

#: The metrics the service exports, with their labels (the contract of issue 37): the API's GET /metrics,
#: then each worker's port. The alert rules and the dashboard may name these and no others.
METRIC_CONTRACT: dict[str, frozenset[str]] = {name: frozenset(labels) for name, labels in {
    "http_requests_total": ("handler", "method", "status"),
    "http_request_duration_seconds_bucket": ("handler", "method", "status", "le"),
    "nonholonomic_jobs_submitted_total": ("kind",),
    "nonholonomic_ensembles_submitted_total": ("kind",),
    "nonholonomic_jobs_cancelled_total": ("kind",),
    "nonholonomic_ensembles_cancelled_total": (),
    "nonholonomic_jobs": ("status",),
    "nonholonomic_queue_depth": ("queue",),
    "nonholonomic_active_jobs": (),
    "nonholonomic_admission_refusals_total": ("reason",),
    "nonholonomic_symbolic_pool_busy": (),
    "nonholonomic_symbolic_pool_waiting": (),
    "nonholonomic_symbolic_pool_size": (),
    "nonholonomic_workers_alive": (),
    "nonholonomic_task_duration_seconds_bucket": ("task", "status", "le"),
    "nonholonomic_tasks_total": ("task", "status"),
    "nonholonomic_task_redeliveries_total": ("task", "source"),
    "nonholonomic_jobs_finished_total": ("kind", "status"),
    "nonholonomic_members_finished_total": ("status",),
    "nonholonomic_integrations_total": (),
    "nonholonomic_crossings_total": (),
    "nonholonomic_worker_resident_memory_bytes": ("pid",),
}.items()}
#: Labels Prometheus adds to every scraped series (target labels), usable with any metric.
TARGET_LABELS = frozenset({"job", "instance", "namespace", "pod", "container", "service", "endpoint"})
#: Environment names the deployment may set that are not ``NONHOLONOMIC_*`` settings, and who reads them.
OTHER_NAMES = {
    "PROMETHEUS_MULTIPROC_DIR": "prometheus-client (the workers' multiprocess metrics)",
    "REMAP_SIGTERM": "Celery/billiard (SIGTERM as SIGQUIT: the soft shutdown)",
    "MPLCONFIGDIR": "matplotlib (its cache, on the writable /tmp)",
    "REDIS_ADDRESS": "KEDA's redis trigger",
    "REDIS_PASSWORD": "KEDA's redis trigger, the example's Redis",
    "POSTGRES_CONNECTION": "KEDA's postgresql trigger",
    "POSTGRES_PASSWORD": "the example's PostgreSQL",
}
#: What kubectl 1.20's kustomize (v2.0.3, Debian bookworm's kubernetes-client) reads in a kustomization.
KUSTOMIZE_V2_FIELDS = frozenset({
    "apiVersion", "kind", "resources", "bases", "namespace", "namePrefix", "nameSuffix", "commonLabels",
    "commonAnnotations", "images", "configMapGenerator", "secretGenerator", "generatorOptions",
    "patchesStrategicMerge", "patchesJson6902", "vars", "crds", "configurations"})


# -- rendering -------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=1)
def _kubectl() -> str | None:
    """kubectl, installed from Debian's ``kubernetes-client`` when missing and we may (root, apt-get)."""
    found = shutil.which("kubectl")
    if found or shutil.which("apt-get") is None or os.geteuid() != 0:
        return found
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    for command in (["apt-get", "install", "-y", "-qq", "kubernetes-client"], ["apt-get", "update", "-qq"],
                    ["apt-get", "install", "-y", "-qq", "kubernetes-client"]):
        subprocess.run(command, env=env, check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       timeout=600)
        if found := shutil.which("kubectl"):
            return found
    return None


@functools.cache
def _rendered(kustomization: str) -> tuple[dict[str, Any], ...]:
    kubectl = _kubectl()
    if kubectl is None:
        pytest.skip("no kubectl, and Debian's kubernetes-client cannot be installed here (not root, no apt-get, "
                    "or apt-get failed): `kubectl kustomize` renders the deployment")
    done = subprocess.run([kubectl, "kustomize", str(K8S / kustomization)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, f"kubectl kustomize {kustomization} failed:\n{done.stderr}"
    return tuple(d for d in yaml.safe_load_all(done.stdout) if d)


def _objects(kustomization: str, kind: str | None = None) -> list[dict[str, Any]]:
    return [copy.deepcopy(o) for o in _rendered(kustomization) if kind is None or o["kind"] == kind]


def _one(kustomization: str, kind: str, name: str) -> dict[str, Any]:
    found = [o for o in _objects(kustomization, kind) if o["metadata"]["name"] == name]
    assert len(found) == 1, f"{kustomization}: {len(found)} {kind} named {name}"
    return found[0]


def _pod_specs(kustomization: str) -> Iterator[tuple[dict[str, Any], dict[str, Any]]]:
    """(object, pod spec) of each workload."""
    for o in _rendered(kustomization):
        if o["kind"] in ("Deployment", "StatefulSet", "DaemonSet", "Job"):
            yield o, o["spec"]["template"]["spec"]


def _container(kustomization: str, kind: str, name: str) -> dict[str, Any]:
    containers = _one(kustomization, kind, name)["spec"]["template"]["spec"]["containers"]
    assert len(containers) == 1
    return containers[0]


def _config_map(kustomization: str) -> dict[str, str]:
    """The shared settings' ConfigMap (its name has kustomize's hash)."""
    found = [o for o in _objects(kustomization, "ConfigMap")
             if o["metadata"]["name"].startswith("nonholonomic-settings")]
    assert len(found) == 1
    return dict(found[0]["data"])


def _env(container: dict[str, Any]) -> dict[str, str]:
    return {e["name"]: e.get("value", "") for e in container.get("env", [])}


def _concurrency(kustomization: str) -> int:
    command = _container(kustomization, "Deployment", WORKER)["command"]
    return int(command[command.index("--concurrency") + 1])


def _triggers(kustomization: str) -> dict[str, dict[str, Any]]:
    return {t["type"]: t for t in _one(kustomization, "ScaledObject", WORKER)["spec"]["triggers"]}


# -- schemas ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_every_kustomization_renders_with_names_and_kinds(kustomization):
    objects = _rendered(kustomization)
    assert objects
    for o in objects:
        assert o.get("apiVersion") and o.get("kind") and o.get("metadata", {}).get("name"), o
    assert not [o for o in objects if o["kind"] == "HorizontalPodAutoscaler"], "KEDA makes the HPA; none beside it"


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_built_in_objects_are_valid_kubernetes(kustomization):
    import kubernetes_validate

    errors = []
    for o in _rendered(kustomization):
        if o["apiVersion"].startswith("keda.sh/"):
            continue
        try:
            kubernetes_validate.validate(o, K8S_VERSION, strict=True)
        except kubernetes_validate.ValidationError as exc:
            errors.append(f"{o['kind']}/{o['metadata']['name']}: {exc.message} at {'.'.join(map(str, exc.path))}")
        except kubernetes_validate.SchemaNotFoundError:
            errors.append(f"{o['kind']}/{o['metadata']['name']}: not a kind of Kubernetes {K8S_VERSION}")
    assert not errors, "\n".join(errors)


def _closed(schema: Any) -> Any:
    """The schema with every object of declared properties closed to others: the API server prunes unknown
    fields and ``kubectl apply`` (strict field validation, the default since 1.27) refuses them."""
    if isinstance(schema, list):
        return [_closed(s) for s in schema]
    if not isinstance(schema, dict):
        return schema
    closed = {k: _closed(v) for k, v in schema.items()}
    if "properties" in closed and "additionalProperties" not in closed \
            and not closed.get("x-kubernetes-preserve-unknown-fields"):
        closed["additionalProperties"] = False
    return closed


@functools.cache
def _keda_validator(kind: str) -> jsonschema.protocols.Validator:
    file = {"ScaledObject": "keda.sh_scaledobjects.v1alpha1.json",
            "TriggerAuthentication": "keda.sh_triggerauthentications.v1alpha1.json"}[kind]
    schema = _closed(json.loads((SCHEMAS / file).read_text()))
    jsonschema.Draft7Validator.check_schema(schema)
    return jsonschema.Draft7Validator(schema)


def _keda_errors(o: dict[str, Any]) -> list[str]:
    return [f"{'.'.join(map(str, e.path))}: {e.message}" for e in _keda_validator(o["kind"]).iter_errors(o)]


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_keda_objects_match_keda_s_crd_schemas(kustomization):
    keda = [o for o in _rendered(kustomization) if o["apiVersion"].startswith("keda.sh/")]
    assert sorted(o["kind"] for o in keda) == ["ScaledObject", "TriggerAuthentication", "TriggerAuthentication"]
    for o in keda:
        assert o["apiVersion"] == "keda.sh/v1alpha1"
        assert not _keda_errors(o), f"{o['kind']}/{o['metadata']['name']}: {_keda_errors(o)}"


def test_the_keda_schemas_catch_what_a_cluster_would_refuse():
    """The validation is not vacuous: a misspelled field and a number where KEDA wants a string fail."""
    scaled = _one("base", "ScaledObject", WORKER)
    typo = copy.deepcopy(scaled)
    typo["spec"]["minReplicas"] = typo["spec"].pop("minReplicaCount")
    assert any("minReplicas" in e for e in _keda_errors(typo))
    number = copy.deepcopy(scaled)
    number["spec"]["triggers"][0]["metadata"]["listLength"] = 2
    assert _keda_errors(number)
    auth = copy.deepcopy(_objects("base", "TriggerAuthentication")[0])
    del auth["spec"]["secretTargetRef"][0]["key"]
    assert _keda_errors(auth)


def test_kustomizations_stay_readable_by_kubectl_1_20():
    """Debian's kubectl (1.20, kustomize v2.0.3) is what a fresh machine gets: no fields it does not know,
    directories only under ``bases``, generators from ``env`` files."""
    for kustomization in KUSTOMIZATIONS:
        folder = K8S / kustomization
        spec = yaml.safe_load((folder / "kustomization.yaml").read_text())
        assert set(spec) <= KUSTOMIZE_V2_FIELDS, f"{kustomization}: {set(spec) - KUSTOMIZE_V2_FIELDS}"
        for resource in spec.get("resources", []):
            assert (folder / resource).is_file(), f"{kustomization}: {resource} is not a file (use bases)"
        for generator in spec.get("configMapGenerator", []) + spec.get("secretGenerator", []):
            assert set(generator) <= {"name", "behavior", "env", "files", "literals", "type"}, generator


# -- the wiring ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_the_scaled_object_scales_the_worker_deployment_on_its_queue(kustomization):
    scaled = _one(kustomization, "ScaledObject", WORKER)["spec"]
    target = scaled["scaleTargetRef"]
    assert (target.get("apiVersion", "apps/v1"), target.get("kind", "Deployment")) == ("apps/v1", "Deployment")
    worker = _one(kustomization, "Deployment", target["name"])
    assert "replicas" not in worker["spec"], "KEDA owns the replicas: `kubectl apply` would reset them"
    assert scaled["minReplicaCount"] == 0 < scaled["maxReplicaCount"]
    queue = Settings.model_fields["queue"].default
    assert _config_map(kustomization)["NONHOLONOMIC_QUEUE"] == queue
    command = _container(kustomization, "Deployment", WORKER)["command"]
    assert command[command.index("-Q") + 1] == queue
    concurrency = _concurrency(kustomization)
    triggers = _triggers(kustomization)
    assert set(triggers) == {"redis", "postgresql"}
    assert triggers["redis"]["metadata"]["listName"] == queue
    # Airflow's rule: pods = ceil((queued + running) / concurrency)
    assert int(triggers["redis"]["metadata"]["listLength"]) == concurrency
    assert int(triggers["postgresql"]["metadata"]["targetQueryValue"]) == concurrency
    auths = {o["metadata"]["name"]: o for o in _objects(kustomization, "TriggerAuthentication")}
    parameters = {"redis": {"address", "password"}, "postgresql": {"connection"}}
    for kind, trigger in triggers.items():
        auth = auths[trigger["authenticationRef"]["name"]]
        assert {r["parameter"] for r in auth["spec"]["secretTargetRef"]} == parameters[kind]
        assert {r["name"] for r in auth["spec"]["secretTargetRef"]} == {SECRET}


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_the_grace_period_outlasts_the_soft_shutdown_and_the_jobs(kustomization, monkeypatch):
    worker = _one(kustomization, "Deployment", WORKER)["spec"]["template"]["spec"]
    container = worker["containers"][0]
    env = _env(container)
    settings = _settings(monkeypatch, {**_config_map(kustomization), **env})
    soft = settings.worker_soft_shutdown_s
    assert env["REMAP_SIGTERM"] == "SIGQUIT", "without it SIGTERM is a warm shutdown, unbounded"
    assert container["command"][0] == "celery", "celery must be PID 1: Kubernetes signals only it"
    assert soft >= settings.job_time_limit_s, "a running job should end on its own before the cold shutdown"
    assert worker["terminationGracePeriodSeconds"] >= soft + 30, "margin for the cold shutdown's requeue"
    api = _one(kustomization, "Deployment", API)["spec"]["template"]["spec"]
    pre_stop = api["containers"][0]["lifecycle"]["preStop"]["exec"]["command"]
    assert api["terminationGracePeriodSeconds"] > float(pre_stop[-1]) + 10


def _settings(monkeypatch: pytest.MonkeyPatch, values: dict[str, str]) -> Settings:
    for name in list(os.environ):
        if name.startswith("NONHOLONOMIC_") or name in ("REDIS_URL", "DATABASE_URL"):
            monkeypatch.delenv(name)
    for name, value in values.items():
        monkeypatch.setenv(name, value)
    return Settings()


def _setting_names() -> set[str]:
    names = set()
    for name, field in Settings.model_fields.items():
        names.add(f"NONHOLONOMIC_{name.upper()}")
        alias = field.validation_alias
        choices = getattr(alias, "choices", [alias] if isinstance(alias, str) else [])
        names.update(str(c) for c in choices)
    return names


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_every_variable_is_a_real_setting_and_the_settings_hold(kustomization, monkeypatch):
    settings, known = _setting_names(), set(OTHER_NAMES)
    names = set(_config_map(kustomization))
    for o, pod in _pod_specs(kustomization):
        if not o["metadata"]["name"].startswith("nonholonomic"):
            continue  # the example's Redis and PostgreSQL read their images' variables
        for container in pod["containers"]:
            names |= set(_env(container))
    for secret in _objects(kustomization, "Secret"):
        names |= set(secret["data"])
    wrong = sorted(n for n in names if (n.startswith("NONHOLONOMIC_") and n not in settings)
                   or (not n.startswith("NONHOLONOMIC_") and n not in settings | known))
    assert not wrong, f"not settings of schemas/settings.py, nor read by anything known: {wrong}"
    # the values parse, and the time limits are what workers.celery_app requires
    worker_env = _env(_container(kustomization, "Deployment", WORKER))
    chosen = _settings(monkeypatch, {**_config_map(kustomization), **worker_env})
    assert chosen.job_soft_time_limit_s < chosen.job_time_limit_s < chosen.visibility_timeout_s


def test_the_config_map_holds_docker_compose_s_shared_settings():
    compose = yaml.safe_load((ROOT / "docker-compose.yml").read_text())["x-settings"]
    shared = {k: str(v) for k, v in compose.items() if k.startswith("NONHOLONOMIC_") and k != "NONHOLONOMIC_API_KEYS"}
    # the ConfigMap's, or for a worker's own setting the worker Deployment's env
    chosen = {**_env(_container("base", "Deployment", WORKER)), **_config_map("base")}
    config = {k: v for k, v in chosen.items() if k in _config_map("base") or k.startswith("NONHOLONOMIC_WORKER_")}
    assert {k: config.get(k) for k in shared} == shared
    assert not {"REDIS_URL", "DATABASE_URL", "NONHOLONOMIC_API_KEYS"} & set(chosen), "secrets go in the Secret"


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_api_workers_and_migrations_read_the_same_config_map_and_secret(kustomization):
    sources = {}
    for kind, name in (("Deployment", API), ("Deployment", WORKER), ("Job", MIGRATE)):
        container = _container(kustomization, kind, name)
        sources[name] = [(k, v["name"]) for e in container["envFrom"] for k, v in e.items()]
    assert len({tuple(s) for s in sources.values()}) == 1, sources
    config_maps = {o["metadata"]["name"] for o in _objects(kustomization, "ConfigMap")}
    for kind, name in sources[API]:
        assert kind in ("configMapRef", "secretRef")
        if kind == "configMapRef":
            assert name in config_maps, f"{name}: no such ConfigMap (kustomize's hash not followed?)"
        else:
            assert name == SECRET


def test_the_example_s_secret_has_every_key_its_readers_ask_for():
    secret = _one(EXAMPLE, "Secret", SECRET)
    keys = set(secret["data"])
    assert {"REDIS_URL", "DATABASE_URL", "NONHOLONOMIC_API_KEYS"} <= keys
    wanted = {r["key"] for o in _objects(EXAMPLE, "TriggerAuthentication") for r in o["spec"]["secretTargetRef"]}
    for _, pod in _pod_specs(EXAMPLE):
        for container in pod["containers"]:
            wanted |= {e["valueFrom"]["secretKeyRef"]["key"] for e in container.get("env", [])
                       if "secretKeyRef" in e.get("valueFrom", {})}
    assert wanted <= keys, wanted - keys
    values = {k: base64.b64decode(v).decode() for k, v in secret["data"].items()}
    chosen = Settings(redis_url=values["REDIS_URL"], database_url=values["DATABASE_URL"])
    assert not chosen.embedded and chosen.store_url == values["DATABASE_URL"]
    assert values["POSTGRES_CONNECTION"].startswith("postgresql://"), "KEDA (pgx) reads a libpq URL"
    # KEDA's keys say what the URLs say: the same Redis database and PostgreSQL database, user and password
    from urllib.parse import urlsplit

    redis_url, database_url = urlsplit(values["REDIS_URL"]), urlsplit(values["DATABASE_URL"])
    keda_pg = urlsplit(values["POSTGRES_CONNECTION"])
    assert values["REDIS_ADDRESS"] == f"{redis_url.hostname}:{redis_url.port}"
    assert values["REDIS_PASSWORD"] == redis_url.password
    assert _triggers(EXAMPLE)["redis"]["metadata"]["databaseIndex"] == redis_url.path.strip("/")
    same = ("hostname", "port", "username", "password", "path")
    assert [getattr(keda_pg, a) for a in same] == [getattr(database_url, a) for a in same]


def _app_serves(path: str) -> bool:
    from starlette.routing import Match

    from service.main import create_app

    app = _app(create_app)
    scope = {"type": "http", "method": "GET", "path": path, "root_path": "", "query_string": b"", "headers": []}
    return any(route.matches(scope)[0] == Match.FULL for route in app.routes)


@functools.lru_cache(maxsize=1)
def _app(create_app: Any) -> Any:
    return create_app()


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_probes_ask_for_routes_the_app_serves_on_named_ports(kustomization):
    container = _container(kustomization, "Deployment", API)
    assert container["command"] == ["uvicorn", "service.main:app", "--host", "0.0.0.0", "--port", "8000",
                                    "--timeout-keep-alive", "5", "--proxy-headers", "--forwarded-allow-ips", "*"]
    ports = {p["name"]: p["containerPort"] for p in container["ports"]}
    assert ports == {"http": 8000}
    probes = [container[p] for p in ("startupProbe", "readinessProbe", "livenessProbe")]
    assert not _app_serves("/no/such/route")  # the check can fail
    for probe in probes:
        assert probe["httpGet"]["port"] in ports
        assert _app_serves(probe["httpGet"]["path"]), probe
    # not /health: 503 while no worker is warm, and the workers scale to zero when idle
    assert all(p["httpGet"]["path"] == "/health/live" for p in probes)
    service = _one(kustomization, "Service", API)["spec"]
    labels = _one(kustomization, "Deployment", API)["spec"]["template"]["metadata"]["labels"]
    assert service["selector"].items() <= labels.items()
    assert [p["targetPort"] for p in service["ports"]] == ["http"]


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_the_worker_serves_its_metrics_where_prometheus_looks(kustomization, monkeypatch):
    deployment = _one(kustomization, "Deployment", WORKER)
    pod = deployment["spec"]["template"]
    container = pod["spec"]["containers"][0]
    env = _env(container)
    port = _settings(monkeypatch, env).worker_metrics_port
    assert port > 0
    assert {p["name"]: p["containerPort"] for p in container["ports"]} == {"metrics": port}
    assert pod["metadata"]["annotations"]["prometheus.io/port"] == str(port)
    service = _one(kustomization, "Service", "nonholonomic-worker-metrics")["spec"]
    assert service["clusterIP"] == "None" and [p["targetPort"] for p in service["ports"]] == ["metrics"]
    assert service["selector"].items() <= pod["metadata"]["labels"].items()
    mounts = {m["mountPath"]: m["name"] for m in container["volumeMounts"]}
    volumes = {v["name"]: v for v in pod["spec"]["volumes"]}
    assert "emptyDir" in volumes[mounts[env["PROMETHEUS_MULTIPROC_DIR"]]]
    api = _one(kustomization, "Deployment", API)["spec"]["template"]["metadata"]["annotations"]
    assert _app_serves(api["prometheus.io/path"]) and api["prometheus.io/port"] == "8000"


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_a_read_only_root_leaves_every_written_folder_on_a_volume(kustomization):
    written = {k: v for k, v in _config_map(kustomization).items() if k in ("NONHOLONOMIC_CACHE_DIR", "MPLCONFIGDIR")}
    assert written
    for o, pod in _pod_specs(kustomization):
        if not o["metadata"]["name"].startswith("nonholonomic"):
            continue
        assert pod["securityContext"]["runAsNonRoot"] is True and pod["securityContext"]["runAsUser"] > 0
        for container in pod["containers"]:
            assert container["securityContext"]["readOnlyRootFilesystem"] is True
            assert container["securityContext"]["allowPrivilegeEscalation"] is False
            mounts = [m["mountPath"] for m in container["volumeMounts"]]
            assert "/tmp" in mounts
            for path in [*written.values(), *(v for k, v in _env(container).items() if v.startswith("/"))]:
                assert any(path == m or path.startswith(m + "/") for m in mounts), (o["metadata"]["name"], path)
            assert container["resources"]["requests"] and container["resources"]["limits"]


def _mebibytes(quantity: str) -> float:
    units = {"Ki": 1 / 1024, "Mi": 1, "Gi": 1024, "Ti": 1024**2}
    number, unit = re.fullmatch(r"(\d+(?:\.\d+)?)([KMGT]i)", quantity).groups()  # type: ignore[union-attr]
    return float(number) * units[unit]


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_the_worker_s_memory_limit_holds_its_processes(kustomization, monkeypatch):
    """Each pool process up to ~1.5 GiB (LLVM compiling integrators; replaced past worker_max_memory_mib
    after a job), and the main process: the pod's limit is above what Celery's own recycling allows, so
    the OOM killer does not come first."""
    container = _container(kustomization, "Deployment", WORKER)
    settings = _settings(monkeypatch, {**_config_map(kustomization), **_env(container)})
    per_process = max(1536, settings.worker_max_memory_mib + 512)
    limit = _mebibytes(container["resources"]["limits"]["memory"])
    assert limit >= _concurrency(kustomization) * per_process + 512
    assert _mebibytes(container["resources"]["requests"]["memory"]) <= limit


@pytest.mark.parametrize("kustomization", KUSTOMIZATIONS)
def test_the_migrations_job_runs_store_migrate(kustomization):
    job = _one(kustomization, "Job", MIGRATE)["spec"]
    container = job["template"]["spec"]["containers"][0]
    assert container["command"] == ["python", "-m", "store.migrate"]
    assert job["template"]["spec"]["restartPolicy"] in ("OnFailure", "Never")
    assert container["image"] == _container(kustomization, "Deployment", API)["image"]


# -- the store: python -m store.migrate and KEDA's query -----------------------------------------------------


def _migrate(url: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NONHOLONOMIC_") and k != "REDIS_URL"}
    return subprocess.run([sys.executable, "-m", "store.migrate"], env={**env, "DATABASE_URL": url}, cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def _postgres_answers() -> bool:
    from sqlalchemy.engine import make_url

    url = make_url(TEST_DATABASE_URL)
    try:
        with socket.create_connection((url.host or "127.0.0.1", url.port or 5432), timeout=1):
            return True
    except OSError:
        return False


@pytest.fixture(params=["sqlite", "postgresql"])
def store_url(request, tmp_path) -> Iterator[str]:
    """A store not migrated yet: a new SQLite file, or a new PostgreSQL database (not created yet either:
    store.migrate creates it), dropped afterwards."""
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path / 'store' / 'jobs.sqlite3'}"
        return
    if not _postgres_answers():
        pytest.skip("no PostgreSQL at NONHOLONOMIC_TEST_DATABASE_URL (scripts/test.py starts one)")
    url = fresh_database_url()
    try:
        yield url
    finally:
        drop_database(url)


def test_store_migrate_brings_a_new_store_to_the_newest_revision(store_url):
    from alembic.config import Config
    from alembic.script import ScriptDirectory
    from sqlalchemy import create_engine, inspect, text

    done = _migrate(store_url)
    assert done.returncode == 0, done.stdout + done.stderr
    config = Config()
    config.set_main_option("script_location", str(ROOT / "store" / "migrations"))
    head = ScriptDirectory.from_config(config).get_current_head()
    engine = create_engine(store_url)
    try:
        assert "alembic_version" in inspect(engine).get_table_names()
        with engine.connect() as connection:
            assert connection.scalar(text("SELECT version_num FROM alembic_version")) == head
    finally:
        engine.dispose()
    assert head in done.stdout
    from store.migrate import main

    assert main(["--url", store_url]) == 0  # again: nothing to do


def test_store_migrate_fails_with_status_1_and_hides_the_password():
    done = _migrate("postgresql+psycopg://user:hunter2-secret@127.0.0.1:1/nothing")
    assert done.returncode == 1
    assert "hunter2-secret" not in done.stdout + done.stderr
    assert "Traceback" not in done.stderr


def test_keda_s_query_counts_queued_and_running_jobs_and_pending_chunks(store_url):
    """The postgresql trigger's query, run against a store that ``python -m store.migrate`` made: every
    table and column it names exists, and it counts what should keep a worker."""
    from sqlalchemy import create_engine, insert, text

    from store.migrate import migrate
    from store.models import EnsembleChunkRow, EnsembleRow, JobRow

    assert migrate(store_url, 3600) is not None  # as test_store_migrate_... checks the command itself
    query = _triggers("base")["postgresql"]["metadata"]["query"]
    engine = create_engine(store_url)
    try:
        with engine.begin() as connection:
            assert connection.scalar(text(query)) == 0
            stamp = {"created": 1.0, "created_at": "2026-01-01T00:00:00+00:00"}
            for i, status in enumerate(["queued", "queued", "running", "succeeded", "failed", "cancelled"]):
                connection.execute(insert(JobRow.__table__).values(id=f"j{i}", status=status, request={}, attempts=0,
                                                                   **stamp))
            for ensemble, cancelled in (("live", False), ("gone", True)):
                connection.execute(insert(EnsembleRow.__table__).values(id=ensemble, request={}, chunks=[[0, 1]] * 3,
                                                                        cancelled=cancelled, **stamp))
                for chunk, done in enumerate([False, False, True]):
                    connection.execute(insert(EnsembleChunkRow.__table__).values(
                        ensemble_id=ensemble, chunk=chunk, done=done, members_done=0, starts=0))
            # 3 active jobs + 2 pending chunks of the live ensemble (the cancelled one's keep no worker)
            assert connection.scalar(text(query)) == 5
    finally:
        engine.dispose()


# -- monitoring ------------------------------------------------------------------------------------------

_KEYWORDS = frozenset({"and", "or", "unless", "by", "without", "on", "ignoring", "group_left", "group_right",
                       "offset", "bool", "inf", "nan"})


def _promql_selectors(expr: str) -> list[tuple[str, set[str]]]:
    """The metric names of a PromQL expression, each with the label names its matchers use."""
    expr = re.sub(r'"(?:[^"\\]|\\.)*"', '""', expr)  # strings (label values) out of the way
    found = [(m[1], set(re.findall(r"([A-Za-z_]\w*)\s*(?:=~|!~|!=|=)", m[2])))
             for m in re.finditer(r"([A-Za-z_:][\w:]*)\s*\{([^}]*)\}", expr)]
    bare = re.sub(r"\{[^}]*\}|\[[^\]]*\]", " ", expr)
    bare = re.sub(r"\b(?:by|without|on|ignoring|group_left|group_right)\s*\([^)]*\)", " ", bare)
    for m in re.finditer(r"(?<![\w:.$])([A-Za-z_:][\w:]*)(\s*\()?", bare):
        if m[2] is None and m[1] not in _KEYWORDS:
            found.append((m[1], set()))
    return found


def _contract_errors(where: str, expr: str) -> list[str]:
    errors = []
    selectors = _promql_selectors(expr)
    if not selectors:
        errors.append(f"{where}: names no metric: {expr}")
    for name, labels in selectors:
        if name not in METRIC_CONTRACT:
            errors.append(f"{where}: {name} is not a metric the service exports")
        elif labels - METRIC_CONTRACT[name] - TARGET_LABELS:
            errors.append(f"{where}: {name} has no label {sorted(labels - METRIC_CONTRACT[name] - TARGET_LABELS)}")
    return errors


def test_the_promql_reader_finds_metrics_and_labels():
    found = _promql_selectors('histogram_quantile(0.95, sum by (handler, le) (rate(http_request_duration_seconds_'
                              'bucket{handler!~"/health|/metrics"}[5m]))) > 2.5 and on() max(up_not) == 0')
    assert {name for name, _ in found} == {"http_request_duration_seconds_bucket", "up_not"}
    assert ("http_request_duration_seconds_bucket", {"handler"}) in found
    assert _contract_errors("x", 'sum(rate(http_requests_total{code="500"}[5m]))')
    assert _contract_errors("x", "rate(nonholonomic_task_total[5m])")


def _rules() -> list[dict[str, Any]]:
    groups = yaml.safe_load((MONITORING / "prometheus-rules.yaml").read_text())["groups"]
    assert groups and all(g["name"] and g["rules"] for g in groups)
    return [rule for group in groups for rule in group["rules"]]


def test_alert_rules_are_complete_and_name_only_exported_metrics():
    rules = _rules()
    names = [r["alert"] for r in rules]
    assert len(names) == len(set(names))
    errors = []
    for rule in rules:
        assert set(rule) <= {"alert", "expr", "for", "labels", "annotations", "keep_firing_for"}, rule["alert"]
        assert re.fullmatch(r"\d+[smh]", rule["for"]), rule["alert"]
        assert rule["labels"]["severity"] in ("critical", "warning", "info"), rule["alert"]
        assert rule["annotations"]["summary"].strip(), rule["alert"]
        errors += _contract_errors(rule["alert"], rule["expr"])
    assert not errors, "\n".join(errors)
    # celery-exporter's three: failure rate over 10 min, queue > 100 for 20 min, a worker gone 15 min
    by_name = {r["alert"]: r for r in rules}
    assert "[10m]" in by_name["NonholonomicTaskFailureRateHigh"]["expr"]
    assert "> 0.05" in by_name["NonholonomicTaskFailureRateHigh"]["expr"]
    queue = by_name["NonholonomicQueueLengthHigh"]
    assert queue["for"] == "20m" and "> 100" in queue["expr"]
    assert by_name["NonholonomicNoWorkerForWaitingWork"]["for"] == "15m"


def test_the_workers_short_alert_knows_the_scaled_object():
    """Its constants are the worker's concurrency and KEDA's maxReplicaCount (else it fires at the maximum,
    or never)."""
    expr = {r["alert"]: r for r in _rules()}["NonholonomicWorkersShort"]["expr"]
    assert int(re.search(r"(\d+) \* max\(nonholonomic_workers_alive\)", expr)[1]) == _concurrency("base")  # type: ignore[index]
    maximum = _one("base", "ScaledObject", WORKER)["spec"]["maxReplicaCount"]
    assert int(re.search(r"max\(nonholonomic_workers_alive\) < (\d+)", expr)[1]) == maximum  # type: ignore[index]


@pytest.mark.skipif(shutil.which("promtool") is None, reason="no promtool here (Debian's prometheus package)")
def test_promtool_accepts_the_rules():
    done = subprocess.run(["promtool", "check", "rules", str(MONITORING / "prometheus-rules.yaml")],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr


def _panels(dashboard: dict[str, Any]) -> Iterator[dict[str, Any]]:
    for panel in dashboard["panels"]:
        yield panel
        yield from panel.get("panels", [])


def test_the_dashboard_reads_prometheus_through_its_input_and_covers_the_contract():
    dashboard = json.loads((MONITORING / "grafana-dashboard.json").read_text())
    assert [i["name"] for i in dashboard["__inputs"]] == ["DS_PROMETHEUS"]
    assert dashboard["__inputs"][0]["pluginId"] == "prometheus"
    ids = [p["id"] for p in _panels(dashboard)]
    assert len(ids) == len(set(ids))
    errors, used = [], set()
    for panel in _panels(dashboard):
        if panel["type"] == "row":
            continue
        assert panel["datasource"]["uid"] == "${DS_PROMETHEUS}", panel["title"]
        assert panel["targets"], panel["title"]
        for target in panel["targets"]:
            assert target.get("datasource", panel["datasource"])["uid"] == "${DS_PROMETHEUS}", panel["title"]
            errors += _contract_errors(panel["title"], target["expr"])
            used |= {name for name, _ in _promql_selectors(target["expr"])}
    assert not errors, "\n".join(errors)
    assert not set(METRIC_CONTRACT) - used, f"exported but on no panel: {sorted(set(METRIC_CONTRACT) - used)}"
