"""A chaos map's figure: one panel per indicator on the section plane, each with its colour bar and the
threshold marked on it, cells outside the level grey, failed cells red."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from schemas.chaos_maps import INDICATOR_WORDS, STATUS_CODES, map_arrays
from service.plot_ensemble import _ensemble_system
from service.plots import PlotUnavailable, _axis_label, _headline, _new_figure

#: Indicator panels are clipped at these quantiles so that a few huge values do not wash out the rest
#: (the colour bar says so: its ends are open).
CLIP_QUANTILES = (0.005, 0.995)


def map_figure(view: Mapping[str, Any], members: Iterable[Mapping[str, Any]]) -> Figure:
    """The map of every finished cell (``GET /v1/ensembles/{id}/plots/map.png``)."""
    request = view.get("request") or {}
    grid = (request.get("members") or {}).get("grid")
    if not grid or not request.get("indicators"):
        raise PlotUnavailable("this ensemble is not a chaos map (no members.grid and indicators)")
    info, units = _ensemble_system(view)
    arrays = map_arrays(request, members, grid["ranges"])
    if not any(np.isfinite(v).any() for v in arrays.values.values()):
        raise PlotUnavailable("no cell of the map has been integrated yet")
    names = list(request["indicators"])
    summary = ((view.get("summary") or {}).get("map")) or {}
    thresholds = summary.get("thresholds", {})
    fig = _new_figure(5.2 * len(names) + 0.6, 5.2)
    (lo0, hi0), (lo1, hi1) = grid["ranges"]
    extent = (lo0, hi0, lo1, hi1)
    for k, name in enumerate(names):
        ax = fig.add_subplot(1, len(names), k + 1)
        values = arrays.values[name]
        finite = values[np.isfinite(values)]
        vmin, vmax = np.quantile(finite, CLIP_QUANTILES)
        if vmax <= vmin:
            vmax = vmin + 1.0
        background = np.where(arrays.status == STATUS_CODES["failed"], 1, 0).astype(float)
        ax.imshow(background.T, origin="lower", extent=extent, aspect="auto", interpolation="nearest",
                  cmap=ListedColormap(["0.85", "#d62728"]), vmin=0, vmax=1)
        image = ax.imshow(np.ma.masked_invalid(values).T, origin="lower", extent=extent, aspect="auto",
                          interpolation="nearest", cmap="inferno", vmin=vmin, vmax=vmax)
        word, unit, _ = INDICATOR_WORDS[name]
        bar = fig.colorbar(image, ax=ax, extend="both", label=f"{word} [{unit}]")
        if name in thresholds and vmin < thresholds[name] < vmax:
            bar.ax.axhline(thresholds[name], color="c", linewidth=2)
        ax.xaxis.set_major_locator(MaxNLocator(5))  # a zoomed axis has long tick labels
        ax.set_xlabel(_axis_label(arrays.coordinates[0], units))
        ax.set_ylabel(_axis_label(arrays.coordinates[1], units))
        ax.set_title(f"{word}" + (f" (chaotic above {thresholds[name]:.3g}: the cyan mark)" if name in thresholds
                                  else ""), fontsize=9)
    level = ", ".join(f"{k} = {v:g}" for k, v in grid["level"].items())
    counts = ", ".join(f"{summary.get(s, 0)} {s}" for s in ("regular", "chaotic", "outside", "failed"))
    fraction = summary.get("chaotic_fraction")
    fig.suptitle(_headline(info, f"chaos map on {grid['surface']} = {grid['value']:g} ({grid['direction']}), "
                                 f"{level}, t = {request['t_final']:g} s\n{counts}"
                                 + (f"; chaotic fraction {fraction:.3f}" if fraction is not None else "")
                                 + " (grey: outside the level)"), fontsize=10)
    return fig
