"""The core's memo (:mod:`nonholonomic.memo`) kept on disk: one file per remembered value.

Deterministic symbolic results (definitions, heyoka forms, numpy kernels, proofs) are read back in a
few milliseconds instead of being derived again by every new process: a worker's or the embedded
API's warm-up, the symbolic fork server, the report. heyoka keeps the machine code it compiled in a
cache of its own (``~/.cache/heyoka``), so integrators are not compiled again either.

A file's name is the SHA-256 of the :func:`fingerprint` and the core's key. Its header holds the
key, the fingerprint, the payload's length and SHA-256. A file whose header or checksum does not
match (truncated, corrupt, written by another version that happened to share the name) is deleted
and the value computed again, never trusted. Files are written atomically (a temporary file, then a
rename), so concurrent processes never read half a file. When the folder outgrows
``cache_max_mib``, the least recently used files are deleted.

The folder is ``NONHOLONOMIC_CACHE_DIR`` (default ``$XDG_CACHE_HOME/nonholonomic`` or
``~/.cache/nonholonomic``; ``off`` disables it). Its files are pickles: like heyoka's cache, it must be
writable only by the service's user (it is created with mode 0700).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import platform
import sys
import tempfile
import threading
import time
from functools import lru_cache
from importlib import metadata
from pathlib import Path

import nonholonomic
from nonholonomic import memo

log = logging.getLogger(__name__)

MAGIC = b"nonholonomic-memo 1\n"
#: Libraries whose versions are part of the fingerprint (their objects are pickled, or their results cached).
LIBRARIES = ("sympy", "heyoka", "numpy", "mpmath", "scipy")
#: Saves between two checks of the folder's size.
PRUNE_EVERY = 64


def _hash_sources(h: hashlib._Hash, base: Path, *folders: Path) -> None:
    """Feed every ``*.py`` under ``folders`` (path relative to ``base``, then content) to ``h``, in order."""
    for folder in folders:
        for path in sorted(folder.rglob("*.py")):
            h.update(str(path.relative_to(base)).encode())
            h.update(path.read_bytes())


def _library_versions() -> dict[str, str | None]:
    """The installed version of each of :data:`LIBRARIES` (None: not installed)."""
    out: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


@lru_cache(maxsize=1)
def fingerprint() -> str:
    """SHA-256 of the core's source files, the library versions, Python's version and the machine.

    Any change of the code that derives a value (``nonholonomic/``) or of a library gives every key a
    new file name: values of another version are never looked up.
    """
    h = hashlib.sha256()
    core = Path(nonholonomic.__file__).resolve().parent
    _hash_sources(h, core, core)
    for name, version in _library_versions().items():
        h.update(f"{name}={version or 'none'}".encode())
    h.update(f"python={sys.version}|{platform.machine()}|{sys.byteorder}".encode())
    return h.hexdigest()


@lru_cache(maxsize=1)
def response_fingerprint() -> str:
    """SHA-256 of the code that shapes a whole remembered answer beyond the core: the HTTP layer, the
    schemas and the workers (parsing, the response models, the report's assembly). Part of the keys of
    remembered responses (a symbolic request's answer, the paper report), so that a change there is
    never answered with a response shaped by the old code (or one the new models would refuse)."""
    h = hashlib.sha256()
    root = Path(nonholonomic.__file__).resolve().parent.parent
    _hash_sources(h, root, *(root / folder for folder in ("schemas", "service", "workers")))
    return h.hexdigest()


def versions() -> dict[str, str]:
    """The versions a remembered value was computed with (shown beside cached results)."""
    out = {"nonholonomic": nonholonomic.__version__, "code": fingerprint()[:16]}
    out.update({name: version for name, version in _library_versions().items() if version is not None})
    return out


def default_directory() -> Path:
    """``$XDG_CACHE_HOME/nonholonomic``, else ``~/.cache/nonholonomic``."""
    base = os.environ.get("XDG_CACHE_HOME")
    if not base:
        try:
            base = str(Path.home() / ".cache")
        except RuntimeError:  # no HOME and no passwd entry (a container's arbitrary user)
            base = os.path.join(tempfile.gettempdir(), f"nonholonomic-{os.getuid()}")
    return Path(base) / "nonholonomic"


class DiskMemo:
    """A :class:`nonholonomic.memo.Memo` in ``directory`` (see the module's docstring)."""

    def __init__(self, directory: str | Path, max_bytes: int = 512 * 2**20, code: str | None = None) -> None:
        self.directory = Path(directory).expanduser()
        self.max_bytes = max_bytes
        self.code = code or fingerprint()
        self.hits = 0  # values read back (this process)
        self.saves = 0  # values derived and written
        self._lock = threading.Lock()
        self.directory.mkdir(parents=True, exist_ok=True, mode=0o700)
        self._check_owner()

    def _check_owner(self) -> None:
        """Refuse a folder another user owns or may write to: its files are unpickled."""
        info = self.directory.stat()
        if hasattr(os, "getuid") and info.st_uid != os.getuid():
            raise PermissionError(f"{self.directory} belongs to another user (uid {info.st_uid}): not used")
        if info.st_mode & 0o022:
            raise PermissionError(f"{self.directory} is writable by other users (mode {info.st_mode & 0o777:o}): "
                                  "not used (chmod 700 it)")

    def path(self, key: str) -> Path:
        """Where the value of ``key`` lives."""
        return self.directory / f"{hashlib.sha256(f'{self.code}|{key}'.encode()).hexdigest()}.memo"

    def load(self, key: str) -> bytes | None:
        path = self.path(key)
        try:
            raw = path.read_bytes()
        except OSError:
            return None
        payload = self._checked(raw, key)
        if payload is None:
            log.warning("the remembered value %s in %s is corrupt or stale: deleted, computed again", key, path)
            self._unlink(path)
            return None
        try:
            os.utime(path)  # recently used: pruned last
        except OSError:
            pass
        self.hits += 1
        return payload

    def _checked(self, raw: bytes, key: str) -> bytes | None:
        """The payload of ``raw`` if its header names ``key`` and this code, and the checksum matches."""
        if not raw.startswith(MAGIC):
            return None
        end = raw.find(b"\n", len(MAGIC))
        if end < 0:
            return None
        try:
            header = json.loads(raw[len(MAGIC):end])
        except ValueError:
            return None
        payload = raw[end + 1:]
        if (not isinstance(header, dict) or header.get("key") != key or header.get("code") != self.code
                or header.get("length") != len(payload)
                or header.get("sha256") != hashlib.sha256(payload).hexdigest()):
            return None
        return payload

    def save(self, key: str, data: bytes) -> None:
        header = json.dumps({"key": key, "code": self.code, "length": len(data),
                             "sha256": hashlib.sha256(data).hexdigest()}).encode()
        path = self.path(key)
        tmp = None
        try:
            fd, tmp = tempfile.mkstemp(dir=self.directory, prefix=".", suffix=".partial")
            with os.fdopen(fd, "wb") as f:
                f.write(MAGIC + header + b"\n" + data)
            os.replace(tmp, path)
        except OSError as exc:  # a full or read-only disk: the value is computed again next time
            log.warning("could not remember %s in %s: %s", key, self.directory, exc)
            if tmp is not None:
                self._unlink(Path(tmp))
            return
        with self._lock:
            self.saves += 1
            due = self.saves % PRUNE_EVERY == 1
        if due:
            self.prune()

    def discard(self, key: str) -> None:
        self._unlink(self.path(key))

    def prune(self) -> None:
        """Delete the least recently used files until the folder holds at most ``max_bytes`` (and files a
        process left half-written when it was killed, after an hour)."""
        files: list[tuple[float, int, Path]] = []
        partial: list[Path] = []
        try:
            for p in self.directory.glob("*.memo"):
                try:  # another process may delete a file between the listing and its stat
                    info = p.stat()
                except OSError:
                    continue
                files.append((info.st_mtime, info.st_size, p))
            for p in self.directory.glob(".*.partial"):
                try:
                    if p.stat().st_mtime < time.time() - 3600:
                        partial.append(p)
                except OSError:
                    continue
        except OSError:
            return
        for path in partial:
            self._unlink(path)
        total = sum(size for _, size, _ in files)
        for _, size, path in sorted(files):
            if total <= self.max_bytes:
                break
            self._unlink(path)
            total -= size

    @staticmethod
    def _unlink(path: Path) -> None:
        try:
            path.unlink()
        except OSError:
            pass


def install_from_settings() -> DiskMemo | None:
    """:func:`install_disk_memo` with the deployment's ``cache_dir`` and ``cache_max_mib``."""
    from schemas.settings import get_settings

    settings = get_settings()
    return install_disk_memo(settings.cache_dir, settings.cache_max_mib)


def install_disk_memo(directory: str | None = None, max_mib: int = 512) -> DiskMemo | None:
    """Install a :class:`DiskMemo` on ``directory`` as the core's memo in this process (None: the default
    folder; ``"off"``: none), unless one on that folder is installed already. A folder that cannot be
    created is logged, and nothing is remembered."""
    if directory is not None and directory.strip().lower() == "off":
        memo.install(None)
        return None
    folder = Path(directory or default_directory()).expanduser()
    current = memo.installed()
    if isinstance(current, DiskMemo) and current.directory == folder:
        return current
    try:
        disk = DiskMemo(folder, max_mib * 2**20)
    except OSError as exc:
        log.warning("no memo on disk (%s): symbolic results are derived again in each process", exc)
        return None
    memo.install(disk)
    return disk
