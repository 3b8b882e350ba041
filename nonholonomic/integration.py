"""Integrating a system: heyoka's Taylor method (default) or scipy's DOP853 (cross-check).

The heyoka integrator is generated from the symbolic right-hand side, with the parameters as
runtime parameters (``hy.par``), so one compiled integrator serves every parameter value; it is
compiled once per (system, tolerance) and process, and copied once per thread. Where the system
has a reduced time ``τ = ∫ ρ dt``, it is integrated as one more state variable.
"""

from __future__ import annotations

import copy
import threading
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
from nonholonomic.taylor import taylor_system

MACHINE_EPSILON = float(np.finfo(float).eps)
#: DOP853 cannot honour tolerances much below this.
SCIPY_MIN_TOLERANCE = 1e-13
ENGINES = ("heyoka", "scipy")

#: At most this many accepted steps are kept for the integral checks (then every other one is dropped).
MAX_RECORDED_STEPS = 400_000

#: ``progress(fraction_done) -> keep_going``; return False to cancel.
ProgressCallback = Callable[[float], bool]


class IntegrationError(RuntimeError):
    """The integration stopped before ``t_final`` (non-finite state, step-size collapse ...)."""


class IntegrationCancelled(RuntimeError):
    """The progress callback asked to stop."""


@dataclass(frozen=True)
class Trajectory:
    """Samples at the requested times and the states at the accepted steps.

    ``step_states`` holds every accepted step unless there were more than ``MAX_RECORDED_STEPS``;
    then it is thinned evenly (see :class:`StepRecorder`).

    ``states`` and ``step_states`` have shape ``(n, dim)`` in the order of ``system.state_symbols``.
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

    ``stride`` is how many accepted steps one kept row stands for (1 until the first thinning).
    """

    def __init__(self, capacity: int = MAX_RECORDED_STEPS) -> None:
        self.capacity, self.stride, self._count = capacity, 1, 0
        self.t: list[float] = []
        self.states: list[np.ndarray] = []

    def add(self, t: float, state: np.ndarray) -> None:
        if self._count % self.stride == 0:
            self.t.append(t)
            self.states.append(state.copy())
            if len(self.t) >= self.capacity:
                self.t, self.states, self.stride = self.t[::2], self.states[::2], self.stride * 2
        self._count += 1


@lru_cache(maxsize=32)
def heyoka_template(system: MechanicalSystem, tolerance: float) -> hy.taylor_adaptive:
    """Compile the Taylor integrator of ``system`` (state, then τ if any) at ``tolerance``, once per process."""
    ts = taylor_system(system)
    return hy.taylor_adaptive(ts.equations, [0.0] * len(ts.variables), pars=[0.0] * ts.n_pars, tol=tolerance)


_per_thread = threading.local()


def _integrator(system: MechanicalSystem, tolerance: float) -> hy.taylor_adaptive:
    """This thread's own copy of the compiled integrator (copied once per thread, then reused;
    every run resets its time, state and parameters)."""
    cache: dict[tuple[MechanicalSystem, float], hy.taylor_adaptive] = _per_thread.__dict__.setdefault("cache", {})
    key = (system, tolerance)
    if key not in cache:
        cache[key] = copy.deepcopy(heyoka_template(system, tolerance))
    return cache[key]


def _versions() -> dict[str, str]:
    return {"heyoka": hy.__version__, "numpy": np.__version__, "scipy": scipy.__version__}


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
    progress : called with the fraction of ``t_final`` reached after each step; returning False
        cancels (raises :class:`IntegrationCancelled`).
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


def _integrate_heyoka(system: MechanicalSystem, p: np.ndarray, y0: np.ndarray, grid: np.ndarray,
                      tol: float, progress: ProgressCallback | None) -> Trajectory:
    ta = _integrator(system, tol)  # compiled once per process, copied once per thread; not timed
    n = system.dimension
    start = time.perf_counter()
    ta.time = 0.0
    ts = taylor_system(system)
    ta.state[:] = ts.initial(y0)
    ta.pars[:] = ts.runtime_parameters(p)
    t_final = grid[-1]
    recorder = StepRecorder()
    recorder.add(0.0, ta.state[:n])

    def on_step(integrator: hy.taylor_adaptive) -> bool:
        recorder.add(integrator.time, integrator.state[:n])
        return True if progress is None else bool(progress(min(integrator.time / t_final, 1.0)))

    outcome, _, _, nsteps, _, out = ta.propagate_grid(grid, callback=on_step)
    if outcome == hy.taylor_outcome.cb_stop:
        raise IntegrationCancelled(f"cancelled at t = {ta.time:g}")
    if outcome != hy.taylor_outcome.time_limit:
        raise IntegrationError(f"heyoka stopped at t = {ta.time:g} with outcome {outcome.name}")
    return Trajectory(
        t=grid, tau=out[:, n].copy() if system.reduced_time else None, states=out[:, :n].copy(),
        step_t=np.asarray(recorder.t), step_states=np.asarray(recorder.states),
        engine="heyoka", tolerance=tol, steps=int(nsteps),
        wall_time_s=time.perf_counter() - start, versions=_versions(),
    )


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
