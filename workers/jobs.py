"""The job function: validate a request, simulate, return JSON. Celery's task and embedded mode
both call :func:`run_job`, so a job computes the same thing however it is run."""

from __future__ import annotations

from typing import Any

from nonholonomic.evidence.claims import claim_evidence
from nonholonomic.integration import ProgressCallback
from nonholonomic.simulation import simulate
from schemas.jobs import JobRequest
from schemas.report import REPORT_JOB, PaperReportRequest
from schemas.results import claims_to_json, first_non_finite, result_to_json
from workers.provenance import project


class InvalidJob(ValueError):
    """The request fails validation (normally caught by the API before anything is queued)."""


class NonFiniteResult(ArithmeticError):
    """A number of the result is NaN or infinite (it overflowed); the job fails naming it."""


def run_job(request: dict[str, Any], progress: ProgressCallback | None = None) -> dict[str, Any]:
    """Run one simulation job.

    Parameters
    ----------
    request : a ``JobRequest`` as JSON, or a ``PaperReportRequest`` (``"job": "paper_report"``).
    progress : ``progress(fraction) -> keep_going``; returning False cancels the job
        (:class:`nonholonomic.integration.IntegrationCancelled` is raised).

    Returns
    -------
    dict
        The ``SimulationResultModel`` as JSON. The same request gives the same numbers
        (only ``integration.wall_time_s`` differs).
    """
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

    Cancelling stops between claims (:class:`IntegrationCancelled` is raised, as for a simulation).
    """
    from nonholonomic.integration import IntegrationCancelled
    from nonholonomic.report import paper_report

    job = PaperReportRequest.model_validate(request)
    problems = job.problems()
    if problems:
        raise InvalidJob("; ".join(f"{f}: {r}" for f, r in problems))
    report = paper_report(progress, only=job.claims)
    if not report["complete"]:
        raise IntegrationCancelled("the report was cancelled")
    return report


def warm_up() -> None:
    """Compile every system's kernels and integrator and start its symbolic proofs (once per process)."""
    from nonholonomic.evidence.measure import symbolic_divergence_vanishes
    from nonholonomic.integration import MACHINE_EPSILON, heyoka_template
    from nonholonomic.kernels import numeric
    from nonholonomic.systems import SUPPORTED_POTENTIALS, SURFACE_KINDS, get_system

    for kind, potentials in SUPPORTED_POTENTIALS.items():
        if kind in SURFACE_KINDS:  # a user's surface is compiled with its first job: the example's would be wasted
            continue
        for potential in potentials:
            system = get_system(kind, potential)
            heyoka_template(system, MACHINE_EPSILON)
            numeric(system).compile_all()
            symbolic_divergence_vanishes(system, budget_s=0)  # starts the proof; it finishes in its own thread
