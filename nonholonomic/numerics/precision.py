"""mpmath's working precision, one per thread.

mpmath keeps its precision in one global context (``mpmath.mp``), and sympy 1.14 changes it in places
(``nsimplify`` sets ``mp.dps`` and restores what it found; ``Function._eval_evalf`` runs under
``mpmath.workprec``). Two threads of one process then interfere: one thread's ``nsimplify`` drops another to
15 digits in the middle of a 50-digit identity test, whose comparison at 1e-40 fails, and a proven
Hamiltonization becomes ``undecided``; or it restores 50 digits after the other has left them, and every later
evaluation of the process runs at 50 digits, changing the last digits of numbers. Both were seen in embedded
mode with several jobs running: the same request answered differently under load (issue 31's test).

A lock around our own evaluations (the first fix) cannot cover sympy's. So, as mpmath's maintainers suggest
(thread-local attributes of the context, mpmath issue 683), :func:`install` makes the precision of
``mpmath.mp`` an attribute of the thread: ``mp.prec``, ``mp.dps``, ``workdps`` and every ``mpf`` operation
read and write the calling thread's value, and a new thread starts at mpmath's default (53 bits, 15
digits). It is installed when this module is imported; :mod:`nonholonomic` imports it first.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import mpmath

__all__ = ["install", "installed", "working_digits"]

#: mpmath's defaults, each thread's precision until it sets one.
_DEFAULT_PREC, _DEFAULT_DPS, _DEFAULT_ROUNDING = 53, 15, "n"


class _ThreadPrecision(threading.local):
    """The calling thread's ``pair`` (``(prec, rounding)``: bits and rounding mode, as mpmath unpacks them on every
    operation) and ``dps`` (digits)."""

    pair: tuple[int, str] = (_DEFAULT_PREC, _DEFAULT_ROUNDING)
    dps: int = _DEFAULT_DPS


_STATE = _ThreadPrecision()


class _PrecisionRounding(list):  # mpmath reads a list [prec, rounding]
    """mpmath's ``[prec, rounding]`` list (``ctx._prec_rounding``, shared by its number types through
    ``_ctxdata``), read and written as the calling thread's values."""

    __slots__ = ()

    def __iter__(self) -> Iterator[Any]:  # every mpf operation: as little as possible
        return iter(_STATE.pair)

    def __getitem__(self, index: Any) -> Any:
        return _STATE.pair[index]

    def __setitem__(self, index: Any, value: Any) -> None:
        prec, rounding = _STATE.pair
        if index in (0, -2):
            _STATE.pair = (value, rounding)
        elif index in (1, -1):
            _STATE.pair = (prec, value)
        else:
            raise IndexError(index)

    def __len__(self) -> int:
        return 2

    def __repr__(self) -> str:
        return f"{list(_STATE.pair)} (this thread's)"


def _get_prec(ctx: Any) -> int:
    return _STATE.pair[0]


def _set_prec(ctx: Any, value: int) -> None:
    _STATE.pair = (value, _STATE.pair[1])


def _get_dps(ctx: Any) -> int:
    return _STATE.dps


def _set_dps(ctx: Any, value: int) -> None:
    _STATE.dps = value


def installed() -> bool:
    """Whether ``mpmath.mp``'s precision is per thread (:func:`install` ran)."""
    return isinstance(mpmath.mp._prec_rounding, _PrecisionRounding)


def install() -> None:
    """Make ``mpmath.mp``'s precision and rounding per thread (idempotent).

    The calling thread keeps the precision it had; every other thread starts at mpmath's default.

    Raises
    ------
    RuntimeError
        If mpmath's context is not laid out as this function expects (an mpmath other than 1.3's, whose
        context keeps ``_prec``, ``_dps`` and the list ``_prec_rounding`` that its number types share).
    """
    if installed():
        return
    ctx = mpmath.mp
    shared = getattr(ctx, "_prec_rounding", None)
    types = [getattr(ctx, name, None) for name in ("mpf", "mpc", "constant")]
    if (not isinstance(shared, list) or not all(isinstance(getattr(t, "_ctxdata", None), list) for t in types)
            or not all(t._ctxdata[2] is shared for t in types)):  # type: ignore[union-attr]
        raise RuntimeError(f"mpmath {mpmath.__version__}: its context is not laid out as "
                           "nonholonomic.numerics.precision expects; its precision cannot be made per thread")
    _STATE.pair, _STATE.dps = (shared[0], shared[1]), ctx._dps
    per_thread = _PrecisionRounding()
    base = type(ctx)
    ctx.__class__ = type("PerThreadMPContext", (base,), {
        "__doc__": "mpmath's context with its precision kept per thread (nonholonomic.numerics.precision).",
        "_prec": property(_get_prec, _set_prec), "_dps": property(_get_dps, _set_dps)})
    for name in ("_prec", "_dps"):
        ctx.__dict__.pop(name, None)
    ctx._prec_rounding = per_thread
    for t in types:
        t._ctxdata[2] = per_thread  # type: ignore[union-attr]


@contextmanager
def working_digits(digits: int) -> Iterator[None]:
    """Evaluate with mpmath at ``digits`` decimal digits in this thread (other threads keep theirs).

    Parameters
    ----------
    digits : int
        mpmath's ``dps`` inside the block (15: double precision's).
    """
    with mpmath.workdps(digits):
        yield


install()
