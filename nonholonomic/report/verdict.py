"""One row of the paper report: a claim, the checks that decide it, and the verdict.

Verdicts (computed, never typed in):

* ``holds``: the form the core uses passes its check, and no printed variant is on record, or the
  printed form passes too (then the row says so);
* ``holds after correction``: the core's form passes and the printed form, checked the same way,
  fails;
* ``fails``: the core's form fails its check;
* ``unresolved``: the check could not decide (a proof past a deterministic work limit of
  :mod:`nonholonomic.work_limits`, sympy unable to reduce it, or a claim not decidable by a check
  here, e.g. chaos).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

HOLDS, CORRECTED, FAILS, UNRESOLVED = "holds", "holds after correction", "fails", "unresolved"
VERDICTS = (HOLDS, CORRECTED, FAILS, UNRESOLVED)


@dataclass(frozen=True)
class Check:
    """One decision: ``passed`` is True/False, or None if undecided."""

    passed: bool | None
    residual: float | None
    tolerance: float | None
    method: str
    detail: str

    @staticmethod
    def at_most(residual: float, tolerance: float, method: str, detail: str) -> Check:
        """Passed iff ``residual`` is finite and ≤ ``tolerance``."""
        ok = residual == residual and abs(residual) != float("inf") and residual <= tolerance
        return Check(bool(ok), float(residual), tolerance, method, detail)

    @staticmethod
    def at_least(residual: float, threshold: float, method: str, detail: str) -> Check:
        """For a printed form expected to fail: 'passed' iff the residual stays ≤ ``threshold``."""
        return Check(bool(residual <= threshold), float(residual), threshold, method, detail)


@dataclass(frozen=True)
class Claim:
    """A claim of the paper, in words, with where it is (its id is its builder's, :func:`claim_id`)."""

    section: str
    claim: str
    equation: str
    printed: str = ""
    corrected: str = ""
    errata: str = ""


@dataclass
class Row:
    """A claim with its checks and verdict (see the module docstring)."""

    claim: Claim
    checks: list[Check]
    printed_check: Check | None = None
    seconds: float = 0.0
    note: str = ""
    id: str = ""
    verdict: str = field(init=False)

    def __post_init__(self) -> None:
        self.verdict = judge(self.checks, self.printed_check)

    def to_json(self) -> dict[str, Any]:
        decisive = next((c for c in self.checks if c.passed is not True), self.checks[0] if self.checks else None)
        return {
            "id": self.id, "section": self.claim.section, "claim": self.claim.claim,
            "equation": self.claim.equation, "verdict": self.verdict,
            "residual": None if decisive is None else decisive.residual,
            "tolerance": None if decisive is None else decisive.tolerance,
            "method": None if decisive is None else decisive.method,
            "printed": self.claim.printed or None,
            "corrected": (self.claim.corrected or None) if self.verdict == CORRECTED or self.claim.corrected else None,
            "errata": self.claim.errata or None,
            "checks": [vars(c) for c in self.checks],
            "printed_check": None if self.printed_check is None else vars(self.printed_check),
            "note": self.note or None,
            "seconds": round(self.seconds, 3),
        }


class RowBuilder(Protocol):
    """A claim's row builder, marked with its claim id by :func:`claim_id`."""

    __name__: str
    claim_id: str

    def __call__(self) -> Row: ...


def claim_id(name: str) -> Callable[[Callable[[], Row]], RowBuilder]:
    """Give a row builder its claim id (``section.name``), readable without running it."""

    def mark(fn: Callable[[], Row]) -> RowBuilder:
        builder = cast(RowBuilder, fn)  # the function itself, which takes the attribute set next
        builder.claim_id = name
        return builder

    return mark


def judge(checks: list[Check], printed: Check | None) -> str:
    """The verdict of a row (module docstring): any failing check fails the claim; any undecided
    one leaves it unresolved; otherwise it holds, after correction if the printed form failed."""
    if not checks:
        return UNRESOLVED
    if any(c.passed is False for c in checks):
        return FAILS
    if any(c.passed is None for c in checks):
        return UNRESOLVED
    if printed is not None and printed.passed is False:
        return CORRECTED
    return HOLDS
