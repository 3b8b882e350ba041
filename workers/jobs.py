"""The job function: validate a request, simulate, return JSON. Celery's task and embedded mode
both call :func:`run_job`, so a job computes the same thing however it is run."""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from typing import Any

from nonholonomic.evidence.claims import claim_evidence
from nonholonomic.numerics.integration import ProgressCallback
from nonholonomic.simulation import simulate
from schemas.jobs import JobRequest
from schemas.report import REPORT_JOB, PaperReportRequest
from schemas.results import claims_to_json, first_non_finite, result_to_json
from workers.provenance import project

log = logging.getLogger(__name__)


class InvalidJob(ValueError):
    """The request fails validation (normally caught by the API before anything is queued)."""


class NonFiniteResult(ArithmeticError):
    """A number of the result is NaN or infinite (it overflowed); the job fails naming it."""


def use_safety_cap() -> None:
    """Wait at most ``symbolic_safety_cap_s`` for one symbolic step in this process (a job past it fails
    saying so: :class:`nonholonomic.bounded.SafetyCapExceeded`, never a different verdict)."""
    from nonholonomic import bounded
    from schemas.settings import get_settings

    bounded.set_safety_cap(get_settings().symbolic_safety_cap_s)


def run_job(request: dict[str, Any], progress: ProgressCallback | None = None) -> dict[str, Any]:
    """Run one simulation job.

    Parameters
    ----------
    request : a ``JobRequest`` as JSON, or a ``PaperReportRequest`` (``"job": "paper_report"``).
    progress : ``progress(fraction) -> keep_going``; returning False cancels the job
        (:class:`nonholonomic.numerics.integration.IntegrationCancelled` is raised).

    Returns
    -------
    dict
        The ``SimulationResultModel`` as JSON. The same request gives the same numbers
        (only ``integration.wall_time_s`` differs).
    """
    use_safety_cap()
    if request.get("job") == REPORT_JOB:
        return run_report(request, progress)
    job = JobRequest.model_validate(request)
    problems = job.problems()
    if problems:
        raise InvalidJob("; ".join(f"{p.field}: {p.reason}" for p in problems))
    system = job.system.definition()
    parameters = job.system.parameter_values()
    result = simulate(
        system, parameters, job.initial_state, job.t_final, job.samples,
        checks=job.checks, project=job.project_initial_state, engine=job.integrator.engine,
        tolerance=job.integrator.tolerance, progress=progress,
        poincare=job.poincare.options() if job.poincare else None,
        lyapunov=job.lyapunov.options() if job.lyapunov else None,
        periodic_orbit=job.periodic_orbit.options(system, parameters) if job.periodic_orbit else None,
    )
    out = result_to_json(result, parameters)
    if job.claims:
        out["claims"] = claims_to_json(claim_evidence(system, result.parameters, result.trajectory,
                                                      [(c.name, c.expression) for c in job.claims]))
    found = first_non_finite(out)
    if found is not None:
        raise NonFiniteResult(f"{found[0]} is {found[1]}: the numbers of this job overflow double precision "
                              "(parameters or initial state too large or too small for each other)")
    out["integration"]["project"] = project()
    return out


def run_report(request: dict[str, Any], progress: ProgressCallback | None = None) -> dict[str, Any]:
    """Run the paper report (every claim, or ``claims``); returns the ``PaperReport`` as JSON.

    The report depends only on the code and the libraries (every check is decided by deterministic
    limits, never by a clock): a complete one is remembered (:mod:`workers.disk_memo`, keyed by the code's
    fingerprint) and the next request for the same claims is answered from it, its ``computed``
    saying when, in how long and with which versions. Cancelling stops between claims
    (:class:`IntegrationCancelled` is raised, as for a simulation).
    """
    from datetime import UTC, datetime

    from nonholonomic import memo
    from nonholonomic.numerics.integration import IntegrationCancelled
    from nonholonomic.report import paper_report
    from workers.disk_memo import install_from_settings, response_fingerprint, versions

    job = PaperReportRequest.model_validate(request)
    problems = job.problems()
    if problems:
        raise InvalidJob("; ".join(f"{f}: {r}" for f, r in problems))
    install_from_settings()
    key = memo.key_of("paper-report", (tuple(job.claims) if job.claims is not None else None, response_fingerprint()))
    found, report = memo.recall(key) if key is not None else (False, None)
    if found:
        assert report is not None  # found: the remembered report
        if progress is not None:
            progress(1.0)
        return {**report, "computed": {**report["computed"], "cached": True}}
    use_safety_cap()
    report = paper_report(progress, only=job.claims)
    if not report["complete"]:
        raise IntegrationCancelled("the report was cancelled")
    report["computed"] = {"at": datetime.now(UTC).isoformat(timespec="seconds"), "seconds": report["seconds"],
                          "versions": versions(), "project": project(), "cached": False}
    if key is not None:
        memo.keep(key, report)
    return report


@dataclass
class WarmUp:
    """Where a process's warm-up is (``/health`` shows it): systems done of ``total``, the one being
    prepared, how many symbolic results the memo on disk gave back (``read_back``) and how many had to
    be derived (``derived``: all of them on a first start), its duration when finished, the memo's folder."""

    total: int = 0
    done: int = 0
    now: str | None = None
    read_back: int = 0
    derived: int = 0
    seconds: float | None = None
    cache: str | None = None

    def as_json(self) -> dict[str, Any]:
        """For ``/health`` (without the folder: it names no path of the machine)."""
        return {k: v for k, v in asdict(self).items() if v is not None and k != "cache"}


def warm_up(state: WarmUp | None = None) -> WarmUp:
    """Compile every system's kernels and integrator and start its symbolic proofs (once per process);
    with the memo on disk (:mod:`workers.disk_memo`, installed here if not yet) an earlier run's
    definitions, kernels and proofs are read back instead of derived (0.7 s instead of 20–37 s on 2
    cores), and heyoka reads the integrators' machine code from its own cache. ``state`` is updated
    as it goes (for ``/health``) and returned."""
    import time

    from workers.disk_memo import install_from_settings

    state = state or WarmUp()
    start = time.perf_counter()
    disk = install_from_settings()
    state.cache = str(disk.directory) if disk is not None else "off"
    from nonholonomic.evidence.measure import start_divergence_proof
    from nonholonomic.numerics.integration import MACHINE_EPSILON, heyoka_template
    from nonholonomic.numerics.kernels import numeric
    from nonholonomic.systems import KINDS, SUPPORTED_POTENTIALS, get_system

    # a user's surface is compiled with its first job: the example's would be wasted
    todo = [(kind, potential) for kind, potentials in SUPPORTED_POTENTIALS.items() if not KINDS[kind].surface
            for potential in potentials]
    state.total = len(todo)
    for kind, potential in todo:
        state.now = f"{kind} ({potential} potential)"
        system = get_system(kind, potential)
        heyoka_template(system, MACHINE_EPSILON)
        numeric(system).compile_all()
        start_divergence_proof(system)  # it finishes in its own thread; a job then reads its verdict
        state.done += 1
        if disk is not None:
            state.read_back, state.derived = disk.hits, disk.saves
    state.now, state.seconds = None, round(time.perf_counter() - start, 2)
    log.warning("warm-up: %d systems ready in %.1f s (%d symbolic results read back from %s, %d derived)",
                state.total, state.seconds, state.read_back, state.cache, state.derived)
    return state
