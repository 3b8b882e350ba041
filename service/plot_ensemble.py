"""Plots of an ensemble (:func:`service.plots.ensemble_plot` draws them): every member's section points,
and the members' largest Lyapunov exponents, which are *finite-time* estimates: the figure says at which
t, and which of them have not converged (the spectrum's own evidence, ``warnings``: an estimate that
still moves by more than 5 % of max |λ| over the last 20 % of the run)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from schemas.sweeps import PATH as SWEEP_PATH
from service.plots import (
    MAX_SECTION_POINTS,
    PlotUnavailable,
    _axis_label,
    _headline,
    _new_figure,
    _thin,
    finite_time,
    not_converged,
)


def _ensemble_system(view: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """A ``system`` block (kind, title, equation) and the units of an ensemble, from its request."""
    from schemas.results import system_units
    from schemas.systems import definition_of

    try:
        system = definition_of(dict(view["request"]["system"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise PlotUnavailable(f"the ensemble's request does not rebuild a system: {exc}") from None
    return {"kind": system.kind, "title": system.title, "equation": system.equation}, system_units(system)


def _ensemble_poincare_figure(view: Mapping[str, Any], members: Iterable[Mapping[str, Any]]) -> Figure:
    """Every member's section points, one colour per member (a colormap over the member index)."""
    info, units = _ensemble_system(view)
    chunks: list[np.ndarray] = []
    indices: list[np.ndarray] = []
    names, section = None, None
    for member in members:
        block = member.get("poincare")
        if not block:
            continue
        section, names = block, names or block.get("coordinate_names")
        points = np.asarray(block.get("coordinates") or [], dtype=float).reshape(-1, 2)
        chunks.append(points)
        indices.append(np.full(len(points), member.get("index", len(indices)), dtype=float))
    if section is None:
        raise PlotUnavailable("no member has a poincare section (the ensemble asked for none, or none succeeded)")
    points = np.concatenate(chunks)
    index = np.concatenate(indices)
    keep = _thin(len(points), MAX_SECTION_POINTS)

    fig = _new_figure(7.5, 6.0)
    ax = fig.add_subplot(1, 1, 1)
    size = 4.0 if len(keep) < 5_000 else 1.0 if len(keep) < 50_000 else 0.3  # tiny markers for many points
    low, high = (float(index.min()), float(index.max())) if len(index) else (0.0, 1.0)
    drawn = ax.scatter(points[keep, 0], points[keep, 1], c=index[keep], cmap="viridis", s=size, linewidths=0,
                       rasterized=True, in_layout=False, vmin=low, vmax=max(high, low + 1))
    bar = fig.colorbar(drawn, ax=ax, label="member index")
    bar.locator = MaxNLocator(integer=True)
    bar.update_ticks()
    names = names or ["", ""]
    ax.set_xlabel(_axis_label(names[0], units))
    ax.set_ylabel(_axis_label(names[1], units))
    ax.grid(alpha=0.3)
    thinned = "" if len(keep) == len(points) else f" ({len(keep)} drawn)"
    fig.suptitle(_headline(info, f"Poincaré section {section['surface']} = {section['value']:g}, "
                                 f"{section['direction']} crossings: {len(points)} points{thinned} "
                                 f"of {len(chunks)} members"))
    return fig


def _ensemble_exponents_figure(view: Mapping[str, Any], members: Iterable[Mapping[str, Any]]) -> Figure:
    """The largest exponent against the swept parameter (a sweep), else the histogram of the largest
    exponents; both as finite-time estimates, the members whose estimate has not converged told apart."""
    info, units = _ensemble_system(view)
    request = view.get("request") or {}
    sweep = (request.get("members") or {}).get("sweep")
    largest, swept, loose, spectra = [], [], [], []
    for member in members:
        spectrum = member.get("lyapunov")
        if not spectrum or not spectrum.get("exponents"):
            continue
        largest.append(float(spectrum["exponents"][0]))
        loose.append(not_converged(spectrum))
        spectra.append(spectrum)
        if sweep:
            label = member.get("label") or {}
            swept.append(float(label["value"]) if "value" in label else float(sweep["values"][member["index"]]))
    if not largest:
        raise PlotUnavailable("no member has a Lyapunov spectrum (the ensemble asked for none, or none succeeded)")
    y, bad = np.asarray(largest), np.asarray(loose, dtype=bool)
    when = finite_time(spectra[0], request.get("t_final"))
    if bad.any():
        verdict = (f"{int(bad.sum())} of {len(y)} not converged (the estimate still moves by > 5 % of max |λ| "
                   f"over the last 20 % of the run)")
    else:
        verdict = f"all {len(y)} converged to within 5 % of max |λ| over the last 20 % of the run"

    fig = _new_figure(8.0, 5.0)
    ax = fig.add_subplot(1, 1, 1)
    ylabel = "largest Lyapunov exponent λ₁ [1/s], finite-time estimate"
    t_end = float(spectra[0].get("t_final") or request.get("t_final") or 0.0)
    # a regular orbit's finite-time λ₁ decays to 0 only like ln t / t: at the run's end it is still about this
    regular_scale = float(np.log(t_end) / t_end) if t_end > np.e else None
    regular_label = (None if regular_scale is None else
                     f"ln T / T = {regular_scale:.3g} 1/s at T = {t_end:g} s: where a regular orbit's "
                     "λ₁ still is (it decays like ln t / t)")
    if sweep:
        x = np.asarray(swept)
        order = np.argsort(x, kind="stable")
        ax.plot(x[order], y[order], color="C0", linewidth=0.8)
        ax.plot(x[~bad], y[~bad], "o", color="C0", markersize=4, label="converged")
        if bad.any():
            ax.plot(x[bad], y[bad], "o", markerfacecolor="white", color="C3", markersize=5, label="not converged")
        ax.axhline(0.0, color="0.5", linewidth=0.6)
        if regular_scale is not None:
            ax.axhline(regular_scale, color="C2", linestyle=":", linewidth=1.2, label=regular_label)
        path = sweep["parameter"]
        match = SWEEP_PATH.match(path.strip())
        unit = units.get(match.group(1)) if match else None
        ax.set_xlabel(f"{path} [{unit}]" if unit is not None else path)
        ax.set_ylabel(ylabel)
        what = f"largest Lyapunov exponent against {path} ({len(y)} members): finite-time estimates at {when}"
    else:
        bins = np.histogram_bin_edges(y, bins=int(np.clip(np.sqrt(len(y)) * 2, 5, 60)))
        ax.hist([y[~bad], y[bad]], bins=bins,  # type: ignore[arg-type]  # matplotlib's stub: no array (it takes one)
                stacked=True, color=["C0", "C3"], alpha=0.85,
                label=[f"converged ({int((~bad).sum())})", f"not converged ({int(bad.sum())})"])
        ax.axvline(0.0, color="0.5", linewidth=0.8)
        low, high = min(float(bins[0]), 0.0), max(float(bins[-1]), 0.0)  # zero in sight: how far from it
        ax.set_xlim(low - 0.02 * (high - low), high + 0.02 * (high - low))
        median = float(np.median(y))
        ax.axvline(median, color="k", linestyle="--", linewidth=1.0, label=f"median {median:.4g} 1/s")
        if regular_scale is not None:
            ax.axvline(regular_scale, color="C2", linestyle=":", linewidth=1.5, label=regular_label)
            high = max(high, regular_scale)
            ax.set_xlim(low - 0.02 * (high - low), high + 0.02 * (high - low))
        ax.set_xlabel(ylabel)
        ax.set_ylabel("members")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        what = f"largest Lyapunov exponents of {len(y)} members: finite-time estimates at {when}"
    ax.legend(loc="best" if sweep else "upper left", fontsize="small")
    ax.set_title(verdict, color="C3" if bad.any() else "0.3")
    ax.grid(alpha=0.3)
    fig.suptitle(_headline(info, what))
    return fig


def _orbit_diagram(view: Mapping[str, Any], members: Iterable[Mapping[str, Any]]) -> Figure:
    from service.orbit_diagram import orbit_diagram_figure  # its own module, which imports this one

    return orbit_diagram_figure(view, members)


ENSEMBLE_FIGURES: dict[str, Callable[[Mapping[str, Any], Iterable[Mapping[str, Any]]], Figure]] = {
    "poincare": _ensemble_poincare_figure, "exponents": _ensemble_exponents_figure, "orbit_diagram": _orbit_diagram,
}
