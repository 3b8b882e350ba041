"""Shared by the Quick-start commands: make ``.venv`` in the checkout and install the project.

Standard library only, so it runs on a machine that has nothing but python3.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VENV = ROOT / ".venv"
BIN = VENV / ("Scripts" if os.name == "nt" else "bin")
PYTHON = BIN / "python"


def say(message: str) -> None:
    print(f"[nonholonomic] {message}", flush=True)


def apt_install(*packages: str) -> bool:
    """Install Debian packages when we can (root and apt-get present)."""
    if shutil.which("apt-get") is None or os.geteuid() != 0:
        return False
    say(f"installing {' '.join(packages)} with apt-get")
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    subprocess.run(["apt-get", "update", "-qq"], check=False, env=env)
    return subprocess.run(["apt-get", "install", "-y", "-qq", *packages], check=False, env=env).returncode == 0


def _create_venv() -> None:
    say(f"creating {VENV}")
    try:
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV)
    except (subprocess.CalledProcessError, OSError) as exc:
        # Debian's python3 lacks ensurepip until python3-venv is installed.
        version = f"python3.{sys.version_info.minor}-venv"
        if not (apt_install(version) or apt_install("python3-venv")):
            raise SystemExit("python3 cannot create a virtual environment: install python3-venv and retry") from exc
        venv.EnvBuilder(with_pip=True, clear=True).create(VENV)


def ensure_installed(extras: str = "") -> None:
    """Create ``.venv`` if needed and ``pip install -e .[extras]`` when pyproject.toml changed."""
    if not PYTHON.exists():
        _create_venv()
    spec = f".[{extras}]" if extras else "."
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes() + spec.encode()).hexdigest()
    stamp = VENV / f".installed-{extras or 'base'}"
    if stamp.exists() and stamp.read_text() == digest:
        return
    say(f"installing {spec} into .venv (first run downloads heyoka, ~100 MB)")
    subprocess.run([str(PYTHON), "-m", "pip", "install", "-q", "--upgrade", "pip"], check=True)
    # setuptools says "Editable installation ... be careful with folders in your working directory"
    # on every editable install (an information, shown as a warning): not for a newcomer's screen.
    quiet = {**os.environ, "PYTHONWARNINGS": "ignore:Editable installation"}
    subprocess.run([str(PYTHON), "-m", "pip", "install", "-q", "--no-compile", "-e", spec], check=True, cwd=ROOT,
                   env=quiet)
    compile_site_packages(PYTHON)
    stamp.write_text(digest)


def compile_site_packages(python: Path) -> None:
    """Bytecode for everything installed in ``python``'s environment, on every core: what pip does one
    file at a time after an install (its ``--no-compile`` skips that; on 2 cores the venv of the test
    extra is made in 52 s instead of 75 s). Errors (a package's test data that is not Python 3) are not
    ours and do not stop the install."""
    where = subprocess.run([str(python), "-c", "import sysconfig; p = sysconfig.get_paths(); "
                            "print(*sorted({p['purelib'], p['platlib']}), sep='\\n')"],
                           check=True, capture_output=True, text=True).stdout.split()
    compile_bytecode(python, where)


def compile_bytecode(python: Path, paths: list[str], cwd: Path | None = None) -> None:
    """``compileall`` over ``paths`` on every core, quietly; a file that does not compile is left to the
    import that needs it."""
    subprocess.run([str(python), "-m", "compileall", "-qq", "-j", "0", *paths], cwd=cwd, check=False)
