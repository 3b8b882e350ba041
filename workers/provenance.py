"""Which build of the service computed a result: the project's version and its git commit."""

from __future__ import annotations

import os
import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path

import nonholonomic

ROOT = Path(__file__).resolve().parents[1]


@lru_cache(maxsize=1)
def git_commit() -> str | None:
    """``NONHOLONOMIC_GIT_COMMIT`` if set (images built without ``.git``), else ``git rev-parse HEAD``
    of the checkout (with ``+dirty`` when it has uncommitted changes), else None."""
    if os.environ.get("NONHOLONOMIC_GIT_COMMIT"):
        return os.environ["NONHOLONOMIC_GIT_COMMIT"]
    if not (ROOT / ".git").exists():
        return None
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=5)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                               capture_output=True, text=True, timeout=5).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("+dirty" if dirty else "")


@lru_cache(maxsize=1)
def project() -> dict[str, str | None]:
    """``{"name", "version", "commit"}`` for a result's ``integration.project``."""
    try:
        version = metadata.version("nonholonomic")
    except metadata.PackageNotFoundError:
        version = nonholonomic.__version__
    return {"name": "nonholonomic", "version": version, "commit": git_commit()}
