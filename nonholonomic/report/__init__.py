"""The paper report: every claim of Borisov & Mamaev's paper checked by the core, one row each.

Each row is computed when the report runs (:mod:`nonholonomic.report.veselova`,
:mod:`nonholonomic.report.ball`, :mod:`nonholonomic.report.others`): the form the core uses is
checked, and where the paper prints something else the printed form is checked the same way, so a
change of a formula in the core changes the verdict. :mod:`nonholonomic.report.verdict` defines
the verdicts.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from typing import Any

from nonholonomic import bounded
from nonholonomic.report import ball, others, veselova
from nonholonomic.report.verdict import UNRESOLVED, VERDICTS, Check, Claim, Row, RowBuilder

#: Every claim's row builder, in the paper's order.
ROWS: list[RowBuilder] = ball.ROWS[:3] + veselova.ROWS + ball.ROWS[3:] + others.ROWS

PAPER = 'A. V. Borisov, I. S. Mamaev, "Hamiltonization of nonholonomic systems"'


def claim_ids() -> list[str]:
    """The row ids in report order (read off the builders, nothing is run)."""
    return [fn.claim_id for fn in ROWS]


def paper_report(progress: Callable[[float], bool] | None = None,
                 only: list[str] | None = None) -> dict[str, Any]:
    """Run every claim (or the builders named in ``only``, see :func:`claim_ids`) and return the report.

    A claim whose check raises is reported ``unresolved`` with the error, so one broken check does
    not hide the others. ``progress(fraction)`` returning False stops early (the rows so far are
    returned, ``complete`` False). Every verdict and detail is the same on every run; only the
    ``seconds`` fields are timings.

    Raises
    ------
    nonholonomic.bounded.SafetyCapExceeded
        If a proof outlives the safety cap: a failure of the report, not a finding of a row.
    """
    start = time.perf_counter()
    builders = [fn for fn, name in zip(ROWS, claim_ids()) if only is None or name in only]
    rows: list[dict[str, Any]] = []
    complete = True
    for i, build in enumerate(builders):
        t0 = time.perf_counter()
        try:
            row = build()
        except bounded.SafetyCapExceeded:  # the machine's limit, not the claim's: no row, the report fails
            raise
        except Exception as exc:  # a broken check is a finding, not a crashed report
            row = Row(Claim("error", build.__doc__ or build.__name__, ""),
                      [Check(None, None, None, "error", f"{type(exc).__name__}: {exc}; "
                             + traceback.format_exc(limit=3).replace("\n", " | "))])
        row.seconds = time.perf_counter() - t0
        row.id = build.claim_id
        rows.append(row.to_json())
        if progress is not None and not progress((i + 1) / len(builders)):
            complete = False
            break
    counts = {v: sum(1 for r in rows if r["verdict"] == v) for v in VERDICTS}
    return {
        "paper": PAPER, "complete": complete,
        "errata": "docs/errata.md: each misprint (ERRATA n), its printed and corrected forms and its test",
        "summary": counts, "rows": rows, "seconds": round(time.perf_counter() - start, 2),
        "verdicts": {
            "holds": "the form the core uses passes; no printed variant differs, or it passes too",
            "holds after correction": "the core's corrected form passes and the printed form fails the same check",
            "fails": "the core's form fails its check",
            UNRESOLVED: "no check here decides the claim (a proof past a deterministic work limit or sympy unable to "
                        "reduce it, or not decidable from finite data)"},
    }


__all__ = ["paper_report", "claim_ids", "ROWS"]
