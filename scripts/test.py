#!/usr/bin/env python3
"""Quick start, command 2: install into .venv (with the test extra), make sure Redis answers on
127.0.0.1:6379 (starting ``redis-server``, installing Debian's package if it is missing) and that a
headless Chromium is there for the page tests (installing Debian's ``chromium`` if it is missing),
then run the whole test suite. Extra arguments go to pytest (e.g. ``-k measure``).
Screenshots and other artefacts of the run go to ``test-output/``."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import time

from _bootstrap import PYTHON, ROOT, apt_install, ensure_installed, say

REDIS_HOST, REDIS_PORT = "127.0.0.1", 6379
#: Where the page tests look for the browser (Debian's package); NONHOLONOMIC_CHROMIUM overrides it.
CHROMIUM = "/usr/bin/chromium"


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


def main(argv: list[str]) -> int:
    ensure_installed("test")
    ensure_redis()
    env = {**os.environ, "NONHOLONOMIC_CHROMIUM": ensure_chromium(), "NONHOLONOMIC_REQUIRE_BROWSER": "1",
           "NONHOLONOMIC_TEST_OUTPUT": os.environ.get("NONHOLONOMIC_TEST_OUTPUT", str(ROOT / "test-output"))}
    os.chdir(ROOT)
    return subprocess.run([str(PYTHON), "-m", "pytest", *argv], env=env).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
