"""Integrating a system: heyoka's Taylor method (default) or scipy's DOP853 (cross-check).

The heyoka integrator is generated from the symbolic right-hand side (:mod:`nonholonomic.numerics.taylor`),
with the parameters as runtime parameters (``hy.par``), so one compiled integrator serves every
parameter value; it is compiled once per (system, tolerance) and process, and copied once per
thread. Where the system has a regular reduced time ``τ = ∫ ρ dt`` (ρ analytic and positive), it is
integrated as one more state variable; otherwise by quadrature along the dense output, segment by segment,
where ρ's zeros, sign changes and kinks are located (:mod:`nonholonomic.numerics.reduced_time`; every segment
then uses the continuous output).

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

:func:`nonholonomic.numerics.integration_batch.integrate_batch` integrates many members at once with heyoka's
batch mode (``taylor_adaptive_batch``, one member per SIMD lane), the same way or, for an ensemble,
with equally spaced check points instead of the step log.
"""

from __future__ import annotations

import copy
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from importlib import metadata

import heyoka as hy
import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics import tally
from nonholonomic.numerics.kernels import numeric
from nonholonomic.numerics.reduced_time import DensityQuadrature, ReducedTimeReport
from nonholonomic.numerics.taylor import TaylorSystem, taylor_system

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
    were more than ``MAX_RECORDED_STEPS``; then it is thinned evenly (see :class:`StepRecorder`). For
    a member of an ensemble (``integrate_batch(check_points=k)``), ``step_t, step_states`` are the
    states at ``k`` equally spaced check points instead (``steps`` still counts the accepted steps).

    ``states`` and ``step_states`` have shape ``(n, dim)`` in the order of ``system.state_symbols``.
    ``wall_time_s`` is the integration's wall time; for a member of :func:`integrate_batch`, its
    batch's wall time divided among the batch's members. ``reduced_time`` says how τ was integrated when by
    quadrature (where N vanished, changed sign, stopped being real; the independent check).
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
    reduced_time: ReducedTimeReport | None = None
    reduced_time_check: tuple[float, float, bool] | None = None
    """(residual, tolerance, passed) of τ against the independent Romberg quadrature."""


def density_quadrature(system: MechanicalSystem, p: np.ndarray) -> DensityQuadrature | None:
    """The quadrature of τ for ``system`` at ``p`` when its reduced time is not regular, else None."""
    if system.reduced_time is None or system.reduced_time.regular:
        return None
    kernels = numeric(system)
    density, kinks = kernels.time_density, kernels.time_density_kinks
    return DensityQuadrature(lambda states: density(np.ascontiguousarray(states), p)[:, 0],
                             None if kinks is None else lambda states: kinks(np.ascontiguousarray(states), p))


def _check_of(quadrature: DensityQuadrature | None) -> tuple[float, float, bool] | None:
    if quadrature is None:
        return None
    return quadrature.report.check_residual, quadrature.check_tolerance(), quadrature.check_passed()


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
    # heyoka sizes the parameters by the highest hy.par the equations use: a parameter only a constant term of L
    # holds (L = ... + k) is in none, so the vector is not forced to n_pars (issue 34: every such job failed)
    return hy.taylor_adaptive(ts.equations, [0.0] * len(ts.variables), tol=tolerance)


@lru_cache(maxsize=32)
def heyoka_batch_template(system: MechanicalSystem, tolerance: float, batch_size: int) -> hy.taylor_adaptive_batch:
    """Compile the batch-mode integrator of ``system`` with ``batch_size`` lanes, once per process."""
    ts = taylor_system(system)
    n = len(ts.variables)
    return hy.taylor_adaptive_batch(ts.equations, np.zeros((n, batch_size)), tol=tolerance)


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
    return hit[1]


def _integrator(system: MechanicalSystem, tolerance: float) -> hy.taylor_adaptive:
    """This thread's copy of the scalar integrator of ``system`` at ``tolerance``."""
    return _thread_copy("scalar", system, tolerance)


def _batch_integrator(system: MechanicalSystem, tolerance: float, batch_size: int) -> hy.taylor_adaptive_batch:
    """This thread's copy of the batch integrator of ``system`` (``batch_size`` lanes)."""
    return _thread_copy("batch", system, tolerance, batch_size)


_taylor_by_id: dict[int, tuple[MechanicalSystem, TaylorSystem]] = {}


def _taylor(system: MechanicalSystem) -> TaylorSystem:
    """:func:`~nonholonomic.numerics.taylor.taylor_system`, looked up by the system's identity."""
    hit = _taylor_by_id.get(id(system))
    if hit is None or hit[0] is not system:
        if len(_taylor_by_id) > 256:
            _taylor_by_id.clear()
        hit = _taylor_by_id[id(system)] = (system, taylor_system(system))
    return hit[1]


def _versions() -> dict[str, str]:
    """The libraries a trajectory was computed with (a new dict; read once per process: importlib's
    metadata parses scipy's METADATA file, ~0.5 ms, a few percent of an ensemble chunk)."""
    return dict(_library_versions())


@lru_cache(maxsize=1)
def _library_versions() -> tuple[tuple[str, str], ...]:
    import sympy

    return (("heyoka", hy.__version__), ("sympy", sympy.__version__), ("numpy", np.__version__),
            ("scipy", metadata.version("scipy")))


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
        if (grid.ndim != 1 or len(grid) < 2 or grid[0] != 0.0 or np.any(np.diff(grid) < 0)
                or not np.all(np.isfinite(grid))):
            raise ValueError("times must be finite, non-decreasing, start at 0 and have at least 2 entries")
    if engine == "heyoka":
        trajectory = _integrate_heyoka(system, p, y0, grid, tolerance or MACHINE_EPSILON, progress)
    else:
        trajectory = _integrate_scipy(system, p, y0, grid, tolerance or 1e-12, progress)
    tally.count(integrations=1)
    return trajectory


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
    ta.pars[:] = ts.runtime_parameters(p)[: len(ta.pars)]
    times, where = np.unique(grid, return_inverse=True)  # propagate_grid wants increasing times
    recorder = StepRecorder()
    nsteps = 0
    quadrature = density_quadrature(system, p)
    tau = np.zeros(len(times))
    if len(times) == 1:
        out = ta.state[None].copy()
        recorder.add(0.0, ta.state[:n])
    elif quadrature is not None:  # every segment with the continuous output, which τ's quadrature reads
        out = np.empty((len(times), nv))
        out[0] = ta.state
        recorder.add(0.0, ta.state[:n])
        nsteps = _segments_with_continuous_output(ta, n, times, out, 1, recorder, progress, quadrature, tau)
        out[-1] = ta.state
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
        if outcome == hy.taylor_outcome.step_limit:  # a long run
            nsteps += _segments_with_continuous_output(ta, n, times, out, done, recorder, progress)
        out[-1] = ta.state  # the last sample is the final state itself
    out = out[where]
    tau_out = out[:, n].copy() if ts.has_tau else (tau[where] if quadrature is not None else None)
    return Trajectory(
        t=grid, tau=tau_out, states=out[:, :n].copy(),
        step_t=recorder.t, step_states=recorder.states,
        engine="heyoka", tolerance=tol, steps=int(nsteps),
        wall_time_s=time.perf_counter() - start, versions=_versions(),
        reduced_time=None if quadrature is None else quadrature.report, reduced_time_check=_check_of(quadrature),
    )


def _segments_with_continuous_output(ta: hy.taylor_adaptive, n: int, times: np.ndarray, out: np.ndarray, done: int,
                                     recorder: StepRecorder, progress: ProgressCallback | None,
                                     quadrature: DensityQuadrature | None = None, tau: np.ndarray | None = None) -> int:
    """Go on to ``times[-1]`` in segments of ``propagate_until(..., c_output=True)`` (no Python per step), writing
    the samples from ``done`` on into ``out`` and, with ``quadrature``, τ into ``tau``; returns the steps taken.

    The segments last about :data:`SEGMENT_WALL_TIME_S` each (sized from the measured time per step), except with
    ``quadrature``: then they have a fixed number of steps, since where τ's events are looked for depends on them
    and no clock may change an answer."""
    segments, t_final = _Segments(len(ta.state), ta.order), float(times[-1])
    outcome, nsteps = hy.taylor_outcome.step_limit, 0
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
            if quadrature is not None and tau is not None:
                tau[done:upto] = quadrature.add(c_out, np.asarray(c_out.times, dtype=float), times[done:upto])
            done = max(done, upto)
        if quadrature is None:
            segments.update(steps, time.perf_counter() - tic)
    return nsteps


def _integrate_scipy(system: MechanicalSystem, p: np.ndarray, y0: np.ndarray, grid: np.ndarray,
                     tol: float, progress: ProgressCallback | None) -> Trajectory:
    kernels = numeric(system)
    t_final = grid[-1]
    start = time.perf_counter()

    n = system.dimension
    quadrature = density_quadrature(system, p)
    tau_kernel = numeric(system).time_density if system.taylor_time_density is not None else None

    def f(t: float, y: np.ndarray) -> np.ndarray:
        if progress is not None and not progress(min(t / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {t:g}")
        x = y[:n]
        dx = kernels.rhs_single(x, p)
        return dx if tau_kernel is None else np.append(dx, tau_kernel(x[None, :], p)[0, 0])

    from scipy.integrate import solve_ivp  # imported when used: ~1 s of every process's start otherwise

    y_start = y0 if tau_kernel is None else np.append(y0, 0.0)
    sol = solve_ivp(f, (0.0, t_final), y_start, method="DOP853", rtol=tol, atol=tol, dense_output=True)
    if not sol.success:
        raise IntegrationError(f"scipy DOP853 failed: {sol.message}")
    out = sol.sol(grid).T
    out[0] = y_start
    out[-1] = sol.y[:, -1]
    tau = out[:, n].copy() if tau_kernel is not None else None
    if quadrature is not None:
        times, where = np.unique(grid, return_inverse=True)
        tau = quadrature.add(lambda t: sol.sol(t).T, sol.t, times)[where]
    return Trajectory(
        t=grid, tau=tau, states=out[:, :n].copy(),
        step_t=sol.t.copy(), step_states=sol.y[:n].T.copy(),
        engine="scipy", tolerance=tol, steps=len(sol.t) - 1,
        wall_time_s=time.perf_counter() - start, versions=_versions(),
        reduced_time=None if quadrature is None else quadrature.report, reduced_time_check=_check_of(quadrature),
    )
