"""``POST /v1/paper/report``: the paper report as a job, and its result model."""

from __future__ import annotations

from typing import Any, Final, Literal

from pydantic import BaseModel, ConfigDict, Field

#: The job's marker in the stored request (simulation jobs have a ``system`` instead).
REPORT_JOB: Final = "paper_report"


class PaperReportRequest(BaseModel):
    """Which claims to check (default: every claim of the paper)."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"examples": [{}, {"claims": ["ball.theorem_3"]}]})

    job: Literal["paper_report"] = REPORT_JOB
    claims: list[str] | None = Field(
        None, min_length=1, description="claim ids (GET /v1/paper/claims lists them); default: all")

    def problems(self) -> list[tuple[str, str]]:
        """``(field, reason)`` for every unknown claim id (``claims[i]``)."""
        if self.claims is None:
            return []
        from nonholonomic.report import claim_ids

        known = claim_ids()
        return [(f"claims[{i}]", f"unknown claim id {c!r}; GET /v1/paper/claims lists the {len(known)} known ones")
                for i, c in enumerate(self.claims) if c not in known]


class ReportRow(BaseModel):
    """One claim: what it says, where, the verdict, the decisive residual and tolerance."""

    id: str
    section: str
    claim: str
    equation: str
    verdict: Literal["holds", "holds after correction", "fails", "unresolved"]
    residual: float | None
    tolerance: float | None
    method: str | None
    printed: str | None
    corrected: str | None
    errata: str | None
    checks: list[dict[str, Any]]
    printed_check: dict[str, Any] | None
    note: str | None
    seconds: float


class ReportProvenance(BaseModel):
    """When and with what the report was computed; ``cached``: this answer was read back from an
    earlier run of the same code and libraries (``versions``), not computed again."""

    at: str = Field(description="when it was computed (ISO 8601, UTC)")
    seconds: float = Field(description="how long computing it took then")
    versions: dict[str, str] = Field(description="the project's version, its code fingerprint and the libraries'")
    project: dict[str, str | None] = Field(description="name, version and git commit of the build")
    cached: bool


class PaperReport(BaseModel):
    """The report: a row per claim and the count of each verdict."""

    paper: str
    errata: str = Field(description="where the paper's misprints are documented, each with its test")
    complete: bool
    summary: dict[str, int]
    rows: list[ReportRow]
    seconds: float
    verdicts: dict[str, str]
    computed: ReportProvenance | None = None


class ClaimList(BaseModel):
    """``GET /v1/paper/claims``: the ids ``POST /v1/paper/report`` accepts in ``claims``."""

    model_config = ConfigDict(extra="forbid")

    claims: list[str]
