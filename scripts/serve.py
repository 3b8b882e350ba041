#!/usr/bin/env python3
"""Quick start, command 1: install into .venv and serve the API (default http://127.0.0.1:8000).

Embedded mode (jobs run in the API process, no Redis) unless ``--queue`` is given, which keeps
``REDIS_URL`` (default redis://127.0.0.1:6379/0) so jobs go to Celery workers.
``--host`` and ``--port`` (or the environment variables ``NONHOLONOMIC_HOST`` and
``NONHOLONOMIC_PORT``) choose the address; other arguments go to uvicorn (e.g. ``--workers 2``).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from _bootstrap import BIN, ROOT, ensure_installed, say


def parse(argv: list[str]) -> tuple[argparse.Namespace, list[str]]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument("--host", default=os.environ.get("NONHOLONOMIC_HOST", "127.0.0.1"),
                        help="address to listen on (env NONHOLONOMIC_HOST; default 127.0.0.1, 0.0.0.0 for every "
                             "interface)")
    parser.add_argument("--port", type=int, default=int(os.environ.get("NONHOLONOMIC_PORT", "8000")),
                        help="port (env NONHOLONOMIC_PORT; default 8000)")
    parser.add_argument("--queue", action="store_true",
                        help="queue mode: jobs go to Celery workers through REDIS_URL (default redis://127.0.0.1:6379/0)")
    return parser.parse_known_args(argv)


def main(argv: list[str]) -> None:
    args, rest = parse(argv)
    ensure_installed()
    env = dict(os.environ)
    if args.queue:
        env.setdefault("REDIS_URL", "redis://127.0.0.1:6379/0")
        say(f"queue mode: jobs go to Celery workers through {env['REDIS_URL']}")
    else:
        env.pop("REDIS_URL", None)
        env.pop("NONHOLONOMIC_REDIS_URL", None)
        say("embedded mode: jobs run in this process (no Redis needed)")
    memo = Path(env.get("NONHOLONOMIC_CACHE_DIR") or Path(env.get("XDG_CACHE_HOME") or Path.home() / ".cache")
                / "nonholonomic")
    if env.get("NONHOLONOMIC_CACHE_DIR", "").lower() != "off" and not any(memo.glob("*.memo")):
        say(f"first start: every system is derived and compiled once (about a minute on 2 cores; GET /health "
            f"says how far), then kept in {memo} for the next starts")
    env.setdefault("NONHOLONOMIC_LOG_FORMAT", "text")  # a terminal's plain lines (deployments log JSON)
    shown = "127.0.0.1" if args.host in ("0.0.0.0", "::") else args.host
    base = f"http://{'[' + shown + ']' if ':' in shown else shown}:{args.port}"
    say(f"API on {base} (listening on {args.host}:{args.port}); docs at {base}/docs; Ctrl-C stops it")
    say(f"try: export NONHOLONOMIC_URL={base}")
    uvicorn = str(BIN / "uvicorn")
    os.chdir(ROOT)
    os.execve(uvicorn, [uvicorn, "service.main:app", "--host", args.host, "--port", str(args.port), *rest], env)


if __name__ == "__main__":
    main(sys.argv[1:])
