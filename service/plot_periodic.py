"""A periodic orbit's figure: its multipliers on the complex plane (the unit circle drawn), and either its
continuation (the section map's trace against the swept parameter, the elliptic band |trace| < 2 shaded,
the folds and period doublings marked) or Newton's closing residual at each evaluation."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from nonholonomic.analysis.periodic_orbit.newton import CLOSING_TOLERANCE
from service.plots import PlotUnavailable, _headline, _new_figure

EVENT_COLOURS = {"fold": "C1", "period_doubling": "C3", "lost": "0.4"}


def periodic_orbit_figure(result: Mapping[str, Any], request: Mapping[str, Any] | None = None) -> Figure:
    """``GET /v1/jobs/{id}/plots/periodic_orbit.png``."""
    orbit = result.get("periodic_orbit")
    if not orbit:
        raise PlotUnavailable("this job asked for no periodic orbit")
    fig = _new_figure(12.0, 5.2)
    _multipliers_panel(fig.add_subplot(1, 2, 1), orbit)
    branch = orbit.get("continuation")
    if branch and branch["points"]:
        _continuation_panel(fig.add_subplot(1, 2, 2), branch)
    else:
        _newton_panel(fig.add_subplot(1, 2, 2), orbit)
    what = (f"period-{orbit['period']} orbit of the return map to {orbit['surface']} = {orbit['value']:g} "
            f"({orbit['direction']}): {orbit['status']}")
    if orbit.get("period_t") is not None and orbit["status"] != "not_found":
        what += f", T = {orbit['period_t']:.10g} s, {orbit.get('stability') or ''}"
    fig.suptitle(_headline(result["system"], what))
    return fig


def _multipliers_panel(ax: Any, orbit: Mapping[str, Any]) -> None:
    theta = np.linspace(0, 2 * np.pi, 361)
    ax.plot(np.cos(theta), np.sin(theta), color="0.6", linewidth=0.8, label="unit circle")
    trivial = orbit["multipliers"]
    section = orbit["section_multipliers"]
    if trivial:
        ax.scatter([1.0], [0.0], s=90, facecolors="none", edgecolors="0.3", linewidths=1.2,
                   label=f"{orbit['trivial_count']} trivial multipliers (= 1)")
    if section:
        re = np.array([m["re"] for m in section])
        im = np.array([m["im"] for m in section])
        ax.scatter(re, im, s=36, color="C0", zorder=3, label="the section map's multipliers")
        reach = float(max(1.3, np.max(np.abs(np.concatenate([re, im]))) * 1.15))
        if reach > 4:  # a strongly hyperbolic orbit: a log-like view would hide the circle; say the values
            for x, y in zip(re, im):
                ax.annotate(f"{x:.4g}", (x, y), textcoords="offset points", xytext=(4, 6), fontsize=8)
        ax.set_xlim(-reach, reach)
        ax.set_ylim(-reach, reach)
    elif not trivial:
        ax.text(0.5, 0.5, "no multipliers: the orbit was not closed", transform=ax.transAxes, ha="center")
    ax.set_aspect("equal")
    ax.axhline(0, color="0.85", linewidth=0.6)
    ax.axvline(0, color="0.85", linewidth=0.6)
    ax.set_xlabel("Re μ")
    ax.set_ylabel("Im μ")
    trace = orbit.get("trace")
    ax.set_title("monodromy multipliers" + (f" (trace of the section map {trace:.6g})" if trace is not None else ""),
                 fontsize=9)
    ax.legend(loc="lower left", fontsize=8)
    ax.grid(alpha=0.3)


def _continuation_panel(ax: Any, branch: Mapping[str, Any]) -> None:
    points = [p for p in branch["points"] if p["trace"] is not None]
    values = np.array([p["value"] for p in points])
    traces = np.array([p["trace"] for p in points])
    ax.axhspan(-2, 2, color="C2", alpha=0.12, label="|trace| < 2: elliptic")
    ax.plot(values, traces, "o-", color="C0", markersize=4, label="trace of the section map")
    seen = set()
    for event in branch["events"]:
        lo, hi = event["between"]
        where = hi if lo is None else (lo + hi) / 2
        label = event["kind"].replace("_", " ")
        ax.axvline(where, color=EVENT_COLOURS[event["kind"]], linestyle="--", linewidth=1.2,
                   label=None if label in seen else label)
        seen.add(label)
    ax.set_xlabel(branch["parameter"])
    ax.set_ylabel("trace (sum of the section multipliers)")
    ax.set_title("continuation: a multiplier through +1 (trace 2) is a fold,\nthrough -1 (trace -2) a period "
                 "doubling", fontsize=9)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)


def _newton_panel(ax: Any, orbit: Mapping[str, Any]) -> None:
    residuals = [r if r is not None else np.nan for r in orbit["newton"]["residuals"]]
    if not residuals:  # not seeded: the reason instead of a curve
        ax.text(0.5, 0.5, textwrap.fill(orbit["reason"], 60), transform=ax.transAxes, ha="center", va="center",
                fontsize=9)
        ax.set_axis_off()
        return
    ax.semilogy(np.arange(1, len(residuals) + 1), np.maximum(residuals, 1e-18), "o-", color="C0", markersize=4)
    ax.axhline(CLOSING_TOLERANCE, color="C3", linestyle="--", linewidth=1,
               label=f"closing tolerance {CLOSING_TOLERANCE:g}")
    ax.set_xlabel("evaluation (an integration of the state and its monodromy)")
    ax.set_ylabel("closing residual max|x(T) - x0| (scaled)")
    ax.set_title(f"search: {orbit['newton']['method']}", fontsize=9)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3, which="both")
