#!/usr/bin/env python3
"""Quick start, command 1: install into .venv and serve the API on http://127.0.0.1:8000.

Embedded mode (jobs run in the API process, no Redis) unless ``--queue`` is given, which keeps
``REDIS_URL`` (default redis://127.0.0.1:6379/0) so jobs go to Celery workers. Extra arguments
go to uvicorn (e.g. ``--port 9000``).
"""

from __future__ import annotations

import os
import sys

from _bootstrap import BIN, ROOT, ensure_installed, say


def main(argv: list[str]) -> None:
    ensure_installed()
    env = dict(os.environ)
    if "--queue" in argv:
        argv = [a for a in argv if a != "--queue"]
        env.setdefault("REDIS_URL", "redis://127.0.0.1:6379/0")
        say(f"queue mode: jobs go to Celery workers through {env['REDIS_URL']}")
    else:
        env.pop("REDIS_URL", None)
        env.pop("NONHOLONOMIC_REDIS_URL", None)
        say("embedded mode: jobs run in this process (no Redis needed)")
    say("API on http://127.0.0.1:8000 (OpenAPI docs at /docs); Ctrl-C stops it")
    uvicorn = str(BIN / "uvicorn")
    os.chdir(ROOT)
    os.execve(uvicorn, [uvicorn, "service.main:app", "--host", "127.0.0.1", "--port", "8000", *argv], env)


if __name__ == "__main__":
    main(sys.argv[1:])
