"""Integrating a system: heyoka's Taylor method (default) or scipy's DOP853 (cross-check).

The heyoka integrator is generated from the symbolic right-hand side (:mod:`nonholonomic.taylor`),
with the parameters as runtime parameters (``hy.par``), so one compiled integrator serves every
parameter value; it is compiled once per (system, tolerance) and process, and copied once per
thread. Where the system has a reduced time ``τ = ∫ ρ dt``, it is integrated as one more state
variable.

The run is cut into segments, with no Python code per step where heyoka can do the work:

* the first :data:`FIRST_SEGMENT_STEPS` steps (all of a short run) go through ``propagate_grid``,
  which writes the samples itself; a lean step callback only appends the state's raw bytes
  (about 1 µs per step, where heyoka's continuous output costs about 1 ms to set up: more than a
  whole short run);
* a longer run goes on in segments of ``propagate_until(..., c_output=True)`` lasting about
  :data:`SEGMENT_WALL_TIME_S` each: the states after the accepted steps are the order-0 Taylor
  coefficients of the segment's steps (exactly the integrator's states) and the samples are the
  continuous output evaluated at the grid times, in one vectorised call per segment.

Progress and cancellation are checked between segments; memory is bounded (one segment's Taylor
coefficients, at most :data:`MAX_RECORDED_STEPS` recorded steps).

:func:`integrate_batch` integrates many members at once with heyoka's batch mode
(``taylor_adaptive_batch``, one member per SIMD lane), the same way.
"""

from __future__ import annotations

import copy
import threading
from collections import OrderedDict
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import heyoka as hy
import numpy as np
import scipy
from scipy.integrate import solve_ivp

from nonholonomic.definition import MechanicalSystem
from nonholonomic.kernels import numeric
from nonholonomic.taylor import TaylorSystem, taylor_system

MACHINE_EPSILON = float(np.finfo(float).eps)
#: DOP853 cannot honour tolerances much below this.
SCIPY_MIN_TOLERANCE = 1e-13
ENGINES = ("heyoka", "scipy")

#: At most this many accepted steps are kept for the integral checks (then every other one is dropped).
MAX_RECORDED_STEPS = 400_000
#: Steps of the first segment, logged by a lean step callback; a longer run goes on in segments
#: with heyoka's continuous output.
FIRST_SEGMENT_STEPS = 1024
#: Wall time a continuous-output segment aims at (sized from the measured time per step).
SEGMENT_WALL_TIME_S = 0.05
#: Bound on one segment's Taylor coefficients held by the continuous output (bytes).
SEGMENT_MEMORY_BYTES = 16 * 2**20

#: ``progress(fraction_done) -> keep_going``; return False to cancel.
ProgressCallback = Callable[[float], bool]


#: heyoka keeps the code it compiled in memory for reuse, up to 2 GiB by default: a worker compiling
#: many users' potentials would grow towards that. The built-in systems need about 17 MiB; beyond the
#: limit the least recently used code is dropped (it is compiled again, or read from heyoka's disk
#: cache, if needed again). Integrators in use are not affected.
HEYOKA_MEMCACHE_BYTES = 64 * 2**20
hy.llvm_state.set_memcache_limit(HEYOKA_MEMCACHE_BYTES)

class IntegrationError(RuntimeError):
    """The integration stopped before ``t_final`` (non-finite state, step-size collapse ...)."""


class IntegrationCancelled(RuntimeError):
    """The progress callback asked to stop."""


@dataclass(frozen=True)
class Trajectory:
    """Samples at the requested times and the states at the accepted steps.

    ``step_states`` holds the initial state and the state after every accepted step unless there
    were more than ``MAX_RECORDED_STEPS``; then it is thinned evenly (see :class:`StepRecorder`).

    ``states`` and ``step_states`` have shape ``(n, dim)`` in the order of ``system.state_symbols``.
    ``wall_time_s`` is the integration's wall time; for a member of :func:`integrate_batch`, its
    batch's wall time divided among the batch's members.
    """

    t: np.ndarray
    tau: np.ndarray | None
    states: np.ndarray
    step_t: np.ndarray
    step_states: np.ndarray
    engine: str
    tolerance: float
    steps: int
    wall_time_s: float
    versions: dict[str, str]


class StepRecorder:
    """The states at accepted steps, thinned by half whenever ``capacity`` is reached (bounded memory).

    ``stride`` is how many accepted steps one kept row stands for (1 until the first thinning):
    row ``i`` of all the rows ever added is kept iff ``i % stride == 0``. :meth:`extend` adds many
    rows at once, with the same result as adding them one by one.
    """

    def __init__(self, capacity: int = MAX_RECORDED_STEPS) -> None:
        self.capacity, self.stride, self._count, self._kept = capacity, 1, 0, 0
        self._t: list[np.ndarray] = []
        self._states: list[np.ndarray] = []

    def add(self, t: float, state: np.ndarray) -> None:
        """Add one row."""
        self.extend(np.array([t], dtype=float), np.asarray(state, dtype=float)[None])

    def extend(self, t: np.ndarray, states: np.ndarray) -> None:
        """Add rows ``t[i], states[i]`` in order (copied)."""
        count = len(t)
        if self.stride > 1:
            keep = (self._count + np.arange(count)) % self.stride == 0
            t, states = t[keep], states[keep]
        self._count += count
        if len(t):
            self._t.append(np.array(t, dtype=float))
            self._states.append(np.array(states, dtype=float))
            self._kept += len(t)
        while self._kept >= self.capacity:
            t_all, s_all = self.t[::2], self.states[::2]
            self._t, self._states, self._kept, self.stride = [t_all], [s_all], len(t_all), self.stride * 2

    @staticmethod
    def _joined(parts: list[np.ndarray]) -> np.ndarray:
        if len(parts) > 1:
            parts[:] = [np.concatenate(parts)]
        return parts[0] if parts else np.empty(0)

    @property
    def t(self) -> np.ndarray:
        """Times of the kept rows."""
        return self._joined(self._t)

    @property
    def states(self) -> np.ndarray:
        """Kept rows, shape ``(n, dim)``."""
        return self._joined(self._states)


@lru_cache(maxsize=32)
def heyoka_template(system: MechanicalSystem, tolerance: float) -> hy.taylor_adaptive:
    """Compile the Taylor integrator of ``system`` (state, then τ if any) at ``tolerance``, once per process."""
    ts = taylor_system(system)
    return hy.taylor_adaptive(ts.equations, [0.0] * len(ts.variables), pars=[0.0] * ts.n_pars, tol=tolerance)


@lru_cache(maxsize=32)
def heyoka_batch_template(system: MechanicalSystem, tolerance: float, batch_size: int) -> hy.taylor_adaptive_batch:
    """Compile the batch-mode integrator of ``system`` with ``batch_size`` lanes, once per process."""
    ts = taylor_system(system)
    n = len(ts.variables)
    return hy.taylor_adaptive_batch(ts.equations, np.zeros((n, batch_size)), pars=np.zeros((ts.n_pars, batch_size)),
                                    tol=tolerance)


_per_thread = threading.local()
#: Copies one thread keeps of each kind, least recently used dropped first: as many as the templates'
#: caches, so that a worker running many distinct user systems does not keep every one's compiled code
#: (unbounded, a pool process grew ~3 MiB per new potential: bench/bench_user_potentials.py).
THREAD_COPIES = 32


def _thread_copy(kind: str, system: MechanicalSystem, *key: object) -> hy.taylor_adaptive | hy.taylor_adaptive_batch:
    """This thread's own copy of a compiled integrator (copied once per thread, then reused; every
    run resets its time, state and parameters; the last :data:`THREAD_COPIES` kept). Looked up by the
    system's identity: hashing a system hashes its whole symbolic definition, which would cost more
    than a short run."""
    cache: OrderedDict[tuple[object, ...], tuple[MechanicalSystem, object]] = _per_thread.__dict__.setdefault(
        kind, OrderedDict())
    lookup = (id(system), *key)
    hit = cache.get(lookup)
    if hit is None or hit[0] is not system:
        template = heyoka_template(system, *key) if kind == "scalar" else heyoka_batch_template(system, *key)
        hit = cache[lookup] = (system, copy.deepcopy(template))
        while len(cache) > THREAD_COPIES:
            cache.popitem(last=False)
    cache.move_to_end(lookup)
    return hit[1]  # type: ignore[return-value]


def _integrator(system: MechanicalSystem, tolerance: float) -> hy.taylor_adaptive:
    """This thread's copy of the scalar integrator of ``system`` at ``tolerance``."""
    return _thread_copy("scalar", system, tolerance)


def _batch_integrator(system: MechanicalSystem, tolerance: float, batch_size: int) -> hy.taylor_adaptive_batch:
    """This thread's copy of the batch integrator of ``system`` (``batch_size`` lanes)."""
    return _thread_copy("batch", system, tolerance, batch_size)


_taylor_by_id: dict[int, tuple[MechanicalSystem, TaylorSystem]] = {}


def _taylor(system: MechanicalSystem) -> TaylorSystem:
    """:func:`~nonholonomic.taylor.taylor_system`, looked up by the system's identity."""
    hit = _taylor_by_id.get(id(system))
    if hit is None or hit[0] is not system:
        if len(_taylor_by_id) > 256:
            _taylor_by_id.clear()
        hit = _taylor_by_id[id(system)] = (system, taylor_system(system))
    return hit[1]


def _versions() -> dict[str, str]:
    import sympy

    return {"heyoka": hy.__version__, "sympy": sympy.__version__, "numpy": np.__version__, "scipy": scipy.__version__}


def _sample_grid(t_final: float, samples: int) -> np.ndarray:
    grid = np.linspace(0.0, t_final, samples)
    grid[-1] = t_final
    return grid


def integrate(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_state: np.ndarray,
    t_final: float,
    samples: int,
    *,
    engine: str = "heyoka",
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
    times: np.ndarray | None = None,
) -> Trajectory:
    """Integrate from t = 0 to ``t_final``, sampling ``samples`` equally spaced times (both ends).

    Parameters
    ----------
    system : the symbolic definition.
    parameters : parameter vector in the order of ``system.parameter_symbols``.
    initial_state : state at t = 0 in the order of ``system.state_symbols``.
    t_final, samples : the sample grid ``linspace(0, t_final, samples)``.
    engine : ``"heyoka"`` (Taylor, default) or ``"scipy"`` (DOP853, rtol = atol = tolerance).
    tolerance : heyoka's tolerance (default machine epsilon) or scipy's rtol = atol (default 1e-12).
    progress : called with the fraction of ``t_final`` reached, between segments (heyoka, after the
        first :data:`FIRST_SEGMENT_STEPS` steps, then about every :data:`SEGMENT_WALL_TIME_S`) or at
        every right-hand side evaluation (scipy); returning False cancels (raises
        :class:`IntegrationCancelled`).
    times : explicit sample times instead of the grid (non-decreasing, starting at 0; ``t_final``
        and ``samples`` are then ignored), e.g. a source trajectory's reduced times τ.

    Raises
    ------
    IntegrationError, IntegrationCancelled, ValueError
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; known: {ENGINES}")
    p = np.asarray(parameters, dtype=float)
    y0 = np.asarray(initial_state, dtype=float)
    if y0.shape != (system.dimension,):
        raise ValueError(f"initial state needs {system.dimension} components, got {y0.shape}")
    if times is None:
        grid = _sample_grid(float(t_final), int(samples))
    else:
        grid = np.asarray(times, dtype=float)
        if grid.ndim != 1 or len(grid) < 2 or grid[0] != 0.0 or np.any(np.diff(grid) < 0) or not np.all(np.isfinite(grid)):
            raise ValueError("times must be finite, non-decreasing, start at 0 and have at least 2 entries")
    if engine == "heyoka":
        return _integrate_heyoka(system, p, y0, grid, tolerance or MACHINE_EPSILON, progress)
    return _integrate_scipy(system, p, y0, grid, tolerance or 1e-12, progress)


class _Segments:
    """Sizes the continuous-output segments of a long run: about :data:`SEGMENT_WALL_TIME_S` of
    wall time each (from the measured time per step), within :data:`SEGMENT_MEMORY_BYTES`."""

    def __init__(self, n_vars: int, order: int, lanes: int = 1) -> None:
        self.cap = max(16, SEGMENT_MEMORY_BYTES // (n_vars * (order + 1) * lanes * 8))
        self.steps = min(FIRST_SEGMENT_STEPS, self.cap)

    def update(self, steps: int, wall_s: float) -> None:
        if steps and wall_s > 0:
            self.steps = int(min(self.cap, max(16, steps * SEGMENT_WALL_TIME_S / wall_s)))


def _failure(t: float, outcome: hy.taylor_outcome) -> IntegrationError:
    return IntegrationError(f"heyoka stopped at t = {t:g} with outcome {outcome.name}")


_GOING = (hy.taylor_outcome.time_limit, hy.taylor_outcome.step_limit)


def _integrate_heyoka(system: MechanicalSystem, p: np.ndarray, y0: np.ndarray, grid: np.ndarray,
                      tol: float, progress: ProgressCallback | None) -> Trajectory:
    ta = _integrator(system, tol)  # compiled once per process, copied once per thread; not timed
    ts = _taylor(system)
    n, nv = system.dimension, len(ts.variables)
    start = time.perf_counter()
    ta.time = 0.0
    ta.state[:] = ts.initial(y0)
    ta.pars[:] = ts.runtime_parameters(p)
    times, where = np.unique(grid, return_inverse=True)  # propagate_grid wants increasing times
    recorder = StepRecorder()
    nsteps = 0
    if len(times) == 1:
        out = ta.state[None].copy()
        recorder.add(0.0, ta.state[:n])
    else:
        # First segment: propagate_grid writes the samples, a lean callback logs the states.
        log, log_t = bytearray(ta.state.tobytes()), [0.0]
        append_state, append_t, state = log.extend, log_t.append, memoryview(ta.state).cast("B")

        def on_step(integrator: hy.taylor_adaptive) -> bool:
            append_state(state)  # the raw bytes of the integrator's state buffer
            append_t(integrator.time)
            return True

        outcome, _, _, nsteps, _, reached = ta.propagate_grid(times, max_steps=FIRST_SEGMENT_STEPS, callback=on_step)
        if outcome not in _GOING:
            raise _failure(ta.time, outcome)
        recorder.extend(np.array(log_t), np.frombuffer(log).reshape(-1, nv)[:, :n])
        done = int(np.searchsorted(times, ta.time, side="right"))
        out = np.empty((len(times), nv))  # the rows of the grid times reached so far, the others to come
        out[:done] = reached[:done]
        # A long run: segments with heyoka's continuous output (no Python per step).
        segments, t_final = _Segments(nv, ta.order), float(times[-1])
        while outcome == hy.taylor_outcome.step_limit:
            if progress is not None and not progress(min(ta.time / t_final, 1.0)):
                raise IntegrationCancelled(f"cancelled at t = {ta.time:g}")
            tic = time.perf_counter()
            outcome, _, _, steps, c_out, _ = ta.propagate_until(t_final, max_steps=segments.steps, c_output=True)
            if outcome not in _GOING:
                raise _failure(ta.time, outcome)
            nsteps += steps
            if steps:
                # The state after each step: the next step's order-0 Taylor coefficients, then the current state.
                recorder.extend(c_out.times[1:], np.concatenate([c_out.tcs[1:, :n, 0], ta.state[None, :n]]))
                upto = int(np.searchsorted(times, ta.time, side="right"))
                if upto > done:
                    out[done:upto] = c_out(np.ascontiguousarray(times[done:upto]))
                    done = upto
            segments.update(steps, time.perf_counter() - tic)
        out[-1] = ta.state  # the last sample is the final state itself
    out = out[where]
    return Trajectory(
        t=grid, tau=out[:, n].copy() if ts.has_tau else None, states=out[:, :n].copy(),
        step_t=recorder.t, step_states=recorder.states,
        engine="heyoka", tolerance=tol, steps=int(nsteps),
        wall_time_s=time.perf_counter() - start, versions=_versions(),
    )


def integrate_batch(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_states: np.ndarray,
    t_final: float,
    samples: int,
    *,
    tolerance: float | None = None,
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
    tol = tolerance or MACHINE_EPSILON
    lanes = hy.recommended_simd_size()
    run = _BatchRun(ts, _batch_integrator(system, tol, lanes), _sample_grid(float(t_final), int(samples)), tol)
    pars = ts.runtime_parameters(P.T).T if len(P) else P  # every member's runtime parameters at once
    results: list[Trajectory | IntegrationError] = []
    for first in range(0, len(P), lanes):
        members = slice(first, min(first + lanes, len(P)))

        def within(fraction: float, first: int = first, count: int = members.stop - first) -> bool:
            return True if progress is None else bool(progress((first + count * fraction) / len(P)))

        results.extend(run.members(P[members], pars[members], Y0[members], within))
        if progress is not None and len(results) < len(P) and not progress(len(results) / len(P)):
            raise IntegrationCancelled(f"cancelled after {len(results)} of {len(P)} members")
    return results


#: One lane's result before its wall time is known: samples, τ (or None), step times, step states, steps.
_Lane = tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, int]


class _BatchRun:
    """The members of one :func:`integrate_batch` call, one batch integrator's lanes at a time."""

    def __init__(self, ts: TaylorSystem, ta: hy.taylor_adaptive_batch, grid: np.ndarray, tol: float) -> None:
        self.ts, self.ta, self.grid, self.tol = ts, ta, grid, tol
        self.lanes = ta.batch_size
        self.times, self.where = np.unique(grid, return_inverse=True)  # propagate_grid wants increasing times
        self.lane_grid = np.repeat(self.times[:, None], self.lanes, axis=1)
        self.versions = _versions()

    def members(self, P: np.ndarray, pars: np.ndarray, Y0: np.ndarray,
                progress: ProgressCallback) -> list[Trajectory | IntegrationError]:
        """Up to ``lanes`` members (parameters ``P``, runtime parameters ``pars``, initial states
        ``Y0``) in one batch; padding lanes run a copy of the last member. A member whose lane
        fails is integrated alone (for its reason, or its trajectory if it then succeeds) and its
        lane given to a healthy member for another run of the batch."""
        alone: dict[int, Trajectory | IntegrationError] = {}
        start = time.perf_counter()
        source = list(range(len(P))) + [len(P) - 1] * (self.lanes - len(P))
        while True:
            lanes, bad = self.run(pars[source], Y0[source], progress)
            if not bad:
                break
            for i in {source[lane] for lane in bad}:
                try:
                    # with progress: a cancellation or time limit acts here too
                    alone[i] = _integrate_heyoka(self.ts.system, P[i], Y0[i], self.grid, self.tol, progress)
                except IntegrationError as exc:
                    alone[i] = exc
            healthy = [i for i in range(len(P)) if i not in alone]
            if not healthy:
                return [alone[i] for i in range(len(P))]
            source = [healthy[-1] if i in alone else i for i in range(len(P))] + [healthy[-1]] * (self.lanes - len(P))
        wall = (time.perf_counter() - start) / len(P)
        return [alone[i] if i in alone else Trajectory(
            t=self.grid, tau=tau, states=states, step_t=step_t, step_states=step_states, engine="heyoka",
            tolerance=self.tol, steps=steps, wall_time_s=wall, versions=self.versions,
        ) for i, (states, tau, step_t, step_states, steps) in enumerate(lanes[:len(P)])]

    def run(self, pars: np.ndarray, Y0: np.ndarray, progress: ProgressCallback) -> tuple[list[_Lane], list[int]]:
        """One batch, one member per lane: each lane's result, or (if any failed) the failed lanes."""
        ts, ta, times, lanes = self.ts, self.ta, self.times, self.lanes
        n, nv = ts.n_state, len(ts.variables)
        ta.set_time(0.0)
        ta.state[:n] = Y0.T
        ta.state[n:] = 0.0  # tau
        ta.pars[:] = pars.T
        nsteps = np.zeros(lanes, dtype=np.int64)
        if len(times) == 1:
            out = ta.state[None].copy()
            step_t, step_states = [np.zeros(1)] * lanes, [y[None].copy() for y in Y0]
        else:
            # First segment: propagate_grid writes the samples, a lean callback logs the states.
            # One record per step: the raw bytes of the integrator's state and time buffers.
            state, clock = memoryview(ta.state).cast("B"), memoryview(ta.time).cast("B")
            log = bytearray(state) + clock
            append = log.extend

            def on_step(_: hy.taylor_adaptive_batch) -> bool:
                append(state)
                append(clock)
                return True

            _, out = ta.propagate_grid(self.lane_grid, max_steps=FIRST_SEGMENT_STEPS, callback=on_step)
            res = ta.propagate_res
            bad = [j for j, r in enumerate(res) if r[0] not in _GOING]
            if bad:
                return [], bad
            nsteps[:] = [r[3] for r in res]
            records = np.frombuffer(log).reshape(-1, (nv + 1) * lanes)
            S, T = records[:, :nv * lanes].reshape(-1, nv, lanes), records[:, nv * lanes:]
            # A lane's own steps are its first rows; once arrived it takes empty steps.
            if any(r[0] == hy.taylor_outcome.step_limit for r in res):
                recorders = [StepRecorder() for _ in range(lanes)]
                for j, rec in enumerate(recorders):
                    rec.extend(T[:nsteps[j] + 1, j], S[:nsteps[j] + 1, :n, j])
                bad = self.long_run(recorders, out, nsteps, progress)
                if bad:
                    return [], bad
                step_t, step_states = [r.t for r in recorders], [r.states for r in recorders]
            else:
                by_lane_t, by_lane = T.T.copy(), S[:, :n, :].transpose(2, 0, 1).copy()
                step_t = [by_lane_t[j, :nsteps[j] + 1] for j in range(lanes)]
                step_states = [by_lane[j, :nsteps[j] + 1] for j in range(lanes)]
            out[-1] = ta.state  # the last samples are the final states themselves
        if len(times) < len(self.grid):
            out = out[self.where]
        states = out[:, :n, :].transpose(2, 0, 1).copy()
        tau = out[:, n, :].T.copy() if ts.has_tau else [None] * lanes
        return [(states[j], tau[j], step_t[j], step_states[j], int(nsteps[j])) for j in range(lanes)], []

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


def _integrate_scipy(system: MechanicalSystem, p: np.ndarray, y0: np.ndarray, grid: np.ndarray,
                     tol: float, progress: ProgressCallback | None) -> Trajectory:
    kernels = numeric(system)
    t_final = grid[-1]
    start = time.perf_counter()

    n = system.dimension
    tau_kernel = numeric(system).time_density if system.reduced_time else None

    def f(t: float, y: np.ndarray) -> np.ndarray:
        if progress is not None and not progress(min(t / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {t:g}")
        x = y[:n]
        dx = kernels.rhs_single(x, p)
        return dx if tau_kernel is None else np.append(dx, tau_kernel(x[None, :], p)[0, 0])

    y_start = y0 if tau_kernel is None else np.append(y0, 0.0)
    sol = solve_ivp(f, (0.0, t_final), y_start, method="DOP853", rtol=tol, atol=tol, dense_output=True)
    if not sol.success:
        raise IntegrationError(f"scipy DOP853 failed: {sol.message}")
    out = sol.sol(grid).T
    out[0] = y_start
    out[-1] = sol.y[:, -1]
    return Trajectory(
        t=grid, tau=out[:, n].copy() if tau_kernel is not None else None, states=out[:, :n].copy(),
        step_t=sol.t.copy(), step_states=sol.y[:n].T.copy(),
        engine="scipy", tolerance=tol, steps=len(sol.t) - 1,
        wall_time_s=time.perf_counter() - start, versions=_versions(),
    )
