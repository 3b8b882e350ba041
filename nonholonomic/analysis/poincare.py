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

The event time reaches Python rounded to a double, so the dense-output state is off the exact
root by up to half an ulp of ``t`` (``|f|·ulp(t)/2``, ~1e-13 at t ~ 1000). One Newton step along
the flow, done for all crossings at once with the numpy kernels,
``δ = −(S(x) − value)/(∇S·f)``, ``x ← x + f(x) δ``, ``t ← t + δ``, ``τ ← τ + ρ δ``, moves each point
back onto the surface (``δ`` is accepted only while it is at the level of that rounding; a
nearly tangent crossing keeps its unrefined point and a warning says so).

``max_points`` stops the integration: the trajectory is propagated in segments (1 % of
``t_final``, but at least 256 and at most 20 000 steps, and not much beyond where the crossing
rate so far puts the ``max_points``-th crossing); after each one the crossings are counted and
``progress`` is asked whether to go on. No Python callback runs at every step.

The τ of a crossing is the integrated reduced time ``dτ = ρ dt`` (paper eq. 2604-5 for the ball).

Measures reported per section: the largest ``|S(x) − value|`` at the points relative to the
surface's scale (:func:`surface_scale_of`), and the largest relative drift of every first integral
at the points against the initial state, normalised as in :mod:`nonholonomic.evidence.integrals`.

Layout: this module is the front door (:func:`section`, :func:`section_batch`: the segment loop,
scalar and batch, with its segment lengths and stall checks); every name below is importable from here.

* :mod:`.poincare_surface`: parsing a surface (:func:`parse_surface`, :class:`SurfaceError`), its
  names and its numpy kernels, :func:`surface_scale_of`;
* :mod:`.poincare_request`: the checks of a request's fields (:data:`DIRECTIONS`,
  :data:`MAX_POINTS_LIMIT`);
* :mod:`.poincare_events`: the compiled integrators with the event, once per process and copied
  once per thread, and the callbacks that record the crossings;
* :mod:`.poincare_result`: the :class:`Section` and the post-processing (the Newton step onto the
  surface, points, coordinates, residual, drift).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import heyoka as hy
import numpy as np

from nonholonomic.analysis.poincare_events import _BatchCrossings, _integrator
from nonholonomic.analysis.poincare_request import (
    DIRECTIONS,
    MAX_POINTS_LIMIT,
    _check_arrays,
    _Request,
    _validate,
)
from nonholonomic.analysis.poincare_result import NEWTON_BOUND, Section, _finish  # noqa: F401 (NEWTON_BOUND: re-exported)
from nonholonomic.analysis.poincare_surface import (
    SurfaceError,
    default_coordinates,
    parse_surface,
    surface_names,
    surface_scale_of,
)
from nonholonomic.definition import MechanicalSystem
from nonholonomic.integration import (
    MACHINE_EPSILON,
    IntegrationCancelled,
    IntegrationError,
    ProgressCallback,
)

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


def _next_segment(t_final: float, t_now: float, steps: float, crossings: int, remaining: int) -> float:
    """Length of the next propagation segment (see the module docstring)."""
    mean_h = t_now / steps if steps > 0 else t_final
    seg = min(max(SEGMENT_FRACTION * t_final, SEGMENT_MIN_STEPS * mean_h), SEGMENT_MAX_STEPS * mean_h)
    if crossings > 0:  # do not run far past the max_points-th crossing
        seg = min(seg, max(1.25 * remaining * t_now / crossings, SEGMENT_MIN_STEPS * mean_h / 4))
    return seg


_GOOD = (hy.taylor_outcome.time_limit, hy.taylor_outcome.success)


#: A piece of SEGMENT_MAX_STEPS steps that gains less than this many ``eps·max(|t|, 1)`` per step has stalled.
STALL_STEP_ULPS = 1024.0


def _stalled_at(before: float, after: float) -> bool:
    """Whether a piece of :data:`SEGMENT_MAX_STEPS` steps from ``before`` to ``after`` stalled: steps at the
    rounding of ``t`` (an event function not finite or not smooth where the orbit is: heyoka's steps
    shrink to nothing and never get past it)."""
    return after - before <= SEGMENT_MAX_STEPS * STALL_STEP_ULPS * MACHINE_EPSILON * max(abs(after), 1.0)


def _stalled(t: float) -> str:
    return (f"heyoka's steps shrank to nothing at t = {t:g}: the surface is not finite or not smooth where the "
            "orbit meets it (e.g. sqrt or a fractional power at 0), so its crossings cannot be located")


def _propagate(ta: hy.taylor_adaptive, t_next: float, t_final: float,
               progress: ProgressCallback | None) -> tuple[hy.taylor_outcome, float, int]:
    """``propagate_until(t_next)`` in pieces of at most :data:`SEGMENT_MAX_STEPS` steps, asking ``progress``
    between them (a cancellation or a time limit acts within one piece). Returns the outcome, the largest
    step and the steps taken. An event function that is not finite at the orbit makes heyoka take empty
    steps forever: a piece that gains (next to) no time raises :class:`IntegrationError`."""
    steps, max_h = 0, 0.0
    while True:
        before = ta.time
        outcome, _, piece_max_h, nsteps, _, _ = ta.propagate_until(t_next, max_steps=SEGMENT_MAX_STEPS)
        steps += nsteps
        if math.isfinite(piece_max_h):
            max_h = max(max_h, abs(piece_max_h))
        if outcome != hy.taylor_outcome.step_limit:
            return outcome, max_h, steps
        if _stalled_at(before, ta.time):
            raise IntegrationError(_stalled(ta.time))
        if progress is not None and not progress(min(ta.time / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {ta.time:g}")



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
    ts = req.prep.ts
    n_vars = len(ts.variables)

    start = time.perf_counter()
    ta.time = 0.0
    ta.state[:] = ts.initial(y0)
    ta.pars[: ts.n_pars] = ts.runtime_parameters(p)
    ta.pars[ts.n_pars] = req.value
    crossings.reset(n_vars, req.max_points)
    steps, max_h, t_now = 0, 0.0, 0.0
    stopped_early = False
    seg = SEGMENT_FRACTION * req.t_final
    while True:
        t_next = req.t_final if t_now + 1.001 * seg >= req.t_final else t_now + seg
        outcome, seg_max_h, nsteps = _propagate(ta, t_next, req.t_final, progress)
        steps += nsteps
        max_h = max(max_h, abs(seg_max_h)) if math.isfinite(seg_max_h) else max_h
        if outcome != hy.taylor_outcome.time_limit:
            raise IntegrationError(f"heyoka stopped between t = {t_now:g} and {t_next:g} with outcome "
                                   f"{outcome.name}")
        t_now = t_next
        if crossings.count >= req.max_points and (t_now < req.t_final or crossings.seen > crossings.count):
            stopped_early = True
        done = stopped_early or t_now >= req.t_final
        if progress is not None and not progress(t_now / req.t_final) and not done:
            raise IntegrationCancelled(f"cancelled at t = {t_now:g}")
        if done:
            break
        seg = _next_segment(req.t_final, t_now, steps, crossings.seen, req.max_points - crossings.count)
    count = crossings.count
    return _finish(req, p, y0, crossings.t[:count].copy(), crossings.x[:count].copy(), max_h, stopped_early,
                   steps, start)


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
        out.append(_finish(req, P[i], Y[i], lane.t[: lane.count].copy(), lane.x[: lane.count].copy(), max_h[i],
                           i in early_at, int(steps[i]), start, share))
    return out
