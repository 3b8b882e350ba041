"""Symbolic work run to its end: one runner for every proof and computation in the core.

A verdict must depend on the question and the code only, never on how busy the machine is. So no
clock decides anything here: a computation runs until it finishes (``done``) or sympy raises
(``error``: the claim stays undecided, with sympy's reason). What keeps a computation small is decided
*before* it starts, by deterministic measures of the work (expression sizes, degrees, unknowns of an
ansatz: :mod:`nonholonomic.work_limits`), so a search that stops early says why in the same words on
every machine.

The clock is only a safety cap (:func:`safety_cap_s`, set by the service from its settings): a
computation still running after it raises :class:`SafetyCapExceeded` in the caller, a failure of the job
or request that says so, never a verdict. Python threads cannot be killed, so the computation itself goes
on in its daemon thread and its result is kept: the next identical call gets the same verdict a quiet
machine would have given.

Identical calls (same key) share one thread; finished results are cached per process and, when a memo
is installed (:mod:`nonholonomic.memo`), across processes. Sympy work sent by users is bounded before it
gets here (expression size, depth and constants, :mod:`nonholonomic.expressions`).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

from nonholonomic import memo

#: Computations run in threads of their own at once in one process; past that a computation runs in
#: its caller's thread (same result, no safety cap of its own: the job's time limit still holds).
MAX_RUNNING = 32
#: Finished results kept per process (least recently used forgotten first).
CACHE_SIZE = 1024
#: Seconds a caller waits for one computation by default (:func:`set_safety_cap`).
DEFAULT_SAFETY_CAP_S = 900.0

_safety_cap_s = DEFAULT_SAFETY_CAP_S


class SafetyCapExceeded(RuntimeError):
    """A symbolic computation still running after the safety cap (:func:`safety_cap_s`).

    Not a verdict: the job or request that waited fails with this message; the computation finishes in
    the background and an identical later call gets its result."""

    def __init__(self, what: str, seconds: float) -> None:
        self.what, self.seconds = what, seconds
        super().__init__(f"the symbolic step {what!r} did not finish within the service's safety cap of "
                         f"{seconds:g} s (a time limit of the machine, not of the question: the machine may be "
                         "overloaded); no verdict was given, and the same request later gets the answer")

    def __reduce__(self) -> tuple[type, tuple[str, float]]:  # crosses process boundaries (a worker's result)
        return type(self), (self.what, self.seconds)


def set_safety_cap(seconds: float) -> None:
    """Wait at most ``seconds`` for one computation from now on in this process."""
    global _safety_cap_s
    _safety_cap_s = max(float(seconds), 0.001)


def safety_cap_s() -> float:
    """Seconds a caller waits for one computation before :class:`SafetyCapExceeded`."""
    return _safety_cap_s


@dataclass(frozen=True)
class Outcome:
    """What a computation gave.

    ``status`` is ``"done"`` (``value`` holds the result) or ``"error"`` (``message`` says what sympy
    raised). ``seconds`` is the computation's own run time (a timing field: never part of a verdict).
    """

    status: str
    value: Any
    seconds: float
    message: str = ""
    remembered: bool = False
    """True when the value was read from the memo (``seconds`` is then the original run's)."""


class _Task:
    def __init__(self, fn: Callable[..., Any], args: tuple[Any, ...], what: str, memo_key: str | None = None) -> None:
        self.done = threading.Event()
        self.value: Any = None
        self.error = ""
        self.capped: SafetyCapExceeded | None = None
        self.seconds = 0.0
        self.remembered = False
        self.what = what
        self._fn, self._args = fn, args
        self._memo_key = memo_key

    def start(self) -> _Task:
        threading.Thread(target=self.run, daemon=True, name=f"bounded-{self.what}").start()
        return self

    def recalled(self, value: Any, seconds: float) -> _Task:
        """Finished at once with a remembered ``value`` (computed in ``seconds`` by an earlier process)."""
        self.value, self.seconds, self.remembered = value, seconds, True
        self.done.set()
        return self

    def run(self) -> None:
        start = time.perf_counter()
        try:
            self.value = self._fn(*self._args)
        except SafetyCapExceeded as exc:  # an inner step's cap: the caller fails too, nothing is cached
            self.capped = exc
        except Exception as exc:  # a sympy failure leaves the claim undecided, not the caller failed
            self.error = f"{type(exc).__name__}: {exc}"
        self.seconds = time.perf_counter() - start
        try:
            if self._memo_key is not None and not self.error and self.capped is None:
                memo.keep(self._memo_key, (self.value, self.seconds))  # before done: a waiter's exit cannot cut it
        finally:
            self.done.set()

    def outcome(self) -> Outcome:
        if not self.done.wait(_safety_cap_s):
            raise SafetyCapExceeded(self.what, _safety_cap_s)
        if self.capped is not None:
            raise self.capped
        if self.error:
            return Outcome("error", None, self.seconds, self.error)
        return Outcome("done", self.value, self.seconds, remembered=self.remembered)


_tasks: OrderedDict[Hashable, _Task] = OrderedDict()
_lock = threading.Lock()


def _running() -> int:
    return sum(1 for t in _tasks.values() if not t.done.is_set())


def _name(fn: Callable[..., Any]) -> str:
    return str(getattr(fn, "__qualname__", getattr(fn, "__name__", "task")))


def start(key: Hashable, fn: Callable[..., Any], args: tuple[Any, ...] = ()) -> _Task:
    """The task for ``key``: a running or finished one, one finished at once with what an earlier
    process remembered, else one started now (in a thread of its own, or, past :data:`MAX_RUNNING`
    running ones, run here and now)."""
    with _lock:
        task = _tasks.get(key)
        if task is not None:
            _tasks.move_to_end(key)
            return task
    memo_key = memo.key_of("bounded", key) if memo.installed() else None
    recalled: tuple[bool, Any] = memo.recall(memo_key) if memo_key is not None else (False, None)
    found, kept = recalled  # kept: the remembered (value, seconds)
    inline = False
    with _lock:
        task = _tasks.get(key)
        if task is not None:  # another thread started it meanwhile
            return task
        while len(_tasks) >= CACHE_SIZE:
            finished = next((k for k, t in _tasks.items() if t.done.is_set()), None)
            if finished is None:
                break
            del _tasks[finished]
        task = _Task(fn, args, _name(fn), memo_key)
        if found:
            task.recalled(*kept)
        elif _running() >= MAX_RUNNING:
            inline = True
        else:
            task.start()
        _tasks[key] = task
    if inline:
        task.run()
    return task


def run(key: Hashable, fn: Callable[..., Any], args: tuple[Any, ...] = ()) -> Outcome:
    """``fn(*args)`` run to its end (shared and cached under ``key``).

    Raises
    ------
    SafetyCapExceeded
        Still running after :func:`safety_cap_s` seconds (the computation goes on; the key is forgotten
        only if it failed through an inner cap).
    """
    task = start(key, fn, args)
    try:
        return task.outcome()
    except SafetyCapExceeded:
        if task.capped is not None:
            with _lock:
                if _tasks.get(key) is task:
                    del _tasks[key]
        raise


def verdict(outcome: Outcome) -> tuple[bool | None, str, Any]:
    """A proof's ``(verdict, detail, payload)`` from its outcome.

    A proof returns ``(verdict, detail)`` or ``(verdict, detail, payload)``; a sympy error leaves the
    verdict None (undecided) with the reason in the detail. The detail holds no time: the same proof
    gives the same words everywhere.
    """
    if outcome.status == "done":
        out = outcome.value
        payload = out[2] if len(out) > 2 else None
        return out[0], str(out[1]), payload
    return None, f"sympy could not decide: {outcome.message}", None


def prove(key: Hashable, fn: Callable[..., tuple], args: tuple[Any, ...] = ()) -> tuple[bool | None, str]:
    """``(verdict, detail)`` of the proof ``fn(*args)`` (see :func:`verdict`)."""
    proven, detail, _ = verdict(run(key, fn, args))
    return proven, detail
