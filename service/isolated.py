"""Run a user's symbolic request in a child process, so that nothing it starts outlives it.

The core runs each sympy step to its end, its size bounded beforehand by deterministic work limits
(:mod:`nonholonomic.work_limits`); the clock is only a safety cap (:mod:`nonholonomic.bounded`), and a
thread past it cannot be stopped: in the API process it would keep the interpreter busy until a
restart, slowing every later request (measured: a runaway ``integrate`` slowed a whole process 5-fold).
Here the request runs in a process forked from a clean fork server (its modules preloaded, no
threads); the process ends when the answer is sent, and its leftover threads end with it. If it
has not answered within the hard limit (the caller's safety cap plus :data:`GRACE_S`) it is killed:
a failure of the machine, which the caller reports as such (never as a verdict).
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any

log = logging.getLogger(__name__)
#: Seconds a child may take beyond the caller's safety cap (start-up, numeric checks, the answer).
GRACE_S = 10.0

_CONTEXT = multiprocessing.get_context("forkserver")
_CONTEXT.set_forkserver_preload(["nonholonomic.hamiltonization.reducing_multiplier", "nonholonomic.evidence.brackets",
                                 "service.routes.symbolic", "service.validation", "service.fork_server_warm"])


def start_fork_server(wait: bool = False) -> threading.Thread:
    """Start the fork server (its preloaded imports and warm-up, :mod:`service.fork_server_warm`: about
    3 s of CPU, most of it imports, with the memo on disk) in a thread, at the API's start-up, so that
    the first symbolic request or validation does not pay for it. The API does not wait for it
    (``wait``: block until it is up); a request arriving earlier waits for the same start.
    A failure (e.g. an interpreter whose main module cannot be re-imported) is logged, not raised: the
    API serves everything else, and a symbolic request reports it."""
    thread = threading.Thread(target=_start, daemon=True, name="nonholonomic-fork-server")
    thread.start()
    if wait:
        thread.join()
    return thread


def _start() -> None:
    try:
        run_isolated(_nothing, (), 120.0)
    except Exception as exc:  # the API still starts
        log.warning("the symbolic fork server did not start: %s", exc)


def _nothing() -> None:
    return None


class IsolatedTimeout(RuntimeError):
    """The child did not answer within its hard limit and was killed.

    ``progress`` is the last value the child sent with :func:`report_progress` (None if none)."""

    def __init__(self, message: str, progress: Any = None) -> None:
        super().__init__(message)
        self.progress = progress


#: In a child: the connection to the parent (for :func:`report_progress`); None elsewhere.
_TO_PARENT: Connection | None = None


def report_progress(value: Any) -> None:
    """In a child of :func:`run_isolated`: tell the parent where the work is (a picklable value; the
    last one is in :class:`IsolatedTimeout` if the child is killed). Elsewhere: nothing."""
    if _TO_PARENT is not None:
        _TO_PARENT.send(("progress", value))


def _child(connection: Connection, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
    global _TO_PARENT
    _TO_PARENT = connection
    try:
        connection.send(("ok", fn(*args)))
    except BrokenPipeError:  # the parent gave up at the hard limit: nobody is listening
        pass
    except Exception as exc:  # sent back and re-raised in the parent (ValueError → 422 there)
        try:
            connection.send(("error", exc))
        except BrokenPipeError:
            pass
        except Exception:  # an exception that does not pickle
            connection.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))
    finally:
        connection.close()


def run_isolated(fn: Callable[..., Any], args: tuple[Any, ...], limit_s: float) -> Any:
    """``fn(*args)`` in a child process; its result (picklable), or its exception re-raised.

    Raises
    ------
    IsolatedTimeout
        If no answer came within ``limit_s`` seconds (the child is killed).
    """
    receiver, sender = _CONTEXT.Pipe(duplex=False)
    process = _CONTEXT.Process(target=_child, args=(sender, fn, args), daemon=True, name="symbolic-request")
    process.start()
    sender.close()
    deadline, progress = time.monotonic() + limit_s, None
    try:
        while True:
            if not receiver.poll(max(deadline - time.monotonic(), 0.0)):
                raise IsolatedTimeout(f"the symbolic work did not finish within {limit_s:g} s and was stopped",
                                      progress)
            try:
                status, value = receiver.recv()
            except EOFError:
                raise RuntimeError(f"the symbolic worker process died (exit code {process.exitcode})") from None
            if status != "progress":
                break
            progress = value
    finally:
        receiver.close()
        process.join(timeout=1.0)
        if process.is_alive():
            process.kill()
            process.join()
    if status == "error":
        raise value
    return value
