#!/usr/bin/env python3
"""Quick start, command 2: install into .venv (with the test extra), make sure Redis answers on
127.0.0.1:6379 (starting ``redis-server``, installing Debian's package if it is missing), that
PostgreSQL answers on 127.0.0.1:5432 (starting a cluster of the tests' own if not) and that a
headless Chromium is there for the page tests (installing Debian's ``chromium`` if it is missing)
and nginx for the slow-client tests (Debian's ``nginx-light``); check the code with ruff and mypy
(as configured in pyproject.toml; mypy runs beside the tests, and a finding fails the command as a
failed test does); then run the whole test suite in parallel (pytest-xdist: ``NONHOLONOMIC_TEST_WORKERS``
processes, default 3, each taking whole files so that a module's server is started once). Extra arguments
go to pytest (e.g. ``-k measure``; ``-n 0`` runs in one process). Screenshots and other artefacts of the
run go to ``test-output/``."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _bootstrap import PYTHON, ROOT, apt_install, compile_bytecode, ensure_installed, say

REDIS_HOST, REDIS_PORT = "127.0.0.1", 6379
PG_HOST, PG_PORT = "127.0.0.1", 5432
#: Where the page tests look for the browser (Debian's package); NONHOLONOMIC_CHROMIUM overrides it.
CHROMIUM = "/usr/bin/chromium"
#: The project's packages, compiled to bytecode once before the run (see :func:`compile_once`).
PACKAGES = ("nonholonomic", "schemas", "service", "store", "workers", "client")


def redis_answers() -> bool:
    try:
        with socket.create_connection((REDIS_HOST, REDIS_PORT), timeout=1) as s:
            s.sendall(b"PING\r\n")
            return s.recv(16).startswith(b"+PONG")
    except OSError:
        return False


def ensure_redis() -> None:
    if redis_answers():
        return
    if shutil.which("redis-server") is None and not apt_install("redis-server"):
        raise SystemExit("no Redis on 127.0.0.1:6379 and redis-server cannot be installed: install it and retry")
    say("starting redis-server on 127.0.0.1:6379")
    subprocess.run([shutil.which("redis-server") or "redis-server", "--daemonize", "yes", "--bind", REDIS_HOST,
                    "--port", str(REDIS_PORT), "--save", "", "--appendonly", "no"], check=True)
    for _ in range(50):
        if redis_answers():
            return
        time.sleep(0.1)
    raise SystemExit("redis-server started but does not answer PING on 127.0.0.1:6379")


def postgres_answers() -> bool:
    try:
        with socket.create_connection((PG_HOST, PG_PORT), timeout=1):
            return True
    except OSError:
        return False


def _postgres_bin() -> Path | None:
    found = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"), key=lambda p: int(p.parent.parent.name))
    return found[-1].parent if found else None


def ensure_postgres() -> None:
    """PostgreSQL on 127.0.0.1:5432, queue mode's job store: the machine's, else a cluster of the tests'
    own (trust authentication, user postgres) in /var/tmp, with Debian's binaries (installed if missing)."""
    if postgres_answers():
        return
    bindir = _postgres_bin()
    if bindir is None and not (apt_install("postgresql") and (bindir := _postgres_bin())):
        raise SystemExit("no PostgreSQL on 127.0.0.1:5432 and Debian's postgresql cannot be installed: install it "
                         "and retry")
    data = Path(os.environ.get("NONHOLONOMIC_TEST_PGDATA", "/var/tmp/nonholonomic-postgres"))
    as_postgres = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
    if not (data / "PG_VERSION").exists():
        data.mkdir(parents=True, exist_ok=True)
        if as_postgres:
            shutil.chown(data, "postgres", "postgres")
        say(f"creating a PostgreSQL cluster in {data}")
        subprocess.run([*as_postgres, str(bindir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres"],
                       check=True, stdout=subprocess.DEVNULL)
    say("starting PostgreSQL on 127.0.0.1:5432")
    subprocess.run([*as_postgres, str(bindir / "pg_ctl"), "-D", str(data), "-l", str(data / "server.log"), "-w",
                    "-o", f"-p {PG_PORT} -k /tmp -c listen_addresses={PG_HOST}", "start"], check=True)
    for _ in range(100):
        if postgres_answers():
            return
        time.sleep(0.1)
    raise SystemExit("PostgreSQL started but does not answer on 127.0.0.1:5432")


def ensure_chromium() -> str:
    """The headless browser of the page tests (Playwright drives it; no browser download)."""
    browser = os.environ.get("NONHOLONOMIC_CHROMIUM", CHROMIUM)
    if os.path.exists(browser):
        return browser
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if found:
        return found
    if apt_install("chromium") and os.path.exists(CHROMIUM):
        return CHROMIUM
    raise SystemExit(f"no Chromium at {browser} and Debian's chromium cannot be installed: install it (or set "
                     "NONHOLONOMIC_CHROMIUM to a Chromium binary) and retry")


def ensure_nginx() -> dict[str, str]:
    """The deployment's front door (deploy/nginx.conf), for the slow-client tests: Debian's
    ``nginx-light`` installed if missing; required when it could be installed."""
    if shutil.which("nginx") or os.path.exists("/usr/sbin/nginx") or apt_install("nginx-light"):
        return {"NONHOLONOMIC_REQUIRE_NGINX": "1"}
    say("no nginx (not root, or apt-get failed): the slow-client tests are skipped")
    return {}


def ensure_kubectl() -> None:
    """``kubectl kustomize`` for the Kubernetes deployment's tests (tests/deploy): Debian's
    ``kubernetes-client`` installed if missing; without it those tests are skipped, saying why."""
    if shutil.which("kubectl") is None and not apt_install("kubernetes-client"):
        say("no kubectl (not root, or apt-get failed): the Kubernetes deployment's tests are skipped")


def ensure_promtool() -> dict[str, str]:
    """``promtool check rules`` for the alert rules (tests/deploy): the binary out of Debian's ``prometheus``
    package, unpacked into .venv/tools (``apt-get download`` + ``dpkg -x``: no Prometheus service is
    installed or started); returns the PATH that finds it (empty if it is on PATH or cannot be had)."""
    if shutil.which("promtool") is not None:
        return {}
    tools = ROOT / ".venv" / "tools" / "prometheus"
    binary = tools / "usr" / "bin" / "promtool"
    if not binary.exists() and shutil.which("apt-get") and shutil.which("dpkg"):
        with tempfile.TemporaryDirectory() as folder:
            download = ["apt-get", "download", "-qq", "prometheus"]  # as root: apt warns it runs unsandboxed
            if subprocess.run(download, cwd=folder, check=False, stderr=subprocess.DEVNULL).returncode:
                subprocess.run(["apt-get", "update", "-qq"], check=False)
                subprocess.run(download, cwd=folder, check=False, stderr=subprocess.DEVNULL)
            for deb in Path(folder).glob("prometheus_*.deb"):
                tools.mkdir(parents=True, exist_ok=True)
                subprocess.run(["dpkg", "-x", str(deb), str(tools)], check=False)
        (binary.parent / "prometheus").unlink(missing_ok=True)  # only promtool is used (48 MB of 96)
    if not binary.exists():
        say("no promtool (apt-get download prometheus failed): the alert rules' promtool check is skipped")
        return {}
    return {"PATH": f"{binary.parent}{os.pathsep}{os.environ.get('PATH', '')}"}


def main(argv: list[str]) -> int:
    ensure_installed("test")
    lint = subprocess.run([str(PYTHON), "-m", "ruff", "check", "--quiet", "."], cwd=ROOT).returncode
    typing = TypeCheck()  # beside the service starts and the tests: about 20 s of one core when cold
    ensure_redis()
    ensure_postgres()
    ensure_kubectl()
    env = {**os.environ, **ensure_nginx(), **ensure_promtool(), "NONHOLONOMIC_CHROMIUM": ensure_chromium(),
           "NONHOLONOMIC_REQUIRE_BROWSER": "1",
           "NONHOLONOMIC_TEST_OUTPUT": os.environ.get("NONHOLONOMIC_TEST_OUTPUT", str(ROOT / "test-output"))}
    os.chdir(ROOT)
    compile_once(env)
    tests = subprocess.run([str(PYTHON), "-m", "pytest", *parallel(argv), *argv], env=env).returncode
    checked = typing.result()
    say(f"ruff: {'clean' if lint == 0 else 'findings above'}; mypy: {'clean' if checked == 0 else 'findings above'}")
    return tests or lint or checked


class TypeCheck:
    """mypy over the configured packages (``[tool.mypy]``) in a process of its own; its output is shown
    when the tests are done (a finding fails the command, as a failed test does)."""

    def __init__(self) -> None:
        self._out = tempfile.TemporaryFile(mode="w+")
        self._process = subprocess.Popen([str(PYTHON), "-m", "mypy"], cwd=ROOT, stdout=self._out,
                                         stderr=subprocess.STDOUT)

    def result(self) -> int:
        code = self._process.wait()
        if code != 0:
            self._out.seek(0)
            print(self._out.read(), flush=True)
        self._out.close()
        return code


def compile_once(env: dict[str, str]) -> None:
    """Compile the project's modules to ``__pycache__`` once, on every core, and let the run keep the
    bytecode it makes: the suite starts about 100 Python processes (APIs, workers, pytest's), and where
    ``PYTHONDONTWRITEBYTECODE`` is set (as on the 2-core machines this project is developed on) each
    compiled every module of the project, and pytest each test module, again."""
    compile_bytecode(PYTHON, list(PACKAGES), cwd=ROOT)
    env.pop("PYTHONDONTWRITEBYTECODE", None)


def parallel(argv: list[str]) -> list[str]:
    """pytest-xdist's options unless the arguments choose their own: ``NONHOLONOMIC_TEST_WORKERS``
    processes (default 3 on 2 cores: the suite waits on servers and workers as much as it computes), a
    file per process at a time in the order tests/conftest.py gives (the two longest, then the files of
    most tests first; all the long files first, cold at once, took 13 min 55 s instead of 11 min 42 s, and
    4 processes 18 min 15 s against 16 min 11 s for 3 on the same day: more CPU, not less waiting; again on
    2026-11-29, 11 min 13 s against 10 min 10 s, and the waiting files spread among the others 10 min 46 s:
    docs/testing.md), and the 15 slowest tests listed."""
    if "no:xdist" in argv or any(a in ("-n", "--numprocesses", "--dist") or a.startswith(("-n", "--numprocesses="))
                                 for a in argv):
        return []
    workers = os.environ.get("NONHOLONOMIC_TEST_WORKERS", "3")
    return ["-n", workers, "--dist", "loadfile", "--no-loadscope-reorder", "--durations", "15"]


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
