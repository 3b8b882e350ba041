"""A branch of periodic orbits as a bifurcation diagram (``GET /v1/jobs/{id}/plots/bifurcation.png``).

Left: the orbit's first section coordinate against the continued value, each branch in its own colour (the job's
period k, then the period-2k branches switched onto), elliptic (linearly stable) parts solid and the others
dashed, each located bifurcation marked and labelled (F fold, T tangent, PD period doubling, R3 and R4 the
1:3 and 1:4 resonances, NS Neimark–Sacker, K Krein collision). Right: the section map's trace against the value,
the elliptic band |trace| < 2 shaded (symmetric-log axis beyond ±10: traces grow fast near a homoclinic orbit)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from service.plots import PlotUnavailable, _axis_label, _headline, _new_figure

LABELS = {"fold": "F", "tangent": "T", "period_doubling": "PD", "resonance_1:3": "R3", "resonance_1:4": "R4",
          "neimark_sacker": "NS", "krein_collision": "K"}
MARKERS = {"fold": "s", "tangent": "D", "period_doubling": "o", "resonance_1:3": "^", "resonance_1:4": "v",
           "neimark_sacker": "P", "krein_collision": "X"}


def _segments(b: Mapping[str, Any]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]]:
    """The branch cut at its located bifurcations into stretches of one stability: (value, first coordinate,
    trace, stable) each, a bifurcation point ending one stretch and starting the next."""
    rows: list[tuple[float, Mapping[str, Any], str | None]] = [(p["arclength"], p, None) for p in b.get("points") or []]
    rows += [(f["point"]["arclength"], f["point"], "cut") for f in b.get("bifurcations") or []]
    rows.sort(key=lambda r: r[0])
    out: list[tuple[np.ndarray, np.ndarray, np.ndarray, bool]] = []
    current: list[Mapping[str, Any]] = []
    stable: bool | None = None
    for _, p, cut in rows:
        here = None if cut else p.get("stability") == "elliptic"
        if here is not None and stable is not None and here != stable and current:
            out.append(_stretch(current, stable))
            current = current[-1:]
        current.append(p)
        if here is not None:
            stable = here
        if cut and stable is not None and len(current) > 1:
            out.append(_stretch(current, stable))
            current, stable = [p], None
    if len(current) > 1 or (current and not out):
        out.append(_stretch(current, bool(stable)))
    return out


def _stretch(points: list[Mapping[str, Any]], stable: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    return (np.array([p["value"] for p in points], dtype=float),
            np.array([(p.get("coordinates") or [np.nan])[0] for p in points], dtype=float),
            np.array([np.nan if p.get("trace") is None else p["trace"] for p in points], dtype=float), stable)


def bifurcation_figure(result: Mapping[str, Any], request: Mapping[str, Any] | None = None) -> Figure:
    """The bifurcation diagram of ``result['periodic_orbit']['branch']`` (see the module docstring)."""
    branch = (result.get("periodic_orbit") or {}).get("branch")
    if not branch or not branch.get("points"):
        raise PlotUnavailable("this job asked for no branch (periodic_orbit.branch), or its orbit was not found")
    units = result["system"]["units"]
    coordinate = (branch.get("coordinate_names") or ["coordinate"])[0]
    value_unit = (branch.get("units") or {}).get("value")
    fig = _new_figure(13.0, 5.6)
    left, right = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    right.axhspan(-2, 2, color="C2", alpha=0.12, label="|trace| < 2: elliptic")
    labelled: set[str] = set()
    for number, b in enumerate([branch, *(branch.get("switched") or [])]):
        points = b.get("points") or []
        if not points:
            continue
        colour = f"C{number % 10}"
        name = f"period {b['period']}" + ("" if number == 0 else f" (from {LABELS['period_doubling']})")
        for value, x0, trace, is_stable in _segments(b):
            tag = f"{name}, {'stable' if is_stable else 'unstable'}"
            for ax, y in ((left, x0), (right, trace)):
                ax.plot(value, y, "-" if is_stable else "--", color=colour, linewidth=1.6,
                        label=tag if (ax is left and tag not in labelled) else None)
            labelled.add(tag)
        for i, bif in enumerate(b.get("bifurcations") or []):
            p = bif["point"]
            label = LABELS.get(bif["kind"], bif["kind"])
            for ax, y in ((left, (p.get("coordinates") or [np.nan])[0]), (right, p.get("trace"))):
                if y is None:
                    continue
                ax.plot([bif["value"]], [y], MARKERS.get(bif["kind"], "o"), color="k", markersize=6,
                        markerfacecolor="white" if not bif.get("located") else "k", zorder=5)
                if ax is left:  # the right panel's markers are at the same values
                    ax.annotate(f"{label} {bif['value']:.6g}", (bif["value"], y), textcoords="offset points",
                                xytext=(7, -12) if i % 2 == 0 else (-7, 5), ha="left" if i % 2 == 0 else "right",
                                fontsize=8)
    value_label = f"{branch['in']} [{value_unit}]" if value_unit else str(branch["in"])
    left.set_xlabel(value_label)
    left.set_ylabel(_axis_label(coordinate, units) + " of x0 on the section")
    left.set_title("solid: stable (elliptic), dashed: unstable; F fold, PD period doubling, R3/R4 resonances",
                   fontsize=9)
    left.legend(loc="best", fontsize=8)
    left.grid(alpha=0.3)
    right.set_yscale("symlog", linthresh=10)
    right.set_xlabel(value_label)
    right.set_ylabel("trace of the section map")
    right.set_title("trace 2: a multiplier +1 (fold, tangent); trace -2: a multiplier -1 (period doubling)",
                    fontsize=9)
    right.legend(loc="best", fontsize=8)
    right.grid(alpha=0.3)
    every = [branch, *(branch.get("switched") or [])]
    count = sum(len(b.get("points") or []) for b in every)
    found = sum(len(b.get("bifurcations") or []) for b in every)
    what = (f"branch of the period-{branch['period']} orbit in {branch['in']}: {count} orbits, {found} bifurcations, "
            f"{len(every) - 1} branch(es) switched onto; {branch['status']}")
    fig.suptitle(_headline(result["system"], what))
    return fig
