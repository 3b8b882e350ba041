"""A text progress bar for waiting on jobs: redrawn in place on a terminal, one line per 10 % otherwise."""

from __future__ import annotations

import math
import sys
import time
import warnings
from collections.abc import Callable
from typing import Self, TextIO

#: Width of the bar in characters (without the brackets).
WIDTH = 30


def render_bar(fraction: float, status: str, elapsed: float | None = None, width: int = WIDTH) -> str:
    """The bar for one progress report.

    Parameters
    ----------
    fraction : float
        Progress in [0, 1] (clipped; NaN counts as 0).
    status : str
        The job's status (``queued``, ``running``, ...).
    elapsed : float, optional
        Seconds since the wait began, shown when given.
    width : int, default 30
        Characters inside the brackets.

    Returns
    -------
    str
        E.g. ``"[###############---------------]  50% running 1.2 s"``.
    """
    f = 0.0 if not math.isfinite(fraction) else min(max(fraction, 0.0), 1.0)
    filled = round(f * width)
    text = f"[{'#' * filled}{'-' * (width - filled)}] {100 * f:3.0f}% {status}"
    return text if elapsed is None else f"{text} {elapsed:.1f} s"


class ProgressBar:
    """A callable ``progress(fraction, status)`` for :meth:`nonholonomic_client.Client.wait` (and
    ``wait_ensemble``) that draws a bar.

    On a terminal the bar is redrawn in place with ``\\r``; on anything else (a log file, a pipe)
    it writes one line each time the progress reaches a new tenth or the status changes.

    Parameters
    ----------
    stream : file-like, optional
        Where to draw (default ``sys.stderr``).
    label : str, optional
        Written before the bar (e.g. the job id).
    tty : bool, optional
        Force terminal (``True``) or line (``False``) mode; default ``stream.isatty()``.
    clock : callable, optional
        Returns seconds (default ``time.monotonic``); for tests.
    """

    def __init__(self, stream: TextIO | None = None, label: str = "", tty: bool | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.label = f"{label} " if label else ""
        self.tty = bool(self.stream.isatty()) if tty is None else tty
        self._clock = clock
        self._start = clock()
        self._last: tuple[int, str] | None = None
        self._width = 0
        self._open = False

    def __call__(self, fraction: float, status: str) -> None:
        """Draw one progress report.

        Parameters
        ----------
        fraction : float
            Progress in [0, 1].
        status : str
            The job's status.
        """
        line = self.label + render_bar(fraction, status, self._clock() - self._start)
        if self.tty:
            pad = " " * max(0, self._width - len(line))
            self.stream.write(f"\r{line}{pad}")
            self._width = len(line)
            self._open = True
        else:
            tenth = math.floor(10 * min(max(fraction, 0.0), 1.0) + 1e-9) if math.isfinite(fraction) else 0
            key = (tenth, status)
            if key == self._last:
                return
            self._last = key
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        """End the bar's line on a terminal, so later output starts on a fresh line."""
        if self.tty and self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class TqdmProgress:
    """A callable ``progress(fraction, status)`` that drives a tqdm bar in units of ``total``: simulated
    seconds for a job (progress is t / t_final, so the bar and its ETA are linear in simulated time),
    members for an ensemble. ``tqdm.auto`` draws a widget in Jupyter (with ipywidgets) and text
    elsewhere.

    Parameters
    ----------
    total : float
        What a fraction of 1 stands for (e.g. ``t_final``).
    unit : str or None
        Its unit, e.g. ``"s"`` (simulated) or ``"members"``; None: a bar without counts.
    label : str, optional
        The bar's description (e.g. the job id's first characters).
    file : file-like, optional
        Where a text bar goes (default ``sys.stderr``).

    Raises
    ------
    ImportError
        Without tqdm (the client's ``[notebook]`` extra).
    """

    def __init__(self, total: float, unit: str | None, label: str = "", file: TextIO | None = None) -> None:
        try:
            with warnings.catch_warnings():  # "IProgress not found": Jupyter without ipywidgets gets text
                warnings.simplefilter("ignore")
                from tqdm.auto import tqdm
        except ImportError as exc:
            raise ImportError("progress=True needs tqdm: pip install 'nonholonomic-client[notebook]'") from exc
        self.total = float(total) if total and math.isfinite(total) and total > 0 else 1.0
        counts = "" if unit is None else "{n:.4g}/{total:.4g} " + unit + " "
        fmt = "{l_bar}{bar}| " + counts + "[{elapsed}<{remaining}] {postfix}"
        self.bar = tqdm(total=self.total, desc=label or None, unit=unit or "it", bar_format=fmt, file=file,
                        dynamic_ncols=True, leave=True)
        self._status = ""

    def __call__(self, fraction: float, status: str) -> None:
        """Move the bar to ``fraction`` of ``total`` and show ``status``.

        Parameters
        ----------
        fraction : float
            Progress in [0, 1].
        status : str
            The job's status.
        """
        f = 0.0 if not math.isfinite(fraction) else min(max(fraction, 0.0), 1.0)
        target = f * self.total
        if status != self._status:
            self._status = status
            self.bar.set_postfix_str(status, refresh=False)
        if target > self.bar.n:
            self.bar.update(target - self.bar.n)  # redraws (at most every tqdm's mininterval)
        elif status == "succeeded" or self.bar.n == 0:
            self.bar.refresh()

    def close(self) -> None:
        """Close the bar (it stays on screen)."""
        self.bar.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _in_kernel_without_widgets() -> bool:
    """Whether this runs in a Jupyter kernel that cannot draw tqdm's widget (no ipywidgets): tqdm's text
    would then arrive as one stderr line per redraw, stacked in the notebook (issue 35, item 5)."""
    import importlib.util

    try:
        from IPython import get_ipython
    except ImportError:
        return False
    shell = get_ipython()
    return shell is not None and "IPKernelApp" in shell.config and importlib.util.find_spec("ipywidgets") is None


class NotebookLine:
    """A callable ``progress(fraction, status)`` drawing one text line in a notebook, updated in place (an
    IPython display handle): Jupyter shows one moving line, and an executed notebook keeps its last state,
    ``100% succeeded``, as one output (the rendered tutorials). Redrawn at most every 0.2 s, at each new
    status and at the end.

    Parameters
    ----------
    total : float
        What a fraction of 1 stands for (e.g. ``t_final``).
    unit : str or None
        Its unit (``"s"`` simulated, ``"members"``); None: no counts.
    label : str, optional
        Written before the bar (the id's first characters).
    """

    def __init__(self, total: float, unit: str | None, label: str = "") -> None:
        from IPython.display import Pretty, display

        self._pretty = Pretty
        self.total = float(total) if total and math.isfinite(total) and total > 0 else 1.0
        self.unit, self.label = unit, label
        self._start = self._drawn = time.monotonic()
        self._last = (0.0, "")
        self.handle = display(Pretty(self._text(0.0, "")), display_id=True)

    def _text(self, fraction: float, status: str) -> str:
        counts = "" if self.unit is None else f" {fraction * self.total:.4g}/{self.total:.4g} {self.unit}"
        bar = render_bar(fraction, status, time.monotonic() - self._start)
        return f"{self.label + ' ' if self.label else ''}{bar}{counts}"

    def __call__(self, fraction: float, status: str) -> None:
        f = 0.0 if not math.isfinite(fraction) else min(max(fraction, 0.0), 1.0)
        now = time.monotonic()
        if status != self._last[1] or now - self._drawn >= 0.2 or f >= 1.0:
            self._drawn, self._last = now, (f, status)
            if self.handle is not None:
                self.handle.update(self._pretty(self._text(f, status)))

    def close(self) -> None:
        """Draw the last state once more (its final elapsed time)."""
        if self.handle is not None:
            self.handle.update(self._pretty(self._text(*self._last)))

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def notebook_progress(total: float, unit: str | None, label: str = "") -> TqdmProgress | NotebookLine:
    """``progress=True``'s bar: tqdm.auto (a widget in Jupyter with ipywidgets, text on a terminal), or one
    updating line in a Jupyter kernel without ipywidgets (:class:`NotebookLine`)."""
    if _in_kernel_without_widgets():
        return NotebookLine(total, unit, label)
    return TqdmProgress(total, unit, label)

