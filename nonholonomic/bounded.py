"""Symbolic work under a time budget: one runner for every proof and computation in the core.

A computation runs in a daemon thread; the caller waits at most its budget and gets an
:class:`Outcome` (``done``, ``error``, ``timeout`` or ``busy``). Identical calls (same key) share one
thread and its result is cached per process, so a proof that outlived a budget answers the next call.
A finished result whose key pickles is also remembered across processes when a memo is installed
(:mod:`nonholonomic.memo`): a proof is done once per machine and version, not once per process.

Python threads cannot be killed: a computation past its budget keeps its CPU until it ends. So at
most :data:`MAX_RUNNING` computations run at once per process; past that a new one is refused
(``busy``) instead of piling up behind runaway ones. Sympy work sent by users is bounded before it
gets here (expression size, depth and constants, :mod:`nonholonomic.expressions`).
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from nonholonomic import memo

#: Computations allowed to run at once in one process (including those past their budget).
MAX_RUNNING = 32
#: Finished results kept per process (least recently used forgotten first).
CACHE_SIZE = 1024


@dataclass(frozen=True)
class Outcome:
    """What a bounded computation gave.

    ``status`` is ``"done"`` (``value`` holds the result), ``"error"`` (``message`` says what sympy
    raised), ``"timeout"`` (still running in the background) or ``"busy"`` (not started: too many
    computations running). ``seconds`` is the computation's own run time when it finished.
    """

    status: str
    value: Any
    seconds: float
    message: str = ""
    remembered: bool = False
    """True when the value was read from the memo (``seconds`` is then the original run's)."""


class _Task:
    def __init__(self, fn: Callable[..., Any], args: tuple[Any, ...], memo_key: str | None = None) -> None:
        self.done = threading.Event()
        self.value: Any = None
        self.error = ""
        self.seconds = 0.0
        self.remembered = False
        self._memo_key = memo_key
        self._thread = threading.Thread(target=self._run, args=(fn, args), daemon=True,
                                        name=f"bounded-{getattr(fn, '__name__', 'task')}")

    def start(self) -> _Task:
        self._thread.start()
        return self

    def recalled(self, value: Any, seconds: float) -> _Task:
        """Finished at once with a remembered ``value`` (computed in ``seconds`` by an earlier process)."""
        self.value, self.seconds, self.remembered = value, seconds, True
        self.done.set()
        return self

    def _run(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
        start = time.perf_counter()
        try:
            self.value = fn(*args)
        except Exception as exc:  # a sympy failure leaves the claim undecided, not the caller failed
            self.error = f"{type(exc).__name__}: {exc}"
        self.seconds = time.perf_counter() - start
        try:
            if self._memo_key is not None and not self.error:  # before done: a waiter's exit cannot cut it
                memo.keep(self._memo_key, (self.value, self.seconds))
        finally:
            self.done.set()

    def outcome(self, budget_s: float) -> Outcome:
        budget_s = max(float(budget_s), 0.0)
        if not self.done.wait(budget_s):
            return Outcome("timeout", None, budget_s,
                           f"did not finish within {budget_s:.3g} s (it continues in the background)")
        if self.error:
            return Outcome("error", None, self.seconds, self.error)
        return Outcome("done", self.value, self.seconds, remembered=self.remembered)


_tasks: OrderedDict[Hashable, _Task] = OrderedDict()
_lock = threading.Lock()


def _running() -> int:
    return sum(1 for t in _tasks.values() if not t.done.is_set())


def start(key: Hashable, fn: Callable[..., Any], args: tuple[Any, ...] = ()) -> _Task | None:
    """The task for ``key``: a running or finished one, one finished at once with what an earlier
    process remembered, else one started now; None if :data:`MAX_RUNNING` are running."""
    with _lock:
        task = _tasks.get(key)
        if task is not None:
            _tasks.move_to_end(key)
            return task
    memo_key = memo.key_of("bounded", key) if memo.installed() else None
    found, kept = memo.recall(memo_key) if memo_key is not None else (False, None)
    with _lock:
        task = _tasks.get(key)
        if task is not None:  # another thread started it meanwhile
            return task
        if not found and _running() >= MAX_RUNNING:
            return None
        while len(_tasks) >= CACHE_SIZE:
            finished = next((k for k, t in _tasks.items() if t.done.is_set()), None)
            if finished is None:
                break
            del _tasks[finished]
        task = _Task(fn, args, memo_key)
        _tasks[key] = task.recalled(*kept) if found else task.start()
        return task


def run(key: Hashable, fn: Callable[..., Any], args: tuple[Any, ...], budget_s: float) -> Outcome:
    """``fn(*args)`` waited on for at most ``budget_s`` seconds (shared and cached under ``key``)."""
    task = start(key, fn, args)
    peek = getattr(_peeking, "on", False)
    if task is None:
        if not peek:
            cut_short()
        return Outcome("busy", None, 0.0, f"not started: {MAX_RUNNING} symbolic computations are already "
                                          "running in this process; try again later")
    outcome = task.outcome(budget_s)
    if outcome.status == "timeout" and not peek:
        cut_short()
    return outcome


_cut_short = 0
_cut_lock = threading.Lock()
_peeking = threading.local()


@contextmanager
def peeking() -> Iterator[None]:
    """In this block (this thread), :func:`run` calls only start computations or read what is already
    known (e.g. with a budget of 0, so that several proofs share one budget): their timeouts are not
    counted by :func:`cut_short_count`; the call that waits for the verdict is."""
    outer = getattr(_peeking, "on", False)
    _peeking.on = True
    try:
        yield
    finally:
        _peeking.on = outer


def cut_short() -> None:
    """Count a computation that a budget or a busy process left undone (:func:`run` counts its own;
    code that skips a step because no budget is left calls this)."""
    global _cut_short
    with _cut_lock:
        _cut_short += 1


def cut_short_count() -> int:
    """How many computations a budget or a busy process has left undone in this process so far.

    A result assembled while this count did not move depends only on its inputs and the code, so it
    may be remembered whole (a symbolic request's answer, the paper report); otherwise it depends on
    the machine's load at the time and is not. Other threads' cuts count too: a false "cut" only
    means a result is not remembered."""
    return _cut_short


def verdict(outcome: Outcome) -> tuple[bool | None, str, Any]:
    """A proof's ``(verdict, detail, payload)`` from its outcome.

    A proof returns ``(verdict, detail)`` or ``(verdict, detail, payload)``; a timeout, a refusal
    or a sympy error leaves the verdict None (undecided) with the reason in the detail.
    """
    if outcome.status == "done":
        out = outcome.value
        payload = out[2] if len(out) > 2 else None
        where = "remembered from an earlier process" if outcome.remembered else "cached per process"
        return out[0], f"{out[1]} ({outcome.seconds:.2f} s, {where})", payload
    if outcome.status == "error":
        return None, f"sympy could not decide: {outcome.message}", None
    return None, f"symbolic proof {outcome.message}", None


def prove(key: Hashable, fn: Callable[..., tuple], args: tuple[Any, ...], budget_s: float) -> tuple[bool | None, str]:
    """``(verdict, detail)`` of the proof ``fn(*args)`` within ``budget_s`` (see :func:`verdict`)."""
    proven, detail, _ = verdict(run(key, fn, args, budget_s))
    return proven, detail
