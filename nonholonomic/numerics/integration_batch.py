"""Many members of one system at once: heyoka's batch mode (``hy.recommended_simd_size()`` SIMD lanes).

The batch path beside :mod:`nonholonomic.numerics.integration` (one orbit) and on its integrators: each member
gets the :class:`~nonholonomic.numerics.integration.Trajectory` the one-orbit path would give it, and a member
whose lane fails is integrated alone to say why. With ``check_points`` (what an ensemble chunk asks for) the
states the evidence is computed at are equally spaced check points written by heyoka with the samples, not every
accepted step: no Python call per step.
"""

from __future__ import annotations

import time
from collections.abc import Container

import heyoka as hy
import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics import integration, tally  # FIRST_SEGMENT_STEPS read at run time (tests change it)
from nonholonomic.numerics.integration import (
    _GOING,
    MACHINE_EPSILON,
    IntegrationCancelled,
    IntegrationError,
    ProgressCallback,
    StepRecorder,
    Trajectory,
    _batch_integrator,
    _integrate_heyoka,
    _sample_grid,
    _Segments,
    _taylor,
    _versions,
)
from nonholonomic.numerics.taylor import TaylorSystem


def lane_sources(count: int, failed: Container[int], lanes: int) -> list[int] | None:
    """Which member each of ``lanes`` lanes runs when members ``failed`` are left out: the others in
    order, a failed member's lane and the padding after the last member filled with the last healthy
    one (lanes do not influence each other); None when every member failed."""
    healthy = [i for i in range(count) if i not in failed]
    if not healthy:
        return None
    return [i if i in healthy else healthy[-1] for i in range(count)] + [healthy[-1]] * (lanes - count)


def integrate_batch(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_states: np.ndarray,
    t_final: float,
    samples: int,
    *,
    tolerance: float | None = None,
    check_points: int | None = None,
    progress: ProgressCallback | None = None,
) -> list[Trajectory | IntegrationError]:
    """Integrate many members (one system, each with its own parameters and initial state) with
    heyoka's batch mode, ``hy.recommended_simd_size()`` members at a time.

    Each member gets the :class:`Trajectory` :func:`integrate` would give it (samples, τ, steps and
    step states for the integral checks, equal up to rounding: the SIMD lanes and the scalar
    integrator may round differently in the last bit), except ``wall_time_s``: its batch's wall
    time divided among the batch's members. The last batch is padded with copies of the last
    member. A member whose lane fails (e.g. a non-finite state) fails alone: its entry is the
    :class:`IntegrationError` found by integrating it alone with :func:`integrate`'s integrator,
    and its batch is run again without it (lanes do not influence each other).

    Parameters
    ----------
    parameters : shape ``(n_members, n_parameters)``, rows in the order of ``system.parameter_symbols``.
    initial_states : shape ``(n_members, dimension)``.
    t_final, samples : the sample grid ``linspace(0, t_final, samples)``, shared by all members.
    tolerance : heyoka's tolerance (default machine epsilon).
    check_points : None (default): ``step_t, step_states`` are the states at every accepted step, kept
        by a step callback (a Python call per step: about a fifth of a short run's time). An int ``k``:
        they are the states at ``k`` equally spaced times ``linspace(0, t_final, k)``, written by heyoka's
        dense output inside ``propagate_grid`` with the samples (no Python per step; the integrals' worst
        drift over an ensemble is the same, see :data:`nonholonomic.analysis.ensemble.CHECK_POINTS`). A
        batch not finished within :data:`~nonholonomic.numerics.integration.FIRST_SEGMENT_STEPS` steps is run
        again with the step log (its points: the steps).
    progress : ``progress(fraction of members done) -> keep_going``, called after each batch and
        between the segments of a long run; False cancels (raises :class:`IntegrationCancelled`).

    Returns
    -------
    list
        One entry per member, in order: a :class:`Trajectory` or an :class:`IntegrationError`.

    Raises
    ------
    IntegrationCancelled, ValueError
    """
    ts = _taylor(system)
    P = np.asarray(parameters, dtype=float)
    Y0 = np.asarray(initial_states, dtype=float)
    if P.ndim != 2 or P.shape[1] != ts.n_user_pars:
        raise ValueError(f"parameters need shape (n_members, {ts.n_user_pars}), got {P.shape}")
    if Y0.shape != (len(P), system.dimension):
        raise ValueError(f"initial_states need shape ({len(P)}, {system.dimension}), got {Y0.shape}")
    if check_points is not None and check_points < 2:
        raise ValueError(f"check_points must be None or at least 2, got {check_points}")
    tol = tolerance or MACHINE_EPSILON
    lanes = hy.recommended_simd_size()
    run = _BatchRun(ts, _batch_integrator(system, tol, lanes), _sample_grid(float(t_final), int(samples)), tol,
                    None if check_points is None else _sample_grid(float(t_final), int(check_points)))
    pars = ts.runtime_parameters(P.T).T if len(P) else P  # every member's runtime parameters at once
    results: list[Trajectory | IntegrationError | None] = [None] * len(P)  # a slot per member, filled below
    for first in range(0, len(P), lanes):
        stop = min(first + lanes, len(P))

        def within(fraction: float, first: int = first, count: int = stop - first) -> bool:
            return True if progress is None else bool(progress((first + count * fraction) / len(P)))

        run.members(first, P[first:stop], pars[first:stop], Y0[first:stop], within, results)
        if progress is not None and stop < len(P) and not progress(stop / len(P)):
            raise IntegrationCancelled(f"cancelled after {stop} of {len(P)} members")
    run.finish(results)
    filled = [r for r in results if r is not None]
    assert len(filled) == len(results)  # every member's slot is filled by members() or finish()
    tally.count(integrations=sum(isinstance(r, Trajectory) for r in filled))
    return filled


#: One lane's result before its wall time is known: samples, τ (or None), step times, step states, steps.
_Lane = tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, int]
_FIELDS = ("states", "tau", "step_t", "step_states", "steps", "t", "engine", "tolerance", "wall_time_s", "versions")


def _trajectory(lane: _Lane, common: tuple[object, ...]) -> Trajectory:
    """A member's :class:`Trajectory` from its lane and the batch's ``t, engine, tolerance, wall_time_s,
    versions``, in one ``__dict__`` update (not the frozen dataclass's ``__setattr__`` per field)."""
    trajectory = object.__new__(Trajectory)
    trajectory.__dict__.update(zip(_FIELDS, (*lane, *common)))
    return trajectory


class _BatchRun:
    """The members of one :func:`integrate_batch` call, one batch integrator's lanes at a time. Short
    runs (every lane at ``t_final`` within :data:`~nonholonomic.numerics.integration.FIRST_SEGMENT_STEPS` steps: an
    ensemble's common case) keep their step records in one log of the call and are finished all together
    (:meth:`finish`: a few array operations in all instead of a few dozen per batch); long runs and failures batch by
    batch."""

    def __init__(self, ts: TaylorSystem, ta: hy.taylor_adaptive_batch, grid: np.ndarray, tol: float,
                 check_times: np.ndarray | None = None) -> None:
        self.ts, self.ta, self.grid, self.tol = ts, ta, grid, tol
        self.lanes = ta.batch_size
        # propagate_grid wants increasing times: the samples' and the check points' times, each once
        self.times = np.unique(grid if check_times is None else np.concatenate([grid, check_times]))
        self.where = np.searchsorted(self.times, grid)  # the samples' rows
        self.check_times = check_times  # shared by every member's Trajectory: read-only
        if check_times is not None:
            check_times.flags.writeable = False
        self.check_rows = None if check_times is None else np.searchsorted(self.times, check_times)
        self.lane_grid = np.repeat(self.times[:, None], self.lanes, axis=1)
        self.versions = _versions()
        # Views on the integrator's buffers; the step log: per step, the raw bytes of its state and time.
        self.state, self.pars, self.time = ta.state, ta.pars, ta.time
        state, clock = memoryview(self.state).cast("B"), memoryview(self.time).cast("B")
        self.log = bytearray()
        append = self.log.extend

        def on_step(_: hy.taylor_adaptive_batch) -> bool:
            append(state)
            append(clock)
            return True

        self.on_step, self.start_record = on_step, (state, clock)
        #: Short runs waiting for :meth:`finish`: (first member, count, start, end, log offset, samples), the
        #: log offset the steps per lane instead when the points are the check points.
        self.short: list[tuple[int, int, float, float, int | list[int], np.ndarray]] = []

    def members(self, first: int, P: np.ndarray, pars: np.ndarray, Y0: np.ndarray, progress: ProgressCallback,
                results: list[Trajectory | IntegrationError | None]) -> None:
        """Members ``first ..`` (up to ``lanes``: parameters, runtime parameters, initial states) in one
        batch, into ``results`` (a short run at :meth:`finish`); padding lanes copy the last member. A
        member whose lane fails is integrated alone (for its reason, or its trajectory if it then
        succeeds) and its lane given to a healthy member for another run of the batch."""
        alone: dict[int, Trajectory | IntegrationError] = {}
        start = time.perf_counter()
        count = len(P)
        source = list(range(count)) + [count - 1] * (self.lanes - count)
        lanes, bad = self.run(*((pars, Y0) if count == self.lanes else (pars[source], Y0[source])), progress,
                              (first, count, start))
        while bad:
            for i in {source[lane] for lane in bad}:
                try:
                    # with progress: a cancellation or time limit acts here too
                    alone[i] = _integrate_heyoka(self.ts.system, P[i], Y0[i], self.grid, self.tol, progress)
                except IntegrationError as exc:
                    alone[i] = exc
            healthy = [i for i in range(count) if i not in alone]
            if not healthy:
                results[first:first + count] = [alone[i] for i in range(count)]
                return
            source = [healthy[-1] if i in alone else i for i in range(count)] + [healthy[-1]] * (self.lanes - count)
            lanes, bad = self.run(pars[source], Y0[source], progress)
        if lanes is None:  # a short run: finished with the others
            return
        common = (self.grid, "heyoka", self.tol, (time.perf_counter() - start) / count, self.versions)
        results[first:first + count] = [alone[i] if i in alone else _trajectory(lane, common)
                                        for i, lane in enumerate(lanes[:count])]

    def run(self, pars: np.ndarray, Y0: np.ndarray, progress: ProgressCallback,
            short: tuple[int, int, float] | None = None) -> tuple[list[_Lane] | None, list[int]]:
        """One batch, one member per lane: each lane's result, or (if any failed) the failed lanes. With
        ``short`` (first member, count, start time), a short run is kept for :meth:`finish` (returns None)."""
        ts, ta, times, lanes = self.ts, self.ta, self.times, self.lanes
        n, nv = ts.n_state, len(ts.variables)
        ta.set_time(0.0)
        self.state[:n] = Y0.T
        self.state[n:] = 0.0  # tau
        self.pars[:] = pars.T[: self.pars.shape[0]]  # the parameters the equations use (heyoka's count)
        if len(times) == 1:
            out = self.state[None].copy()
            step_t, step_states = [np.zeros(1)] * lanes, [y[None].copy() for y in Y0]
            nsteps = [0] * lanes
        elif self.check_rows is not None and (checked := self.run_checked(short)) is not None:
            return checked
        else:
            # First segment: propagate_grid writes the samples, a lean callback logs the states.
            ta.set_time(0.0)  # again after a checked run that did not finish
            self.state[:n] = Y0.T
            self.state[n:] = 0.0
            log, mark = self.log, len(self.log)
            log += self.start_record[0]
            log += self.start_record[1]
            _, out = ta.propagate_grid(self.lane_grid, max_steps=integration.FIRST_SEGMENT_STEPS, callback=self.on_step)
            if short is not None and (self.time == times[-1]).all():  # every lane there: no failure, no step limit
                out[-1] = self.state  # the last samples are the final states themselves
                self.short.append((*short, time.perf_counter(), mark, out))
                return None, []
            records = np.frombuffer(bytes(log[mark:])).reshape(-1, nv + 1, lanes)  # rows: state, τ, t
            del log[mark:]
            res = ta.propagate_res
            outcomes = [r[0] for r in res]
            if any(o not in _GOING for o in outcomes):
                return [], [j for j, o in enumerate(outcomes) if o not in _GOING]
            nsteps = [r[3] for r in res]
            # A lane's own steps are its first records; once arrived it takes empty steps.
            if hy.taylor_outcome.step_limit in outcomes:
                recorders = [StepRecorder() for _ in range(lanes)]
                for j, rec in enumerate(recorders):
                    rec.extend(records[:nsteps[j] + 1, nv, j], records[:nsteps[j] + 1, :n, j])
                total = np.array(nsteps)
                bad = self.long_run(recorders, out, total, progress)
                if bad:
                    return [], bad
                nsteps = total.tolist()
                step_t, step_states = [r.t for r in recorders], [r.states for r in recorders]
            else:
                step_t = [records[:k + 1, nv, j] for j, k in enumerate(nsteps)]
                step_states = [records[:k + 1, :n, j] for j, k in enumerate(nsteps)]
            out[-1] = self.state  # the last samples are the final states themselves
        out = out[self.where]
        return [(out[:, :n, j], out[:, n, j] if ts.has_tau else None, step_t[j], step_states[j],
                 int(nsteps[j])) for j in range(lanes)], []

    def run_checked(self, short: tuple[int, int, float] | None) -> tuple[list[_Lane] | None, list[int]] | None:
        """One batch through ``propagate_grid`` alone (the state, parameters and time set by :meth:`run`),
        the check points among the grid's times; None when a lane is still short of ``t_final`` after
        :data:`~nonholonomic.numerics.integration.FIRST_SEGMENT_STEPS` steps (then :meth:`run` goes on with the
        step log)."""
        ta, n = self.ta, self.ts.n_state
        _, out = ta.propagate_grid(self.lane_grid, max_steps=integration.FIRST_SEGMENT_STEPS)
        res = ta.propagate_res  # a new list of tuples at each access
        if any(r[0] not in _GOING for r in res):
            return [], [j for j, r in enumerate(res) if r[0] not in _GOING]
        if not (self.time == self.times[-1]).all():
            return None
        out[-1] = self.state  # the last samples are the final states themselves
        nsteps = [r[3] for r in res]
        if short is not None:
            self.short.append((*short, time.perf_counter(), nsteps, out))
            return None, []
        samples, checks = out[self.where], out[self.check_rows]
        check_times = self.check_times
        assert check_times is not None  # a checked run: there are check points (check_rows is not None)
        return [(samples[:, :n, j], samples[:, n, j] if self.ts.has_tau else None, check_times, checks[:, :n, j],
                 nsteps[j]) for j in range(self.lanes)], []

    def finish(self, results: list[Trajectory | IntegrationError | None]) -> None:
        """Every short run's trajectories into ``results``: step records are views of the log, a lane's
        steps end where its time reaches ``t_final`` (then it takes empty steps); wall time: the batch's
        per member plus a share of this pass."""
        if not self.short:
            return
        if self.check_rows is not None:
            self.finish_checked(results)
            return
        tic = time.perf_counter()
        n, nv, lanes = self.ts.n_state, len(self.ts.variables), self.lanes
        records = np.frombuffer(self.log).reshape(-1, nv + 1, lanes)
        starts = np.array([short[4] for short in self.short]) // ((nv + 1) * lanes * 8)
        clock = records[:, nv, :]
        arrival = np.where(clock == self.times[-1], np.arange(len(records))[:, None], len(records))
        steps = (np.minimum.reduceat(arrival, starts, axis=0) - starts[:, None]).tolist()
        samples = np.stack([short[5] for short in self.short])[:, self.where]  # batch, time, variable, lane
        tau = samples[:, :, n] if self.ts.has_tau else None
        share = (time.perf_counter() - tic) / sum(short[1] for short in self.short)
        for b, ((first, count, start, end, _, _), s, lane_steps) in enumerate(zip(self.short, starts.tolist(), steps)):
            common = (self.grid, "heyoka", self.tol, (end - start) / count + share, self.versions)
            for j in range(count):
                k = lane_steps[j]
                results[first + j] = _trajectory((samples[b, :, :n, j], None if tau is None else tau[b, :, j],
                                                  records[s:s + k + 1, nv, j], records[s:s + k + 1, :n, j], k), common)
        self.short.clear()

    def finish_checked(self, results: list[Trajectory | IntegrationError | None]) -> None:
        """:meth:`finish` when the points are the check points: every short run's samples and check points
        are rows of its ``propagate_grid`` output."""
        tic = time.perf_counter()
        n = self.ts.n_state
        check_times = self.check_times
        assert check_times is not None  # called when there are check points (check_rows is not None)
        grids = np.stack([short[5] for short in self.short])  # batch, time, variable, lane
        samples = grids[:, self.where]
        # batch, lane, time, variable: each member's check points one contiguous block
        checks = np.ascontiguousarray(grids[:, self.check_rows, :n].transpose(0, 3, 1, 2))
        tau = samples[:, :, n] if self.ts.has_tau else None
        share = (time.perf_counter() - tic) / sum(short[1] for short in self.short)
        for b, (first, count, start, end, nsteps, _) in enumerate(self.short):
            assert isinstance(nsteps, list)  # a checked short run keeps the steps per lane, not a log offset
            common = (self.grid, "heyoka", self.tol, (end - start) / count + share, self.versions)
            for j in range(count):
                results[first + j] = _trajectory((samples[b, :, :n, j], None if tau is None else tau[b, :, j],
                                                  check_times, checks[b, j], nsteps[j]), common)
        self.short.clear()

    def long_run(self, recorders: list[StepRecorder], out: np.ndarray, nsteps: np.ndarray,
                 progress: ProgressCallback) -> list[int]:
        """Go on to ``t_final`` in continuous-output segments (no Python per step); returns failed lanes."""
        ta, times, n = self.ta, self.times, self.ts.n_state
        segments, t_final = _Segments(len(self.ts.variables), ta.order, self.lanes), float(times[-1])
        done = np.searchsorted(times, ta.time, side="right")
        res = ta.propagate_res
        while any(r[0] == hy.taylor_outcome.step_limit for r in res):
            if not progress(float(np.mean(np.minimum(ta.time / t_final, 1.0)))):
                raise IntegrationCancelled(f"cancelled at t = {ta.time.min():g}")
            tic = time.perf_counter()
            c_out, _ = ta.propagate_until(t_final, max_steps=segments.steps, c_output=True)
            res = ta.propagate_res
            bad = [j for j, r in enumerate(res) if r[0] not in _GOING]
            if bad:
                return bad
            steps = np.array([r[3] for r in res])
            nsteps += steps
            if c_out is not None and steps.max() > 0:
                # States after each step: the next steps' order-0 coefficients, then the current state.
                ends = np.concatenate([c_out.tcs[1:, :n, 0, :], ta.state[None, :n, :]])
                now = ta.time.copy()
                upto = np.searchsorted(times, now, side="right")
                wanted = upto - done
                if wanted.max() > 0:  # one evaluation: each lane's times, padded with its current time
                    k = np.arange(wanted.max())[:, None]
                    at = np.where(k < wanted, times[np.minimum(done + k, len(times) - 1)], now)
                    values = c_out(np.ascontiguousarray(at))
                for j, rec in enumerate(recorders):
                    rec.extend(c_out.times[1:steps[j] + 1, j], ends[:steps[j], :, j])
                    if wanted[j] > 0:
                        out[done[j]:upto[j], :, j] = values[:wanted[j], :, j]
                done = np.maximum(done, upto)
            segments.update(int(steps.max()), time.perf_counter() - tic)
        return []
