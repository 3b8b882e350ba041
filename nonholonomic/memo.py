"""Deterministic symbolic results remembered across processes (a hook; the core does no file I/O).

A system's definition, its heyoka form, its numpy kernels and its proofs depend only on the
definition's inputs (kind, potential, surface ...) and on the code and library versions. Deriving
them costs seconds of sympy in every new process (a warm-up took 20–37 s on 2 cores); read
back, they cost milliseconds. The core marks what may be remembered (:func:`remembered`,
:func:`remember`) and asks a :class:`Memo` for it; the service installs one that keeps pickles on
disk (``workers/disk_memo.py``), whose keys also hold the code's and libraries' fingerprint and whose
entries carry a checksum. Without an installed memo everything is computed as before.

A value that does not pickle (e.g. a heyoka integrator, a closure) is simply not remembered; a
value that does not unpickle (corrupt, or from a library that changed its classes) is discarded
and computed again.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import logging
import pickle
import threading
import weakref
from collections.abc import Callable
from typing import Any, Protocol, TypeVar

import sympy as sp
from sympy.printing.str import StrPrinter

log = logging.getLogger(__name__)

T = TypeVar("T")
#: The pickle protocol of remembered values and of keys (deterministic for the same inputs).
PROTOCOL = 5


class Memo(Protocol):
    """Where remembered values live: bytes by key (the key names what was computed from what)."""

    def load(self, key: str) -> bytes | None:
        """The bytes saved under ``key``, or None (missing, stale or corrupt: never wrong bytes)."""

    def save(self, key: str, data: bytes) -> None:
        """Keep ``data`` under ``key`` (best effort: a failure to save is not an error)."""

    def discard(self, key: str) -> None:
        """Forget ``key`` (its bytes did not unpickle)."""


_memo: Memo | None = None


def install(memo: Memo | None) -> None:
    """Use ``memo`` from now on in this process (None: remember nothing)."""
    global _memo
    _memo = memo


def installed() -> Memo | None:
    """The memo in use, if any."""
    return _memo


#: The dataclass values :func:`remember` returned (a system's definition), by identity, with the key they
#: were remembered under: what is derived from one (its kernels) is keyed by that key, not by its pickle.
#: Weak references: an entry goes with its value (the systems' own caches bound how many live).
_origins: dict[int, tuple[weakref.ref, str]] = {}
_origins_lock = threading.RLock()  # a weak reference's callback may run inside a locked block (GC)


def _note_origin(value: object, key: str) -> None:
    if not dataclasses.is_dataclass(value) or isinstance(value, type):  # never a shared object (None, 0, "")
        return
    ident = id(value)

    def forget(ref: weakref.ref) -> None:
        with _origins_lock:
            if _origins.get(ident, (None, ""))[0] is ref:
                del _origins[ident]

    try:
        ref = weakref.ref(value, forget)
    except TypeError:  # a class without weak references: its derived values are keyed by their pickle
        return
    with _origins_lock:
        _origins[ident] = (ref, key)


def origin(value: object) -> str | None:
    """The key ``value`` was remembered under in this process, if it came from :func:`remember`."""
    found = _origins.get(id(value))
    return found[1] if found is not None and found[0]() is value else None


class _ExactPrinter(StrPrinter):
    """sympy's printed form with every float exact (its binary mantissa and exponent): two floats that
    print alike to 15 digits must not give one key."""

    def _print_Float(self, expr: sp.Float) -> str:
        return f"Float({expr._mpf_!r}, {expr._prec})"


def _stable(value: object) -> object:
    """``value`` in a form that pickles to the same bytes in every process for the same meaning.

    A remembered value becomes its key; an object with a ``memo_key()`` (a potential, which holds
    closures) that key; a sympy expression its printed form (terms in sympy's canonical order: a
    rebuilt expression may hold its terms in another order) and its free symbols with their
    assumptions; dataclasses, tuples, lists and dicts are taken apart.
    """
    known = origin(value)
    if known is not None:
        return ("remembered", known)
    if hasattr(value, "memo_key"):
        return (type(value).__qualname__, _stable(value.memo_key()))
    if isinstance(value, (sp.Basic, sp.MatrixBase)):
        return ("sympy", type(value).__name__, _ExactPrinter().doprint(value),
                tuple(sorted(sp.srepr(s) for s in value.free_symbols)))
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return (type(value).__qualname__,
                tuple((f.name, _stable(getattr(value, f.name))) for f in dataclasses.fields(value)))
    if isinstance(value, (tuple, list)):
        return type(value).__name__, tuple(_stable(v) for v in value)
    if isinstance(value, dict):
        return "dict", tuple((_stable(k), _stable(v)) for k, v in value.items())
    if isinstance(value, (frozenset, set)):
        return "set", tuple(sorted(repr(_stable(v)) for v in value))
    return value


def key_of(namespace: str, inputs: object) -> str | None:
    """``namespace:sha256`` of the inputs in their stable form (:func:`_stable`), or None if they do
    not pickle (a closure, a compiled integrator: such inputs are not remembered)."""
    try:
        data = pickle.dumps(_stable(inputs), protocol=PROTOCOL)
    except Exception:  # unpicklable inputs: not remembered
        return None
    return f"{namespace}:{hashlib.sha256(data).hexdigest()}"


def recall(key: str) -> tuple[bool, Any]:
    """``(True, value)`` if the installed memo holds ``key``, else ``(False, None)``."""
    memo = _memo
    if memo is None:
        return False, None
    data = memo.load(key)
    if data is None:
        return False, None
    try:
        return True, pickle.loads(data)
    except Exception as exc:  # a class that changed, or bytes that passed the checksum yet do not load
        log.warning("remembered %s does not load (%s: %s): computing it again", key, type(exc).__name__, exc)
        memo.discard(key)
        return False, None


def keep(key: str, value: T) -> T:
    """Save ``value`` under ``key`` in the installed memo, if any and if it pickles; returns the value as
    a later process will read it back (sympy may order a rebuilt expression's terms differently, and
    keys derived from the value must be the same in every process), or ``value`` itself if not saved."""
    memo = _memo
    if memo is None:
        return value
    try:
        data = pickle.dumps(value, protocol=PROTOCOL)
        read_back = pickle.loads(data)
    except Exception:  # e.g. a compiled integrator inside: computed again next time
        return value
    memo.save(key, data)
    return read_back


def remember(namespace: str, inputs: object, compute: Callable[[], T]) -> T:
    """``compute()``, or what it returned in an earlier process for the same ``namespace`` and ``inputs``."""
    key = key_of(namespace, inputs) if _memo is not None else None
    if key is None:
        return compute()
    found, value = recall(key)
    if not found:
        value = keep(key, compute())
    _note_origin(value, key)
    return value


def remembered(namespace: str) -> Callable[[Callable[..., T]], Callable[..., T]]:
    """Decorator: the function's results remembered under ``namespace``, its module and name, and its
    arguments (which must pickle to the same bytes for the same meaning: names, numbers, tuples,
    sympy expressions, frozen dataclasses of them)."""

    def decorate(fn: Callable[..., T]) -> Callable[..., T]:
        @functools.wraps(fn)
        def wrapper(*args: Any, **kwargs: Any) -> T:
            inputs = (fn.__module__, fn.__qualname__, args, tuple(sorted(kwargs.items())))
            return remember(namespace, inputs, lambda: fn(*args, **kwargs))

        return wrapper

    return decorate
