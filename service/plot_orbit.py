"""The orbit a trajectory plot draws: the job's own integration again, sampled densely.

A job stores ``samples`` equally spaced states (201 by default), whatever the length of the run: a
long orbit drawn through them is a polygon of chords. :func:`dense_orbit` integrates the job's
request again from the result's own initial state (after any projection), with the same engine and
tolerance, and asks the integrator's dense output (heyoka's Taylor polynomials in ``propagate_grid``,
scipy's ``dense_output``) for the states on a fine grid. The accepted steps do not depend on the
sample times, so the same request gives the same orbit: the grid holds every stored sample time,
and the dense curve is checked to pass through the stored samples (within
:data:`MATCH_TOLERANCE`, relative to the orbit's size) before it is drawn; if it does not, or the
request cannot be integrated again, the stored samples are drawn and the title says why.

How dense: every interval between stored samples is cut into equal parts, about :data:`START_POINTS`
points in all at first, then refined once so that the largest *sagitta*
of the drawn polylines (the distance of a point from the chord of its two neighbours, relative to
the curve's extent, the quantity a reader sees as a corner) is at most :data:`SAGITTA_TARGET`;
the sagitta of a smooth curve falls as 1/N², so one refinement nearly always suffices (at most
:data:`REFINEMENTS`). At most
:data:`MAX_POINTS` points and :data:`TIME_BUDGET_S` of integration (checked between the integrator's
segments; beyond it the stored samples are drawn, and that image is not cached; no refinement after
half of it). The budget covers the integration only: rebuilding the system and compiling its
integrator come first (from the memo and heyoka's disk cache once a process has seen the system).
Dense orbits are remembered for the last :data:`CACHE_SIZE` requests (the PNG and the SVG share one).
Everything here is deterministic: the same result draws the same points.
"""

from __future__ import annotations

import hashlib
import json
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

#: Points of the first dense grid (or the stored samples, when they are more).
START_POINTS = 2001
#: Most points of a drawn orbit (the grid of the refinement is capped here).
MAX_POINTS = 20_000
#: Largest sagitta of a drawn polyline relative to its extent (about half a pixel of a 500 px panel).
SAGITTA_TARGET = 5e-4
#: Refinements of the grid at most (each from the sagitta of the last; one is nearly always enough).
REFINEMENTS = 3
#: Wall time the dense integration may take; beyond it the stored samples are drawn.
TIME_BUDGET_S = 5.0
#: Largest distance, relative to the orbit's extent, between the dense curve and a stored sample.
MATCH_TOLERANCE = 1e-9
#: Dense orbits remembered (by request and initial state).
CACHE_SIZE = 8


@dataclass(frozen=True)
class Orbit:
    """States of the orbit at ``t`` (``vectors``: every state vector by name, ``(len(t), k)``).

    ``dense`` says whether they come from the dense output (else they are the stored samples);
    ``sagitta`` is the largest relative sagitta of the drawn curves; ``note`` says in words how the
    orbit was sampled (for the plot's title); ``stored_deviation`` is the largest distance between the
    dense curve and the stored samples at their times, relative to the extent (0 for the samples).
    """

    t: np.ndarray
    vectors: dict[str, np.ndarray]
    dense: bool
    sagitta: float
    note: str
    stored_deviation: float = 0.0
    cut_short: bool = False  # the stored samples because the time budget ran out: a busy machine, not the job


class TransientImage(bytes):
    """A rendered plot not to be cached: drawn from the stored samples because the dense output ran past
    its time budget (a loaded machine), so a later request may draw the dense orbit."""


class _Slow(RuntimeError):
    """The dense integration ran past :data:`TIME_BUDGET_S`."""


_cache: OrderedDict[str, Orbit] = OrderedDict()
_cache_lock = threading.Lock()


def sagitta(curve: np.ndarray) -> float:
    """Largest distance of a point of the polyline ``curve`` (``(n, d)``) from the chord through its two
    neighbours, relative to the curve's extent (the largest ``ptp`` of a coordinate); 0 for < 3 points."""
    curve = np.asarray(curve, dtype=float)
    if len(curve) < 3:
        return 0.0
    extent = float(np.max(np.ptp(curve, axis=0)))
    if not extent > 0:
        return 0.0
    a, b, c = curve[:-2], curve[1:-1], curve[2:]
    chord, offset = c - a, b - a
    length2 = np.einsum("ij,ij->i", chord, chord)
    along = np.divide(np.einsum("ij,ij->i", offset, chord), length2, out=np.zeros(len(chord)), where=length2 > 0)
    along = np.clip(along, 0.0, 1.0)
    distance = np.linalg.norm(offset - along[:, None] * chord, axis=1)
    return float(np.max(distance)) / extent


def drawn_sagitta(t: np.ndarray, vectors: Mapping[str, np.ndarray], names: Sequence[str]) -> float:
    """The largest relative sagitta of what a trajectory plot draws: the first vector of ``names`` as a
    curve in its space, each component of the others against t (t and the values scaled to a unit box)."""
    worst = sagitta(vectors[names[0]])
    span = float(t[-1] - t[0]) or 1.0
    for name in names[1:]:
        values = vectors[name]
        scale = float(np.max(np.ptp(values, axis=0))) if values.size else 0.0
        if not scale > 0:
            continue
        for k in range(values.shape[1]):
            worst = max(worst, sagitta(np.column_stack([(t - t[0]) / span, values[:, k] / scale])))
    return worst


def stored_orbit(result: Mapping[str, Any], names: Sequence[str], why: str | None = None,
                 cut_short: bool = False) -> Orbit:
    """The job's stored samples as the orbit (``why``: the reason no dense output is drawn; ``cut_short``:
    the reason is the time budget)."""
    trajectory = result["trajectory"]
    t = np.asarray(trajectory["t"], dtype=float)
    vectors = {n: np.asarray(trajectory[n], dtype=float).reshape(len(t), -1) for n in names if trajectory.get(n)}
    worst = drawn_sagitta(t, vectors, [n for n in names if n in vectors]) if names and names[0] in vectors else 0.0
    note = f"{len(t)} stored samples" + (f" ({why})" if why else "")
    return Orbit(t, vectors, False, worst, note, cut_short=cut_short)


def _key(result: Mapping[str, Any], request: Mapping[str, Any], names: Sequence[str]) -> str:
    """The cache key: what decides the orbit (the request, the initial state, the stored samples drawn)."""
    trajectory = result["trajectory"]
    digest = hashlib.sha256(json.dumps([request, result.get("initial_state"), list(names)], sort_keys=True,
                                       default=str).encode())
    for name in ("t", *names):
        digest.update(np.asarray(trajectory.get(name) or [], dtype=float).tobytes())
    return digest.hexdigest()


def dense_orbit(result: Mapping[str, Any], request: Mapping[str, Any], names: Sequence[str],
                window: tuple[float, float] | None = None) -> Orbit:
    """The orbit of a job's result for its trajectory plot, densely sampled (see the module's doc).

    Parameters
    ----------
    result, request : the job's ``result`` (with its ``trajectory``) and ``request``.
    names : the state vectors the plot draws, the curve first (``["gamma", "M"]``).
    window : ``(t_from, t_to)``: only that stretch, as densely as the whole run would be (the integration
        still starts at t = 0; only the stored sample intervals the window meets are cut finer).

    Returns
    -------
    Orbit
        The dense orbit (of the window), or the stored samples (in the window) with the reason when it cannot
        be had.
    """
    key = _key(result, request, names) + ("" if window is None else f"|{window[0]!r},{window[1]!r}")
    with _cache_lock:
        if key in _cache:
            _cache.move_to_end(key)
            return _cache[key]
    orbit = _compute(result, request, names, window)
    if orbit.dense:  # the stored samples are cheap to draw again, and a budget's fallback must not stay
        with _cache_lock:
            _cache[key] = orbit
            while len(_cache) > CACHE_SIZE:
                _cache.popitem(last=False)
    return orbit


def window_of(orbit: Orbit, window: tuple[float, float]) -> Orbit:
    """The part of ``orbit`` with ``t_from <= t <= t_to`` (the stored samples' fallback cut to the window)."""
    keep = (orbit.t >= window[0]) & (orbit.t <= window[1])
    return replace(orbit, t=orbit.t[keep], vectors={n: v[keep] for n, v in orbit.vectors.items()})


def _compute(result: Mapping[str, Any], request: Mapping[str, Any], names: Sequence[str],
             window: tuple[float, float] | None = None) -> Orbit:
    stored_t = np.asarray(result["trajectory"]["t"], dtype=float)
    if window is None:
        cut = np.ones(max(len(stored_t) - 1, 1), dtype=bool)  # which stored intervals are cut finer
    else:
        cut = (stored_t[1:] > window[0]) & (stored_t[:-1] < window[1])  # the intervals the window meets
        cut = cut[:int(np.flatnonzero(cut).max()) + 1] if cut.any() else cut[:0]  # the grid ends with the window

    def fallback(why: str | None = None, cut_short: bool = False) -> Orbit:
        orbit = stored_orbit(result, names, why, cut_short)
        return orbit if window is None else window_of(orbit, window)

    intervals = int(cut.sum())
    if len(stored_t) < 2 or intervals == 0:
        return fallback()
    most = (MAX_POINTS - 1) // intervals  # the most points per stored interval
    if most < 2:
        return fallback()  # already as dense as a plot draws
    try:
        rerun = _Rerun(result, request, names)
    except Exception as exc:  # noqa: BLE001  (any reason: the plot still draws the samples)
        return fallback(f"no dense output: {_reason(exc)}")
    start = time.perf_counter()

    def states(per: int) -> tuple[np.ndarray, dict[str, np.ndarray], float]:
        t, vectors, deviation = rerun.states(np.where(cut, per, 1), start)
        if window is not None:
            keep = (t >= window[0]) & (t <= window[1])
            t, vectors = t[keep], {n: v[keep] for n, v in vectors.items()}
        return t, vectors, deviation

    try:
        per = min(most, max(2, math.ceil((START_POINTS - 1) / intervals)))
        t, vectors, deviation = states(per)
        worst = drawn_sagitta(t, vectors, names)
        for _ in range(REFINEMENTS):
            if worst <= SAGITTA_TARGET or per >= most or time.perf_counter() - start > TIME_BUDGET_S / 2:
                break
            per = min(most, math.ceil(per * math.sqrt(worst / SAGITTA_TARGET) * 1.1))  # sagitta ~ 1/N²
            t, vectors, deviation = states(per)
            worst = drawn_sagitta(t, vectors, names)
    except _Slow:
        return fallback(f"the dense output took more than {TIME_BUDGET_S:g} s", cut_short=True)
    except Exception as exc:  # noqa: BLE001
        return fallback(f"no dense output: {_reason(exc)}")
    if not deviation <= MATCH_TOLERANCE:
        return fallback(f"the integration again is {deviation:.1e} off the stored samples")
    capped = f" (capped at {MAX_POINTS})" if worst > SAGITTA_TARGET and per >= most else ""
    inside = int(np.count_nonzero((stored_t >= t[0]) & (stored_t <= t[-1]))) if len(t) else 0
    note = f"dense output at {len(t)} times{capped}, through the {inside} stored samples"
    return Orbit(t, vectors, True, worst, note, deviation)


def _reason(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return text if len(text) <= 80 else text[:77] + "..."


class _Rerun:
    """The job's integration, ready to run again on any grid that holds the stored sample times."""

    def __init__(self, result: Mapping[str, Any], request: Mapping[str, Any], names: Sequence[str]) -> None:
        from nonholonomic.initial_state import vector_slice
        from nonholonomic.numerics.kernels import parameter_vector, state_vector
        from schemas.jobs import JobRequest

        job = JobRequest.model_validate(request)
        self.system = job.system.definition()
        p = parameter_vector(self.system, dict(job.system.parameter_values()))
        state = {v.name: result["initial_state"][v.name] for v in self.system.state}
        self.p, self.y0 = p, state_vector(self.system, state, p)
        self.engine, self.tolerance = job.integrator.engine, job.integrator.tolerance
        trajectory = result["trajectory"]
        self.stored_t = np.asarray(trajectory["t"], dtype=float)
        self.t_final = float(self.stored_t[-1])
        self.slices = {n: vector_slice(self.system, n) for n in names}
        self.stored = {n: np.asarray(trajectory[n], dtype=float).reshape(len(self.stored_t), -1) for n in names}

    def states(self, per: np.ndarray, start: float) -> tuple[np.ndarray, dict[str, np.ndarray], float]:
        """The orbit with stored sample interval ``i`` cut into ``per[i]`` equal parts (the stored times among
        the grid's, exactly; the grid ends at the last interval ``per`` names), and the largest relative
        distance from the stored samples. The integration stops (:class:`_Slow`) when it runs past
        :data:`TIME_BUDGET_S` from ``start`` (checked between its segments: a short run, under
        ``FIRST_SEGMENT_STEPS`` steps, is one segment and always ends)."""
        from nonholonomic.numerics.integration import integrate

        m = len(per)
        t = self.stored_t[:m + 1]
        grid = np.append(np.concatenate([t[i] + (t[i + 1] - t[i]) * (np.arange(k) / k) for i, k in enumerate(per)]),
                         t[-1])

        def in_time(_: float) -> bool:
            if time.perf_counter() - start > TIME_BUDGET_S:
                raise _Slow
            return True

        trajectory = integrate(self.system, self.p, self.y0, float(t[-1]), len(grid), engine=self.engine,
                               tolerance=self.tolerance, progress=in_time, times=grid)
        vectors = {n: trajectory.states[:, s] for n, s in self.slices.items()}
        at = np.concatenate([[0], np.cumsum(per)])
        deviation = 0.0
        for name, values in vectors.items():
            stored = self.stored[name][:m + 1]
            extent = max(float(np.max(np.abs(self.stored[name]))), float(np.max(np.ptp(self.stored[name], axis=0))))
            extent = extent if extent > 0 else 1.0
            deviation = max(deviation, float(np.max(np.abs(values[at] - stored))) / extent)
        return grid, vectors, deviation
