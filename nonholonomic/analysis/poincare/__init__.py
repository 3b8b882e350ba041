"""Poincaré sections: the crossings of one trajectory with a surface ``S(state) = value``.

A surface is a user expression in the state components (``M1``, ``gamma3``, ``omega2`` ...,
parsed by the safe parser :func:`nonholonomic.expressions.parse_expression`, never ``eval``),
possibly using the system's parameters (``I1``, ``D`` ...). Derived components (the ball's
``omega = I_Q⁻¹ M``, paper eq. 2604-1) are substituted by their expressions in the state, so
every surface is a function of the integrated variables.

Method
------
The crossings are located by heyoka's non-terminal events (``nt_event``, ``nt_event_batch``)
on the event function ``S(x) − value``: heyoka computes the Taylor expansion of the event
function along with the state's and finds the roots of that polynomial inside every step, so a
crossing is found to machine precision without any extra step. The callback evaluates the dense
output (``update_d_output``) at the event time, as heyoka's own Poincaré-section tutorial does.
``value`` is a runtime parameter (the slot after the system's parameters), so one compiled
integrator serves every level; it is compiled once per (system, surface, direction, tolerance)
and process, and copied once per thread.

The event time reaches Python rounded to a double; one Newton step along the flow moves each
crossing back onto the surface (:mod:`.result`, where the step and its bounds are described).

``max_points`` stops the integration: the trajectory is propagated in segments of a number of
steps (:func:`section`: 64 first when there is a ``progress`` to ask, else as many as ``max_points``
crossings may need; then at most 20 000 and not much beyond where the crossing rate
so far puts the ``max_points``-th crossing, and with a ``progress`` to ask, about 1 % of
``t_final`` but at least 256 steps; no step is cut short at a segment's end, so the steps are those
of one uninterrupted propagation; :func:`section_batch`: segments of 1 % of ``t_final`` in time,
in pieces of at most 20 000 steps); after each one the crossings are counted and ``progress`` is
asked whether to go on. No Python callback runs at every step.

The τ of a crossing is the integrated reduced time ``dτ = ρ dt`` (paper eq. 2604-5 for the ball).

Measures reported per section: the largest ``|S(x) − value|`` at the points relative to the
surface's scale (:func:`surface_scale_of`), and the largest relative drift of every first integral
at the points against the initial state, normalised as in :mod:`nonholonomic.evidence.integrals`.

Layout: this module is the front door (:func:`section`, :func:`section_batch`: the segment loop,
scalar and batch, with its segment lengths and stall checks); every name below is importable from here.

* :mod:`.surface`: parsing a surface (:func:`parse_surface`, :class:`SurfaceError`), its
  names and its compiled kernels, :func:`surface_scale_of`;
* :mod:`.request`: the checks of a request's fields (:data:`DIRECTIONS`,
  :data:`MAX_POINTS_LIMIT`);
* :mod:`.events`: the compiled integrators with the event, once per process and copied
  once per thread, and the callbacks that record the crossings;
* :mod:`.result`: the :class:`Section` and the post-processing (the Newton step onto the
  surface, points, coordinates, residual, drift).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import heyoka as hy
import numpy as np

from nonholonomic.analysis.poincare.events import _BatchCrossings, _Crossings, _integrator
from nonholonomic.analysis.poincare.request import (
    DIRECTIONS,
    MAX_POINTS_LIMIT,
    _check_arrays,
    _Request,
    _validate,
)
from nonholonomic.analysis.poincare.result import NEWTON_BOUND, Section, _finish  # noqa: F401 (NEWTON_BOUND: re-exported)
from nonholonomic.analysis.poincare.surface import (
    SurfaceError,
    default_coordinates,
    parse_surface,
    surface_names,
    surface_scale_of,
)
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import (
    MACHINE_EPSILON,
    IntegrationCancelled,
    IntegrationError,
    ProgressCallback,
)
from nonholonomic.numerics.taylor import TaylorSystem

__all__ = [
    "DIRECTIONS",
    "MAX_POINTS_LIMIT",
    "Section",
    "SurfaceError",
    "default_coordinates",
    "parse_surface",
    "section",
    "section_batch",
    "surface_names",
    "surface_scale_of",
]

#: Propagation segments: at least this many steps each ...
SEGMENT_MIN_STEPS = 256
#: ... at most this many (bounds the time between two progress calls) ...
SEGMENT_MAX_STEPS = 20_000
#: ... and otherwise this fraction of ``t_final``.
SEGMENT_FRACTION = 0.01
#: The first segment of :func:`section` (steps): its step size and crossing rate size the next ones.
FIRST_SEGMENT_STEPS = 64


def _next_segment(t_final: float, t_now: float, steps: float, crossings: int, remaining: int) -> float:
    """Length of the next propagation segment of :func:`section_batch` (see the module docstring)."""
    mean_h = t_now / steps if steps > 0 else t_final
    seg = min(max(SEGMENT_FRACTION * t_final, SEGMENT_MIN_STEPS * mean_h), SEGMENT_MAX_STEPS * mean_h)
    if crossings > 0:  # do not run far past the max_points-th crossing
        seg = min(seg, max(1.25 * remaining * t_now / crossings, SEGMENT_MIN_STEPS * mean_h / 4))
    return seg


def _next_steps(t_final: float, t_now: float, steps: int, crossings: int, remaining: int, reporting: bool) -> int:
    """Steps of the next segment of :func:`section` (``steps``: the steps so far): at most
    :data:`SEGMENT_MAX_STEPS`; not much beyond where the crossing rate so far puts the ``max_points``-th
    crossing (before the first crossing, as many steps as so far); with a ``progress`` to call, about
    :data:`SEGMENT_FRACTION` of ``t_final`` at the mean step so far, at least :data:`SEGMENT_MIN_STEPS`."""
    seg = 1.25 * remaining * steps / crossings if crossings > 0 else float(steps)
    if reporting and t_now > 0:
        seg = min(seg, max(SEGMENT_FRACTION * t_final * steps / t_now, SEGMENT_MIN_STEPS))
    return int(min(max(seg, SEGMENT_MIN_STEPS / 4), SEGMENT_MAX_STEPS))


_GOOD = (hy.taylor_outcome.time_limit, hy.taylor_outcome.success)
_GOING = (hy.taylor_outcome.time_limit, hy.taylor_outcome.step_limit)

#: Runtime parameter vectors computed lately, by (TaylorSystem identity, parameter bytes).
_runtime_by_key: dict[tuple[int, bytes], tuple[TaylorSystem, np.ndarray]] = {}


def _runtime_parameters(ts: TaylorSystem, p: np.ndarray) -> np.ndarray:
    """``ts.runtime_parameters(p)``, remembered for the parameter vectors used lately: computing the
    derived parameters costs tens of microseconds, a large share of a short section, and a service
    asks for sections of the same system with the same parameters again and again."""
    key = (id(ts), p.tobytes())
    hit = _runtime_by_key.get(key)
    if hit is None or hit[0] is not ts:
        if len(_runtime_by_key) >= 256:
            _runtime_by_key.clear()
        runtime = ts.runtime_parameters(p)
        runtime.flags.writeable = False  # shared by every call with these parameters
        hit = _runtime_by_key[key] = (ts, runtime)
    return hit[1]


#: A piece of steps that gains less than this many ``eps·max(|t|, 1)`` per step has stalled.
STALL_STEP_ULPS = 1024.0


def _stalled_at(before: float, after: float, steps: int = SEGMENT_MAX_STEPS) -> bool:
    """Whether a piece of ``steps`` steps from ``before`` to ``after`` stalled: steps at the rounding of ``t``
    (an event function not finite or not smooth where the orbit is: heyoka's steps shrink to nothing and
    never get past it)."""
    return after - before <= steps * STALL_STEP_ULPS * MACHINE_EPSILON * max(abs(after), 1.0)


def _stalled(t: float) -> str:
    return (f"heyoka's steps shrank to nothing at t = {t:g}: the surface is not finite or not smooth where the "
            "orbit meets it (e.g. sqrt or a fractional power at 0), so its crossings cannot be located")


# --------------------------------------------------------------------------------------------------
# Entry points
# --------------------------------------------------------------------------------------------------

def section(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_state: np.ndarray,
    t_final: float,
    surface: str,
    *,
    value: float = 0.0,
    direction: str = "increasing",
    coordinates: Sequence[str] | None = None,
    max_points: int = 10_000,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> Section:
    """The Poincaré section of the trajectory from ``initial_state`` on ``surface = value`` for 0 ≤ t ≤ ``t_final``.

    Parameters
    ----------
    system : the symbolic definition (e.g. ``get_system("chaplygin_ball", "zero")``).
    parameters : in the order of ``system.parameter_symbols``.
    initial_state : in the order of ``system.state_symbols``.
    t_final : end time (> 0).
    surface : expression text (see :func:`parse_surface`), e.g. ``"gamma3"``.
    value : the level of the section.
    direction : one of :data:`DIRECTIONS`.
    coordinates : two component names (state or derived) to report as ``coordinates``; default
        :func:`default_coordinates`.
    max_points : stop integrating once this many crossings are recorded (≤ :data:`MAX_POINTS_LIMIT`);
        the section then has ``stopped_early`` and a warning, it is not an error.
    tolerance : heyoka's tolerance (default machine epsilon).
    progress : called with the fraction of ``t_final`` reached after each propagation segment;
        returning False cancels (:class:`IntegrationCancelled`).

    Raises
    ------
    SurfaceError
        A refused field (``.field``, ``.reason``, ``.position``); a :class:`ValueError`.
    IntegrationError
        The integration failed before ``t_final`` (non-finite state ...).
    IntegrationCancelled
    """
    req = _validate(system, surface, value, direction, coordinates, max_points, t_final, tolerance)
    p = np.asarray(parameters, dtype=float)
    y0 = np.asarray(initial_state, dtype=float)
    if p.ndim != 1:
        raise SurfaceError("parameters", f"must be one vector, got shape {p.shape}")
    if y0.ndim != 1:
        raise SurfaceError("initial_state", f"must be one vector, got shape {y0.shape}")
    _check_arrays(system, p, y0)
    ta, crossings = _integrator(req.prep, req.direction, req.tolerance)
    assert isinstance(crossings, _Crossings)  # the scalar integrator's event callback (batch = 0)
    ts = req.prep.ts
    n_vars = len(ts.variables)

    start = time.perf_counter()
    runtime = _runtime_parameters(ts, p)
    ta.time = 0.0
    ta.state[: ts.n_state] = y0
    ta.state[ts.n_state:] = 0.0  # τ
    ta.pars[: ts.n_pars] = runtime
    ta.pars[ts.n_pars] = req.value
    crossings.reset(n_vars, req.max_points)
    steps, iterations, max_h = 0, 0, 0.0
    stopped_early = False
    # Segments of a number of steps (no step cut short at their ends: the steps are those of one
    # uninterrupted propagation), each one propagate_until call, with the checks between them.
    # the first segment: short with a progress to ask; else as long as max_points crossings may need
    seg = FIRST_SEGMENT_STEPS if progress is not None else _next_steps(req.t_final, 0.0, 1, 1, req.max_points, False)
    while True:
        before = ta.time
        outcome, _, seg_max_h, nsteps, _, _ = ta.propagate_until(req.t_final, max_steps=seg)
        steps += nsteps
        iterations += seg  # a segment cut by its step limit made seg iterations (empty steps are not counted)
        if math.isfinite(seg_max_h):
            max_h = max(max_h, abs(seg_max_h))
        if outcome not in _GOING:
            raise IntegrationError(f"heyoka stopped at t = {ta.time:g} with outcome {outcome.name}")
        t_now = ta.time
        reached = outcome == hy.taylor_outcome.time_limit
        if crossings.count >= req.max_points and (not reached or crossings.seen > crossings.count):
            stopped_early = True
        done = stopped_early or reached
        # an event function not finite or not smooth at the orbit: heyoka takes empty steps forever
        if not done and seg >= SEGMENT_MIN_STEPS and _stalled_at(before, t_now, seg):
            raise IntegrationError(_stalled(t_now))
        if progress is not None and not progress(min(t_now / req.t_final, 1.0)) and not done:
            raise IntegrationCancelled(f"cancelled at t = {t_now:g}")
        if done:
            break
        seg = _next_steps(req.t_final, t_now, iterations, crossings.seen, req.max_points - crossings.count,
                          progress is not None)
    return _finish(req, runtime, y0, *crossings.arrays(), max_h, stopped_early, steps, start)


def section_batch(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_states: np.ndarray,
    t_final: float,
    surface: str,
    *,
    value: float = 0.0,
    direction: str = "increasing",
    coordinates: Sequence[str] | None = None,
    max_points: int = 10_000,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> list[Section | IntegrationError]:
    """:func:`section` for many members at once with heyoka's batch mode.

    Members are integrated ``hy.recommended_simd_size()`` at a time (``taylor_adaptive_batch`` with
    an ``nt_event_batch``; the last batch is padded with copies of a member whose results are
    dropped). Each member gets its own :class:`Section` or, if its integration fails, the
    :class:`IntegrationError` in its place: heyoka halts every lane when one fails, so the failed
    lane is replaced by a copy of a healthy one (discarded) and the others resume where they were;
    their results are those of an uninterrupted run. A member reaching ``max_points`` stops
    recording; its lane runs on until the batch ends (its steps are not counted).

    Parameters
    ----------
    parameters : shape ``(n_members, n_parameters)``, or one vector shared by every member.
    initial_states : shape ``(n_members, dimension)``.
    progress : called with the fraction of the whole work done after each segment of each batch.
    Other parameters as for :func:`section`.

    Returns
    -------
    list of Section or IntegrationError, one per member in order. ``wall_time_s`` of a member is its
    share of its batch's wall time.

    Raises
    ------
    SurfaceError, IntegrationCancelled
    """
    req = _validate(system, surface, value, direction, coordinates, max_points, t_final, tolerance)
    Y = np.asarray(initial_states, dtype=float)
    if Y.ndim != 2 or len(Y) == 0:
        raise SurfaceError("initial_state", f"must have shape (n_members, {system.dimension}), got {Y.shape}")
    P = np.asarray(parameters, dtype=float)
    if P.ndim == 1:
        P = np.broadcast_to(P, (len(Y), len(P)))
    if P.ndim != 2 or len(P) != len(Y):
        raise SurfaceError("parameters", f"must have shape ({len(Y)}, n_parameters), got {P.shape}")
    _check_arrays(system, P, Y)
    batch = hy.recommended_simd_size()
    ta, recorder = _integrator(req.prep, req.direction, req.tolerance, batch)
    assert isinstance(recorder, _BatchCrossings)  # the batch integrator's event callback (batch > 0)
    n_groups = -(-len(Y) // batch)
    results: list[Section | IntegrationError] = []
    for g in range(n_groups):
        members = list(range(g * batch, min((g + 1) * batch, len(Y))))
        lane_progress = None if progress is None else (
            lambda fraction, g=g: progress((g + fraction) / n_groups))
        results.extend(_run_batch(req, ta, recorder, P[members], Y[members], lane_progress))
    return results


def _run_batch(req: _Request, ta: hy.taylor_adaptive_batch, recorder: _BatchCrossings, P: np.ndarray,
               Y: np.ndarray, progress: ProgressCallback | None) -> list[Section | IntegrationError]:
    """Integrate up to one batch of members (``len(Y) <= batch``)."""
    ts = req.prep.ts
    batch = ta.batch_size
    real = len(Y)
    lanes = list(range(real)) + [real - 1] * (batch - real)  # padding lanes copy the last member
    n_vars = len(ts.variables)

    start = time.perf_counter()
    ta.set_time(np.zeros(batch))
    ta.state[:] = np.stack([ts.initial(Y[m]) for m in lanes], axis=1)
    pars = np.empty((ts.n_pars + 1, batch))
    pars[: ts.n_pars] = ts.runtime_parameters(P[lanes].T)
    pars[ts.n_pars] = req.value
    ta.pars[:] = pars
    recorder.reset(n_vars, [req.max_points if i < real else 0 for i in range(batch)])
    failed: dict[int, IntegrationError] = {}
    early_at: dict[int, bool] = {}
    steps = np.zeros(batch, dtype=np.int64)
    max_h = np.zeros(batch)
    t_now = 0.0
    seg = SEGMENT_FRACTION * req.t_final

    def active(i: int) -> bool:
        return i < real and i not in failed and i not in early_at

    while any(active(i) for i in range(batch)):
        t_next = req.t_final if t_now + 1.001 * seg >= req.t_final else t_now + seg
        while True:  # until every lane reaches t_next; a failing lane is replaced and the rest resume
            before = np.array(ta.time)
            ta.propagate_until(t_next, max_steps=SEGMENT_MAX_STEPS)  # bounded: progress is asked in between
            bad, going = [], False
            for i, (outcome, _, lane_max_h, nsteps) in enumerate(ta.propagate_res):
                if active(i):
                    steps[i] += nsteps
                    if math.isfinite(lane_max_h):
                        max_h[i] = max(max_h[i], abs(lane_max_h))
                if outcome == hy.taylor_outcome.step_limit and _stalled_at(float(before[i]), float(ta.time[i])):
                    bad.append((i, _stalled(float(ta.time[i]))))
                elif outcome == hy.taylor_outcome.step_limit:
                    going = True
                elif outcome not in _GOOD:
                    bad.append((i, f"heyoka stopped between t = {t_now:g} and {t_next:g} with outcome {outcome.name}"))
            if going and not bad and progress is not None and not progress(float(np.min(ta.time)) / req.t_final):
                raise IntegrationCancelled(f"cancelled at t = {float(np.min(ta.time)):g}")
            if not bad:
                if going:
                    continue
                break
            times_hi, times_lo = (np.array(a) for a in ta.dtime)
            for i, reason in bad:
                if active(i):
                    failed[i] = IntegrationError(reason)
                recorder.lanes[i].capacity = 0  # from now on a dummy lane: its crossings are dropped
            healthy = [i for i in range(batch) if i not in {b for b, _ in bad}]
            if not healthy:
                break
            donor = healthy[0]
            state, lane_pars = np.array(ta.state), np.array(ta.pars)
            for i, _ in bad:
                times_hi[i], times_lo[i] = times_hi[donor], times_lo[donor]
                state[:, i], lane_pars[:, i] = state[:, donor], lane_pars[:, donor]
            ta.set_dtime(times_hi, times_lo)
            ta.state[:] = state
            ta.pars[:] = lane_pars
        if not any(active(i) for i in range(batch)):
            break
        t_now = t_next
        for i in range(real):
            lane = recorder.lanes[i]
            if active(i) and lane.count >= req.max_points and (t_now < req.t_final or lane.seen > lane.count):
                early_at[i] = True
                lane.capacity = lane.count  # stop recording
        done = t_now >= req.t_final or not any(active(i) for i in range(batch))
        if progress is not None and not progress(t_now / req.t_final) and not done:
            raise IntegrationCancelled(f"cancelled at t = {t_now:g}")
        if done:
            break
        alive = [i for i in range(batch) if active(i)]
        if alive:
            seen = min(recorder.lanes[i].seen for i in alive)
            remaining = max(req.max_points - recorder.lanes[i].count for i in alive)
            seg = _next_segment(req.t_final, t_now, float(np.mean(steps[alive])), seen, remaining)

    share = 1.0 / real
    out: list[Section | IntegrationError] = []
    for i in range(real):
        if i in failed:
            out.append(failed[i])
            continue
        lane = recorder.lanes[i]
        out.append(_finish(req, pars[: ts.n_pars, i], Y[i], *lane.arrays(), max_h[i], i in early_at, int(steps[i]),
                           start, share))
    return out
