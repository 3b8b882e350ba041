"""Ensemble chunks: the function a worker (Celery task or embedded thread) runs for one chunk.

Records, progress and results live in the :class:`store.ensembles.EnsembleStore`, where a chunk's
members are written with its ``done`` flag at once: a chunk that runs twice (redelivered after its
worker died) replaces its own results with the same numbers and is counted once. Progress is
members done per chunk, written while the chunk runs; cancellation is a flag every running chunk reads.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from sqlalchemy.exc import OperationalError

from nonholonomic.analysis.chaos_map import cell_digest, run_cells
from nonholonomic.analysis.ensemble import digest, run_chunk
from nonholonomic.numerics.integration import IntegrationCancelled
from schemas.chaos_maps import cell_to_json
from schemas.ensembles import EnsembleRequest
from schemas.results import member_to_json
from store.ensembles import EnsembleStore
from workers.job_store import write_until_stored
from workers.jobs import use_safety_cap
from workers.limits import Deadline
from workers.metrics import metrics

#: Seconds between progress writes (and cancellation checks) of a running chunk.
PROGRESS_INTERVAL_S = 0.2
#: The task of an ensemble chunk.
ENSEMBLE_CHUNK = "nonholonomic.ensemble_chunk"


def chunk_task_id(ensemble_id: str, chunk: int) -> str:
    """The Celery task id of chunk ``chunk`` (the same every time it is sent)."""
    return f"{ensemble_id}.chunk-{chunk}"


def run_ensemble_chunk(store: EnsembleStore, ensemble_id: str, chunk: int, worker: str,
                       stopping: Callable[[], bool] = lambda: False, time_limit_s: float | None = None) -> str:
    """Run chunk ``chunk`` of an ensemble and store its members' results.

    Returns what happened: ``"done"``, ``"already done"`` (a redelivered chunk whose results are
    stored), ``"cancelled"`` (the ensemble was cancelled), ``"stopped"`` (``stopping()`` said so: the
    process stops, the chunk stays pending and runs again later). A chunk that fails as a whole (a
    bug, a time limit) stores every one of its members as failed with the reason, so the ensemble
    still completes. While the database is away, progress is not written and the results are
    written when it is back (:func:`workers.job_store.write_until_stored`); an error reading the
    ensemble before the chunk starts is raised (the caller tries again later). ``time_limit_s``: the
    chunk's soft time limit, checked at its progress reports (its members then fail with
    :class:`workers.limits.JobTimeout`).
    """
    if store.is_cancelled(ensemble_id):
        return "cancelled"
    if store.chunk_done(ensemble_id, chunk):
        return "already done"
    spec = store.spec(ensemble_id)
    if spec is None:
        return "cancelled"  # expired or never created
    start, stop = spec[1][chunk]
    use_safety_cap()
    store.mark_started(ensemble_id, chunk)
    request = EnsembleRequest.model_validate(spec[0])
    last = [time.monotonic()]
    deadline = Deadline(time_limit_s) if time_limit_s is not None else None

    def progress(fraction: float) -> bool:
        now = time.monotonic()
        if now - last[0] < PROGRESS_INTERVAL_S:
            return True
        last[0] = now
        if stopping():
            return False
        if deadline is not None:
            deadline.check()
        try:
            if store.is_cancelled(ensemble_id):
                return False
            store.set_progress(ensemble_id, chunk, int(fraction * (stop - start)))
        except OperationalError:  # the database is away: the chunk goes on
            pass
        return True

    try:
        members = request.members_list(start, stop)
        if request.indicators:
            system = request.definition()
            cells = run_cells(system, members, request.t_final, request.map_options(), progress)
            members_json, digests = [cell_to_json(system, c) for c in cells], [cell_digest(c) for c in cells]
            _store(store, ensemble_id, chunk, members_json, digests, worker)
            return "done"
        results = run_chunk(
            request.definition(), members, request.t_final, request.samples, checks=request.checks,
            poincare=request.poincare.options() if request.poincare else None,
            lyapunov=request.lyapunov.options() if request.lyapunov else None,
            tolerance=request.integrator.tolerance,
            parameter_groups=request.system.parameter_values(),
            progress=progress)
    except IntegrationCancelled:
        return "stopped" if stopping() else "cancelled"
    except Exception as exc:  # noqa: BLE001 - the chunk's members fail with the reason, the ensemble goes on
        reason = f"the chunk failed: {type(exc).__name__}: {exc}"
        failed = [{"index": i, "status": "failed", "error": reason} for i in range(start, stop)]
        _store(store, ensemble_id, chunk, failed, failed, worker)
        return "failed"
    members_json, digests = [member_to_json(m) for m in results], [digest(m) for m in results]
    _store(store, ensemble_id, chunk, members_json, digests, worker)
    return "done"


def _store(store: EnsembleStore, ensemble_id: str, chunk: int, members: list[dict[str, Any]],
           digests: list[Any], worker: str) -> None:
    """Store the chunk's results (until the database takes them); its members are counted in the metrics
    only by the run whose results were kept (:meth:`store.ensembles.EnsembleStore.store_chunk`)."""
    if write_until_stored(lambda: store.store_chunk(ensemble_id, chunk, members, digests, worker)):
        for member in members:
            metrics().members_finished.labels(str(member.get("status", "unknown"))).inc()
