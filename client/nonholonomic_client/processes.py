"""``nonholonomic serve`` and ``nonholonomic worker``: the command lines of the API and of a Celery worker.

Both replace the current process (``os.execve``) with the same Python interpreter running uvicorn or
Celery, so signals (Ctrl-C, SIGTERM from a supervisor) reach the server directly.
"""

from __future__ import annotations

import importlib.util
import os
import socket
import sys
from collections.abc import Mapping
from typing import NoReturn
from urllib.parse import urlsplit, urlunsplit

#: The Redis URL of queue mode when the environment gives none (the README's).
DEFAULT_REDIS_URL = "redis://127.0.0.1:6379/0"
#: The Celery queue when ``NONHOLONOMIC_QUEUE`` is not set.
DEFAULT_QUEUE = "nonholonomic"
_REDIS_VARS = ("REDIS_URL", "NONHOLONOMIC_REDIS_URL")


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on now (asked from the kernel).

    Parameters
    ----------
    host : str
        The address to bind to.

    Returns
    -------
    int
    """
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def redacted(url: str) -> str:
    """``url`` with its password replaced by ``***`` (for printing).

    Parameters
    ----------
    url : str

    Returns
    -------
    str
    """
    parts = urlsplit(url)
    if parts.password is None:
        return url
    netloc = parts.netloc.replace(f":{parts.password}@", ":***@", 1)
    return urlunsplit(parts._replace(netloc=netloc))


def serve_command(host: str, port: int, queue: bool,
                  environ: Mapping[str, str]) -> tuple[list[str], dict[str, str], str]:
    """The command, environment and banner of ``nonholonomic serve``.

    Parameters
    ----------
    host : str
        Address uvicorn binds to.
    port : int
        Its port; 0 picks a free one here, so the banner gives the real address.
    queue : bool
        Queue mode: keep (or default) ``REDIS_URL``; otherwise embedded mode with every Redis
        variable removed.
    environ : mapping
        The environment to start from.

    Returns
    -------
    argv : list of str
        ``[sys.executable, "-m", "uvicorn", "service.main:app", "--host", host, "--port", port]``.
    env : dict
        The server's environment.
    banner : str
        What to print: the address and the mode.
    """
    env = dict(environ)
    if queue:
        if not any(env.get(v) for v in _REDIS_VARS):
            env["REDIS_URL"] = DEFAULT_REDIS_URL
        url = env.get("REDIS_URL") or env["NONHOLONOMIC_REDIS_URL"]
        mode = f"queue mode: jobs go to Celery workers through {redacted(url)}"
    else:
        for v in _REDIS_VARS:
            env.pop(v, None)
        mode = "embedded mode: jobs run in this process, no Redis"
    if port == 0:
        port = free_port(host if host not in ("0.0.0.0", "::", "") else "127.0.0.1")
    shown = "127.0.0.1" if host in ("0.0.0.0", "") else "[::1]" if host == "::" else host
    address = f"http://{shown}:{port}"
    everywhere = f" (listening on {host})" if shown != host else ""
    banner = f"nonholonomic API on {address}{everywhere}, docs at {address}/docs; {mode}"
    argv = [sys.executable, "-m", "uvicorn", "service.main:app", "--host", host, "--port", str(port)]
    return argv, env, banner


def worker_command(concurrency: int | None, environ: Mapping[str, str]) -> tuple[list[str], dict[str, str], str]:
    """The command, environment and banner of ``nonholonomic worker``.

    Parameters
    ----------
    concurrency : int, optional
        Worker processes (Celery's default, the number of cores, when None).
    environ : mapping
        The environment to start from; ``NONHOLONOMIC_QUEUE`` names the queue (default
        ``nonholonomic``), ``REDIS_URL`` the broker (default ``redis://127.0.0.1:6379/0``).

    Returns
    -------
    argv : list of str
    env : dict
    banner : str
    """
    env = dict(environ)
    if not any(env.get(v) for v in _REDIS_VARS):
        env["REDIS_URL"] = DEFAULT_REDIS_URL
    url = env.get("REDIS_URL") or env["NONHOLONOMIC_REDIS_URL"]
    queue = env.get("NONHOLONOMIC_QUEUE") or DEFAULT_QUEUE
    argv = [sys.executable, "-m", "celery", "-A", "workers.celery_app:app", "worker", "-Q", queue,
            "--loglevel", "INFO"]
    if concurrency is not None:
        argv += ["--concurrency", str(concurrency)]
    return argv, env, f"nonholonomic worker on queue {queue!r} through {redacted(url)}"


#: The modules ``serve`` and ``worker`` need: the server's install, not the client's alone.
SERVER_MODULES = {"uvicorn": ("service", "uvicorn"), "celery": ("workers", "celery")}


def missing_server(argv: list[str]) -> str | None:
    """Why ``argv`` (a ``serve`` or ``worker`` command) cannot run here, or None if it can.

    Parameters
    ----------
    argv : list of str
        From :func:`serve_command` or :func:`worker_command`.

    Returns
    -------
    str or None
        A message naming the missing modules and the install that brings them.
    """
    needed = SERVER_MODULES.get(argv[2] if len(argv) > 2 else "", ())
    missing = [m for m in needed if importlib.util.find_spec(m) is None]
    if not missing:
        return None
    return (f"this command needs the server, which is not installed here (no module {', '.join(missing)}): "
            "install it from a checkout with `pip install -e .` (or `python3 scripts/serve.py`); "
            "the client alone (nonholonomic-client) talks to a running API")


def execute(argv: list[str], env: dict[str, str], banner: str) -> NoReturn:
    """Print ``banner`` and replace this process with ``argv``.

    Parameters
    ----------
    argv : list of str
    env : dict
    banner : str

    Raises
    ------
    SystemExit
        With a message (exit code 2) when the server is not installed.
    """
    reason = missing_server(argv)
    if reason is not None:
        print(f"nonholonomic: {reason}", file=sys.stderr)
        raise SystemExit(2)
    print(banner, flush=True)
    sys.stderr.flush()
    os.execve(argv[0], argv, env)
