"""A job's trajectory plot: the geometric vector on its sphere or ellipsoid, the momentum-like vector against t.

Both are drawn through the integrator's dense output (:mod:`service.plot_orbit`). A long run drawn whole is a
scribble (t = 2000 for the ball: hundreds of turns over the sphere, M(t) a solid band), so it is drawn as a
*window* (issue 35, item 6): by default the last stretch, the last :data:`WINDOW_TURNS` turns of the geometric
vector, once the run has more than :data:`LONG_TURNS`; or the reader's ``(t_from, t_to)``. A window is drawn
in colour over the whole run's orbit in grey (where the vector goes over the whole run), and under the momentum
against t, a strip shows the whole run's envelope (each component's range in each of :data:`ENVELOPE_BUCKETS`
stretches) with the window shaded. A *turn* is arc length of the geometric vector's curve π × its extent (one
great circle of the unit sphere); counted on the dense orbit, so the same result gets the same window.
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from nonholonomic.definition import StateConstraint, StateVector
from service.plots import (
    _axis_label,
    _component_label,
    _definition,
    _geometric_vector,
    _headline,
    _momentum_vector,
    _new_figure,
    _surface_mesh,
    _symbol,
    _thin,
    _vector_samples,
)

#: A run of more turns than this is drawn as a window by default.
LONG_TURNS = 12.0
#: The default window: the last this many turns of the geometric vector.
WINDOW_TURNS = 4.0
#: Stretches of the whole run in the envelope strip (each component's min and max in each).
ENVELOPE_BUCKETS = 400
#: Characters of a title line (the figure is 11 inches wide).
TITLE_WIDTH = 150
#: Points of the whole run drawn in grey behind a window.
CONTEXT_POINTS = 5000


def turns(curve: np.ndarray) -> np.ndarray:
    """Cumulative turns along ``curve`` (``(n, d)``): arc length over π × the curve's extent (its largest
    ``ptp``), 0 at the first point."""
    extent = float(np.max(np.ptp(curve, axis=0))) if len(curve) else 0.0
    steps = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)]) / (np.pi * extent) if extent > 0 else np.zeros(len(curve))


def default_window(t: np.ndarray, curve: np.ndarray) -> tuple[float, float] | None:
    """The last :data:`WINDOW_TURNS` turns of ``curve`` sampled at ``t``, if it makes more than
    :data:`LONG_TURNS` in all; else None (the whole run)."""
    along = turns(curve)
    if not len(along) or along[-1] <= LONG_TURNS:
        return None
    start = int(np.searchsorted(along, along[-1] - WINDOW_TURNS))
    return float(t[start]), float(t[-1])


def _plane_orbit(ax: Any, g: np.ndarray, keep: np.ndarray, t: np.ndarray, geometric: StateVector,
                 units: Mapping[str, str], context: np.ndarray | None = None) -> None:
    """The orbit of a 2-component state vector (q1, q2) in its plane (over the whole run's, in grey)."""
    if context is not None:
        ax.plot(context[:, 0], context[:, 1], color="0.7", linewidth=0.4, in_layout=False, label="whole run")
    ax.plot(g[keep, 0], g[keep, 1], color="C0", linewidth=0.7, in_layout=False)
    ax.plot(*g[0], marker="o", color="C2", markersize=4, linestyle="none", label=f"t = {t[0]:g} s")
    ax.plot(*g[-1], marker="s", color="C3", markersize=4, linestyle="none", label=f"t = {t[-1]:g} s")
    names = [str(s) for s in geometric.symbols]
    ax.set_xlabel(f"{names[0]} [{units.get(geometric.name, '')}]")
    ax.set_ylabel(f"{names[1]} [{units.get(geometric.name, '')}]")
    ax.set_title(f"{_symbol(geometric.name)} = ({names[0]}, {names[1]})\n{geometric.meaning}")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")


def _space_orbit(ax3: Any, g: np.ndarray, keep: np.ndarray, t: np.ndarray, geometric: StateVector,
                 constraint: StateConstraint | None, info: Mapping[str, Any], units: Mapping[str, str],
                 context: np.ndarray | None = None) -> None:
    """The orbit of a 3-vector in space, on its sphere or ellipsoid when it has one (over the whole run's,
    in grey)."""
    mesh = _surface_mesh(constraint, info.get("parameters", {}))
    if mesh is not None:
        ax3.plot_wireframe(*mesh, color="0.55", linewidth=0.3, alpha=0.35, in_layout=False)
        extent = np.array([np.ptp(m) for m in mesh])
        ax3.set_box_aspect(tuple(extent / extent.max()))
    if context is not None:
        ax3.plot(context[:, 0], context[:, 1], context[:, 2], color="0.6", linewidth=0.3, alpha=0.6,
                 in_layout=False, label="whole run")
    ax3.plot(g[keep, 0], g[keep, 1], g[keep, 2], color="C0", linewidth=0.7, in_layout=False)
    ax3.plot(*g[0], marker="o", color="C2", markersize=4, linestyle="none", label=f"t = {t[0]:g} s")
    ax3.plot(*g[-1], marker="s", color="C3", markersize=4, linestyle="none", label=f"t = {t[-1]:g} s")
    for k, (axis, set_label) in enumerate(zip((ax3.xaxis, ax3.yaxis, ax3.zaxis),
                                               (ax3.set_xlabel, ax3.set_ylabel, ax3.set_zlabel))):
        axis.set_major_locator(MaxNLocator(5))
        set_label(_component_label(geometric, k, units))
    ax3.tick_params(labelsize=7)
    where = (f" on {constraint.formula.split(':')[0]} (eq. {constraint.equation})" if constraint else "")
    ax3.set_title(f"{_symbol(geometric.name)}{where}\n{geometric.meaning}")
    ax3.legend(loc="upper left")


def envelope(t: np.ndarray, values: np.ndarray, buckets: int = ENVELOPE_BUCKETS) -> tuple[np.ndarray, ...]:
    """``(t_mid, low, high)``: the smallest and largest of ``values`` in each of ``buckets`` stretches of equal
    numbers of samples (all of them when fewer)."""
    edges = np.unique(np.linspace(0, len(t), min(buckets, len(t)) + 1).round().astype(int))
    pieces = [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    mid = np.array([(t[a] + t[b - 1]) / 2 for a, b in pieces])
    return mid, np.array([values[a:b].min() for a, b in pieces]), np.array([values[a:b].max() for a, b in pieces])


def trajectory_figure(result: Mapping[str, Any], request: Mapping[str, Any] | None = None,
                      window: tuple[float, float] | None = None) -> Figure:
    """The trajectory plot (see the module's doc).

    Parameters
    ----------
    result, request : the job's ``result`` and ``request`` (without the request, the stored samples are drawn).
    window : ``(t_from, t_to)`` in s, the stretch drawn in colour; None: :func:`default_window` (the whole run
        for a short one). ``(0, t_final)`` draws the whole run alone.
    """
    from service.plot_orbit import MAX_POINTS, Orbit, dense_orbit, stored_orbit, window_of

    info = result["system"]
    units = info.get("units", {})
    system = _definition(info, request)
    geometric, constraint = _geometric_vector(system)
    momentum = _momentum_vector(system, geometric)
    names = [geometric.name] + ([momentum.name] if momentum is not None else [])
    _vector_samples(result["trajectory"], geometric.name)  # the samples are there, or the plot is unavailable
    rerun = bool(request and "system" in request)

    def orbit_of(stretch: tuple[float, float] | None) -> Orbit:
        if rerun:
            return dense_orbit(result, request or {}, names, stretch)
        whole = stored_orbit(result, names, "no request to integrate again")
        return whole if stretch is None else window_of(whole, stretch)

    whole = orbit_of(None)
    t_final = float(whole.t[-1])
    chosen = "the reader's window"
    if window is None:
        window = default_window(whole.t, whole.vectors[geometric.name])
        chosen = f"the last {WINDOW_TURNS:g} of {turns(whole.vectors[geometric.name])[-1]:.0f} turns"
    if window is not None and window[0] <= whole.t[0] and window[1] >= t_final:
        window = None  # the whole run, asked for
    orbit = whole if window is None else orbit_of(window)
    t = orbit.t
    g = orbit.vectors[geometric.name]
    keep = _thin(len(t), MAX_POINTS)
    context = None if window is None else whole.vectors[geometric.name][_thin(len(whole.t), CONTEXT_POINTS)]

    fig = _new_figure(11.0, 4.8 if window is None else 5.8)
    fig.nonholonomic_transient = orbit.cut_short or whole.cut_short  # type: ignore[attr-defined]  # job_plot's flag
    grid = fig.add_gridspec(1 if window is None else 2, 2, height_ratios=None if window is None else [3, 1])
    if g.shape[1] == 2:  # generalized coordinates (q1, q2): the orbit in the plane
        _plane_orbit(fig.add_subplot(grid[:, 0]), g, keep, t, geometric, units, context)
    else:
        _space_orbit(fig.add_subplot(grid[:, 0], projection="3d"), g, keep, t, geometric, constraint, info, units,
                     context)

    ax = fig.add_subplot(grid[0, 1])
    if momentum is not None and momentum.name in orbit.vectors:
        m = orbit.vectors[momentum.name]
        for k in range(m.shape[1]):
            ax.plot(t[keep], m[keep, k], linewidth=0.8, in_layout=False, label=_symbol(str(momentum.symbols[k])))
        ax.set_ylabel(_axis_label(momentum.name, units))
        ax.set_title(f"{_symbol(momentum.name)}: {momentum.meaning}")
        ax.legend(loc="upper right")
        if window is not None:
            _envelope_strip(fig.add_subplot(grid[1, 1]), whole, momentum, window, units)
    ax.set_xlabel(_axis_label("t", units))
    ax.grid(alpha=0.3)
    drawn = "" if len(keep) == len(t) else f", {len(keep)} of them drawn"
    span = (f"t in [0, {t_final:g}] {units.get('t', 's')}" if window is None else
            f"window t in [{window[0]:g}, {window[1]:g}] of [0, {t_final:g}] {units.get('t', 's')} ({chosen}; "
            f"t_from and t_to choose another)")
    fig.suptitle(_headline(info, textwrap.fill(f"trajectory, {span}: {orbit.note}{drawn}; largest chord sagitta "
                                               f"{orbit.sagitta:.0e} × extent", TITLE_WIDTH)))
    return fig


def _envelope_strip(ax: Any, whole: Any, momentum: StateVector, window: tuple[float, float],
                    units: Mapping[str, str]) -> None:
    """The whole run of the momentum-like vector as each component's range per stretch, the window shaded."""
    m = whole.vectors[momentum.name]
    for k in range(m.shape[1]):
        mid, low, high = envelope(whole.t, m[:, k])
        ax.fill_between(mid, low, high, color=f"C{k}", alpha=0.35, linewidth=0, in_layout=False)
    ax.axvspan(window[0], window[1], color="0.15", alpha=0.15, label="window")
    ax.set_xlim(float(whole.t[0]), float(whole.t[-1]))
    ax.set_xlabel(_axis_label("t", units))
    ax.set_ylabel(_axis_label(momentum.name, units), fontsize=7)
    ax.set_title(f"whole run: range of each component of {_symbol(momentum.name)} in each of "
                 f"{ENVELOPE_BUCKETS} stretches; the window shaded", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(loc="upper right", fontsize=7)
