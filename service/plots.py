"""Plots of a job's result and of an ensemble, as PNG or SVG bytes (matplotlib, Agg, no pyplot).

Each plot is built by a ``_*_figure(...) -> Figure`` function from the JSON the API serves (a job's
``result`` and ``request``, an ensemble's view and its members), then rendered by :func:`_render`.
The routes ``GET /v1/jobs/{id}/plots/{name}.{png|svg}`` and ``GET /v1/ensembles/{id}/plots/{name}.{png|svg}``
call :func:`job_plot` and :func:`ensemble_plot`.

Figures are :class:`matplotlib.figure.Figure` objects with their own Agg canvas (no pyplot state).
matplotlib's style (``rcParams``) and its text caches are process-global, so building and rendering
run under one lock: plots are drawn one at a time, whatever thread serves the request. Lines are
thinned to :data:`MAX_LINE_POINTS` (the trajectory to :data:`service.plot_orbit.MAX_POINTS`), and data
artists stay out of the constrained layout (``in_layout=False``: they are clipped to their axes, and
measuring thousands of points per layout pass would cost more than drawing them).

The trajectory plot draws the orbit from the integrator's dense output (:mod:`service.plot_orbit`: the
job's integration again on a fine grid through the stored samples), not the job's ``samples`` (201 by
default, chords on a long orbit). The Lyapunov plots say that they show finite-time estimates, at which
t, and which have not converged. The ensemble's figures are in :mod:`service.plot_ensemble`.

Which vector is drawn on which surface comes from the system's definition, not a table: the
*geometric vector* is the first state vector fixed by a constraint on itself alone (``|γ| = 1``,
``|s| = 1``, ``|Γ| = 1``, the quadric ``(x, B⁻¹x) = 1``); the *momentum-like vector* is the first
other state vector (``M``, ``ω``, ``L``). The constraint's own value says the surface: a unit norm is
the unit sphere; the ball-on-quadric's constraint is the ellipsoid ``(x, B⁻¹x) = 1`` with ``B`` from
the result's parameters.
"""

from __future__ import annotations

import io
import itertools
import re
import textwrap
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import matplotlib
import mpl_toolkits.mplot3d  # type: ignore[import-untyped]  # no py.typed  # noqa: F401  (the "3d" projection)
import numpy as np
import sympy as sp
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from nonholonomic.definition import MechanicalSystem, StateConstraint, StateVector
from nonholonomic.potentials import EXPRESSION
from nonholonomic.systems import get_system, registered

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

JOB_PLOTS: tuple[str, ...] = ("trajectory", "integrals", "poincare", "lyapunov", "periodic_orbit", "bifurcation")
ENSEMBLE_PLOTS: tuple[str, ...] = ("poincare", "exponents", "map", "orbit_diagram")
FORMATS = {"png": "image/png", "svg": "image/svg+xml"}

#: Resolution of PNG output.
PNG_DPI = 110
#: A line is thinned to at most this many points before it is drawn.
MAX_LINE_POINTS = 5000
#: An ensemble section draws at most this many points (evenly thinned beyond).
MAX_SECTION_POINTS = 200_000
#: A relative drift below this (an exact zero included) is drawn at it on the log axis.
DRIFT_FLOOR = 1e-17

#: Style of every plot; SVG text stays text (searchable, selectable), SVG ids are reproducible.
_STYLE: dict[RcKeyType, Any] = {
    "svg.fonttype": "none",
    "svg.hashsalt": "nonholonomic",
    "font.size": 9.0,
    "axes.titlesize": 9.0,
    "legend.fontsize": 8.0,
    "figure.titlesize": 10.0,
}
#: Metadata-free output: the same result draws the same bytes.
_METADATA = {"png": {"Software": None}, "svg": {"Date": None, "Creator": None}}
_LOCK = threading.Lock()

#: Names of the paper written as its symbols (state names, τ).
_GREEK = {"gamma": "γ", "Gamma": "Γ", "omega": "ω", "tau": "τ", "alpha": "α", "beta": "β", "lambda": "λ"}
_SUBSCRIPT = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")
_COMPONENT = re.compile(r"^([A-Za-z_]+?)(\d*)$")


class PlotUnavailable(ValueError):
    """This plot cannot be drawn for this result (e.g. no poincare block asked); message says why."""


# --------------------------------------------------------------------------- public API


def job_plot(name: str, result: dict, request: dict, fmt: str, window: tuple[float, float] | None = None) -> bytes:
    """One plot of a job's result, rendered.

    Parameters
    ----------
    name : one of :data:`JOB_PLOTS`: ``trajectory`` (the geometric vector on its sphere or
        ellipsoid, the momentum-like vector against t), ``integrals`` (relative drift of every first
        integral, log scale, the verdict's tolerance), ``poincare`` (the section's two coordinates),
        ``lyapunov`` (running estimates of the exponents), ``periodic_orbit`` (the multipliers on the complex
        plane; the continuation's trace, or Newton's residuals).
    result : the job's ``result`` (``GET /v1/jobs/{id}``).
    request : the job's ``request`` (the integrals plot rebuilds the system and its parameters from it).
    fmt : ``png`` or ``svg`` (:data:`FORMATS`).
    window : ``(t_from, t_to)``, the trajectory plot's window (:mod:`service.plot_trajectory`; None: the last
        stretch of a long run, a short run whole).

    Returns
    -------
    bytes
        The image; its media type is ``FORMATS[fmt]``.

    Raises
    ------
    ValueError
        For an unknown ``name`` or ``fmt``.
    PlotUnavailable
        If the result lacks what the plot needs (no section asked, a paper report ...).
    """
    _check(name, JOB_PLOTS, fmt)
    if not isinstance(result, Mapping) or "trajectory" not in result:
        raise PlotUnavailable("this job has no simulation result to plot (a paper report, or no result yet)")
    from service.plot_branch import bifurcation_figure  # their own modules, which import this one
    from service.plot_periodic import periodic_orbit_figure
    from service.plot_trajectory import trajectory_figure

    figures = {**_JOB_FIGURES, "periodic_orbit": periodic_orbit_figure, "bifurcation": bifurcation_figure,
               "trajectory": lambda r, q: trajectory_figure(r, q, window)}
    with _LOCK, matplotlib.rc_context(_STYLE):
        fig = figures[name](result, request)
        transient = getattr(fig, "nonholonomic_transient", False)
        data = _render(fig, fmt)
    if transient:
        from service.plot_orbit import TransientImage

        return TransientImage(data)
    return data


def ensemble_plot(name: str, view: dict, members: Iterable[dict], fmt: str) -> bytes:
    """One plot of an ensemble, rendered.

    Parameters
    ----------
    name : one of :data:`ENSEMBLE_PLOTS`: ``poincare`` (every member's section points, one colour
        per member), ``exponents`` (the largest exponent against the swept parameter, or their
        histogram), ``map`` (a chaos map: one panel per indicator) or ``orbit_diagram`` (a sweep's section
        points against the swept parameter).
    view : the ensemble's view (``GET /v1/ensembles/{id}``; its ``request`` names the system).
    members : the member results (``GET /v1/ensembles/{id}/members`` items), consumed once.
    fmt : ``png`` or ``svg``.

    Raises
    ------
    ValueError
        For an unknown ``name`` or ``fmt``.
    PlotUnavailable
        If no member has what the plot needs.
    """
    from service.plot_ensemble import (
        ENSEMBLE_FIGURES,  # the ensemble's figures, in their own modules
    )
    from service.plot_map import map_figure

    _check(name, ENSEMBLE_PLOTS, fmt)
    with _LOCK, matplotlib.rc_context(_STYLE):
        fig = {**ENSEMBLE_FIGURES, "map": map_figure}[name](view, members)
        return _render(fig, fmt)


def _check(name: str, names: Sequence[str], fmt: str) -> None:
    if name not in names:
        raise ValueError(f"unknown plot {name!r}; known: {', '.join(names)}")
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; known: {', '.join(FORMATS)}")


def _render(fig: Figure, fmt: str) -> bytes:
    """``fig`` as PNG (:data:`PNG_DPI`) or SVG bytes (no metadata)."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; known: {', '.join(FORMATS)}")
    FigureCanvasAgg(fig)  # the figure's own canvas: no pyplot, no global figure manager
    buffer = io.BytesIO()
    fig.savefig(buffer, format=fmt, dpi=PNG_DPI if fmt == "png" else "figure", metadata=_METADATA[fmt])
    return buffer.getvalue()


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


# --------------------------------------------------------------------------- names, units, thinning


def _symbol(name: str) -> str:
    """A state name or component in the paper's symbols: ``gamma1`` → ``γ₁``, ``M3`` → ``M₃``, ``tau`` → ``τ``."""
    match = _COMPONENT.match(name)
    if not match:
        return name
    base, index = match.groups()
    return _GREEK.get(base, base) + index.translate(_SUBSCRIPT)


def _vector_of(component: str) -> str:
    """The vector a component belongs to: ``gamma1`` → ``gamma``."""
    match = _COMPONENT.match(component)
    return match.group(1) if match else component


def _axis_label(name: str, units: Mapping[str, str]) -> str:
    """``γ₁ [1]``: the symbol and its unit (the unit of the component's vector)."""
    unit = units.get(name, units.get(_vector_of(name)))
    return f"{_symbol(name)} [{unit}]" if unit is not None else _symbol(name)


def _component_label(vector: StateVector, k: int, units: Mapping[str, str]) -> str:
    """``γ₁ [1]``, ``θ [as L's coordinates]``: component ``k`` of a state vector by its own symbol (a user's
    coordinate's name), with the vector's unit."""
    unit = units.get(vector.name)
    return f"{_symbol(str(vector.symbols[k]))} [{unit}]" if unit is not None else _symbol(str(vector.symbols[k]))


def _headline(system: Mapping[str, Any], what: str) -> str:
    """``title (kind, eq. …)`` over ``what``: a plot's title."""
    kind = system.get("kind", "")
    return f"{system.get('title', kind)} ({kind}, eq. {system.get('equation', '?')})\n{what}"


def _thin(n: int, limit: int = MAX_LINE_POINTS) -> np.ndarray:
    """At most ``limit`` evenly spaced indices of ``range(n)``, the first and the last kept."""
    if n <= limit:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, limit).round().astype(int))


def _bucket_max(y: np.ndarray, limit: int = MAX_LINE_POINTS) -> np.ndarray:
    """Indices of the largest ``y`` in each of ``limit`` consecutive buckets (the peaks survive thinning)."""
    n = len(y)
    if n <= limit:
        return np.arange(n)
    edges = np.linspace(0, n, limit + 1).round().astype(int)
    return np.array([a + int(np.argmax(y[a:b])) for a, b in itertools.pairwise(edges) if b > a])


# --------------------------------------------------------------------------- geometry from the definition


def _definition(system_info: Mapping[str, Any], request: Mapping[str, Any] | None = None) -> MechanicalSystem:
    """The core's definition of a result's ``system`` block, for its geometry (state vectors and
    constraints, which a user's potential does not change; a user's surface, from the ``request``, does)."""
    potential = system_info.get("potential", "zero")
    surface = None
    record = registered(system_info["kind"])
    if record is not None and record.written_by_user:  # the user's system lives in the request
        from schemas.systems import definition_of

        if request is None or "system" not in request:
            raise PlotUnavailable("the system of this result is in its request, which is not given")
        return definition_of(request["system"])
    if record is not None and record.surface:
        from schemas.systems import SurfaceSpec

        if request is None or "surface" not in request.get("system", {}):
            raise PlotUnavailable("the surface of this result is in its request, which is not given")
        surface = SurfaceSpec.model_validate(request["system"]["surface"]).core()
    try:
        return get_system(system_info["kind"], "zero" if potential == EXPRESSION else potential, surface)
    except KeyError as exc:
        raise PlotUnavailable(f"cannot rebuild the system of this result: {exc}") from None


def _geometric_vector(system: MechanicalSystem) -> tuple[StateVector, StateConstraint | None]:
    """The first state vector fixed by a constraint on itself alone (``|γ| = 1``, the quadric of ``x``),
    with that constraint; else the first state vector and None."""
    vectors = {v.name: v for v in system.state}
    state_symbols = set(system.state_symbols)
    for constraint in system.constraints:
        vector = vectors.get(constraint.field)
        if vector is not None and (constraint.expression.free_symbols & state_symbols) <= set(vector.symbols):
            return vector, constraint
    return system.state[0], None


def _momentum_vector(system: MechanicalSystem, geometric: StateVector) -> StateVector | None:
    """The first state vector other than the geometric one (``M``, ``ω``, ``L``)."""
    return next((v for v in system.state if v.name != geometric.name), None)


def _surface_mesh(constraint: StateConstraint | None, parameters: Mapping[str, Any],
                  resolution: tuple[int, int] = (25, 13)) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Wireframe of the constraint's surface: the unit sphere for ``|v| = 1``, the ellipsoid
    ``x = B^(1/2) u`` (``|u| = 1``) for the quadric ``(x, B⁻¹x) = 1``; None for anything else."""
    if constraint is None:
        return None
    u = np.linspace(0, 2 * np.pi, resolution[0])
    v = np.linspace(0, np.pi, resolution[1])
    sphere = np.stack([np.outer(np.cos(u), np.sin(v)), np.outer(np.sin(u), np.sin(v)),
                       np.outer(np.ones_like(u), np.cos(v))])
    if constraint.value > 0 and _is_norm(constraint):  # |v| = r
        r = float(constraint.value)
        return r * sphere[0], r * sphere[1], r * sphere[2]
    if "B" in parameters:  # the quadric of ball_on_quadric: (x, B^-1 x) = 1, x = B^(1/2) u
        B = np.asarray(parameters["B"], dtype=float)
        B = np.diag(B) if B.shape == (3,) else (B + B.T) / 2
        w, V = np.linalg.eigh(B)
        root = V @ np.diag(np.sqrt(np.clip(w, 0, None))) @ V.T
        x = np.einsum("ij,jkl->ikl", root, sphere)
        return x[0], x[1], x[2]
    return None


def _is_norm(constraint: StateConstraint) -> bool:
    """Whether the constraint is ``|v| = value`` (its expression is ``sqrt((v, v))``)."""
    expr = constraint.expression
    return isinstance(expr, sp.Pow) and expr.exp == sp.Rational(1, 2) and all(
        sp.Pow(s, 2) in expr.base.args for s in expr.free_symbols)


def _vector_samples(trajectory: Mapping[str, Any], name: str) -> np.ndarray:
    """A vector's samples as an ``(n, 3)`` array."""
    if name not in trajectory or trajectory[name] is None:
        raise PlotUnavailable(f"the trajectory has no samples of {name}")
    return np.asarray(trajectory[name], dtype=float).reshape(len(trajectory[name]), -1)


# --------------------------------------------------------------------------- job plots


def _integrals_figure(result: Mapping[str, Any], request: Mapping[str, Any]) -> Figure:
    """Relative drift ``|I(t) − I(0)| / max(|I(0)|, scale)`` of every first integral at the samples."""
    from nonholonomic.evidence.integrals import integral_series, integral_tolerance
    from schemas.jobs import JobRequest

    info = result["system"]
    units = info.get("units", {})
    try:
        job = JobRequest.model_validate(request)
    except ValueError as exc:
        raise PlotUnavailable(f"the job's request does not rebuild a system: {exc}") from None
    system = job.system.validation_definition()
    if not system.integrals:
        raise PlotUnavailable(f"{system.kind} claims no first integral")
    trajectory = result["trajectory"]
    t = np.asarray(trajectory["t"], dtype=float)
    states = np.hstack([_vector_samples(trajectory, v.name) for v in system.state])
    series = integral_series(system, job.system.parameter_values(), states)
    reported = {item["name"]: item for item in result.get("integrals") or []}
    tolerance = (next(iter(reported.values()))["tolerance"] if reported
                 else integral_tolerance(result["integration"]["tolerance"]))

    fig = _new_figure(10.0, 6.5)
    ax = fig.add_subplot(1, 1, 1)
    top = tolerance
    for claim in system.integrals:
        drift = relative_drift(*series[claim.name], reported.get(claim.name, {}).get("reference"))
        keep = _bucket_max(drift)
        peak = float(np.max(drift)) if len(drift) else 0.0
        top = max(top, peak)
        ax.plot(t[keep], np.maximum(drift[keep], DRIFT_FLOOR), linewidth=0.8, in_layout=False,
                label=textwrap.fill(f"{claim.name}: {claim.formula} (eq. {claim.equation}); max {peak:.2g}", 75,
                                    subsequent_indent="    "))
    ax.axhline(tolerance, color="k", linestyle="--", linewidth=1.0, label=f"verdict tolerance {tolerance:.0e}")
    ax.set_yscale("log")
    ax.set_ylim(DRIFT_FLOOR / 3, top * 30)
    ax.set_xlabel(_axis_label("t", units))
    ax.set_ylabel("|I(t) - I(0)| / max(|I(0)|, scale)  [1]")
    ax.grid(alpha=0.3, which="major")
    entries = len(system.integrals) + 1
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=1 if entries <= 4 else 2,
              title=f"drifts below {DRIFT_FLOOR:.0e} (exact zeros too) are drawn at {DRIFT_FLOOR:.0e}")
    fig.suptitle(_headline(info, f"relative drift of the first integrals at the {len(t)} samples "
                                 f"(the verdict also evaluates every accepted step)"))
    return fig


def relative_drift(values: np.ndarray, scales: np.ndarray, reference: float | None = None) -> np.ndarray:
    """``|I − I(0)| / reference`` with ``reference = max(|I(0)|, max |scale|)`` (1 if that is 0), or the
    job's reported ``reference`` (computed over the samples and every accepted step) when given."""
    values = np.asarray(values, dtype=float)
    if len(values) == 0:
        return values
    if reference is None:
        reference = max(abs(float(values[0])), float(np.max(np.abs(scales))))
    reference = reference if reference > 0 else 1.0
    return np.abs(values - values[0]) / reference


def _poincare_figure(result: Mapping[str, Any], request: Mapping[str, Any] | None = None) -> Figure:
    """The section's two coordinates as dots."""
    section = result.get("poincare")
    if not section:
        raise PlotUnavailable("this job asked for no poincare section")
    info = result["system"]
    units = info.get("units", {})
    names = section.get("coordinate_names") or ["", ""]
    points = np.asarray(section.get("coordinates") or [], dtype=float).reshape(-1, 2)

    fig = _new_figure(7.0, 6.0)
    ax = fig.add_subplot(1, 1, 1)
    ax.scatter(points[:, 0], points[:, 1], s=4.0 if len(points) < 2000 else 1.0, color="C0", linewidths=0,
               rasterized=len(points) > 2000, in_layout=False)
    if not len(points):
        ax.text(0.5, 0.5, "no crossing of the surface", transform=ax.transAxes, ha="center", va="center")
    orbit = result.get("periodic_orbit") or {}
    if (orbit.get("status") in ("found", "degenerate") and orbit.get("coordinate_names") == list(names)
            and orbit.get("surface") == section["surface"] and orbit.get("value") == section["value"]):
        u, v = orbit["coordinates"]
        ax.scatter(u, v, marker="*", s=160, color="C3", edgecolors="k", linewidths=0.5, zorder=3,
                   label=f"the periodic orbit (period {orbit['period']}, {orbit.get('stability')})")
        ax.legend(loc="best", fontsize=8)
    ax.set_xlabel(_axis_label(names[0], units))
    ax.set_ylabel(_axis_label(names[1], units))
    ax.grid(alpha=0.3)
    note = " (stopped at max_points)" if section.get("stopped_early") else ""
    fig.suptitle(_headline(info, f"Poincaré section {section['surface']} = {section['value']:g}, "
                                 f"{section['direction']} crossings: {section['count']} points{note}, "
                                 f"t in [0, {section.get('t_final', result.get('t_final', 0)):g}] s"))
    return fig


def not_converged(spectrum: Mapping[str, Any]) -> bool:
    """Whether a spectrum says its estimates have not converged (its ``warnings``: an estimate still moves
    by more than 5 % of max |λ| over the last 20 % of the run)."""
    return any(str(w).startswith("not converged") for w in spectrum.get("warnings") or ())


def finite_time(spectrum: Mapping[str, Any], t_final: float | None = None) -> str:
    """``t = 200 s`` (and the transient left out): the time the finite-time estimates belong to."""
    end = spectrum.get("t_final", t_final)
    transient = float(spectrum.get("transient") or 0.0)
    text = f"t = {end:g} s" if end is not None else "the end of the run"
    return text + (f" (averaged after a transient of {transient:g} s)" if transient > 0 else "")


def _lyapunov_figure(result: Mapping[str, Any], request: Mapping[str, Any] | None = None) -> Figure:
    """Running estimates of the Lyapunov exponents against t (log t); the title says they are finite-time
    estimates, and whether they have converged."""
    spectrum = result.get("lyapunov")
    if not spectrum:
        raise PlotUnavailable("this job asked for no Lyapunov spectrum")
    info = result["system"]
    units = info.get("units", {})
    t = np.asarray(spectrum["convergence_t"], dtype=float)
    estimates = np.asarray(spectrum["convergence"], dtype=float).reshape(len(t), -1)
    exponents = spectrum["exponents"]
    zero = set(spectrum.get("zero_indices") or [])
    keep = _thin(len(t))
    keep = keep[t[keep] > 0]  # log axis

    fig = _new_figure(9.0, 5.0)
    ax = fig.add_subplot(1, 1, 1)
    ax.axhline(0.0, color="0.5", linewidth=0.6)
    for i, final in enumerate(exponents):
        ax.plot(t[keep], estimates[keep, i], linewidth=0.9, in_layout=False, linestyle="--" if i in zero else "-",
                label=f"{_symbol(f'lambda{i + 1}')} = {final:+.4g} 1/s" + (" (expected 0)" if i in zero else ""))
    ax.set_xscale("log")
    ax.set_xlabel(_axis_label("t", units))
    ax.set_ylabel("running estimate of λᵢ [1/s]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    loose = not_converged(spectrum)
    moved = spectrum.get("moved_last_20pct") or []
    verdict = ("not converged: " + (f"an estimate still moves by {max(moved):.2g} 1/s over the last 20 % of the run"
                                    if moved else "run longer")) if loose else \
        "converged to within 5 % of max |λ| over the last 20 % of the run"
    ax.set_title(verdict, color="C3" if loose else "0.3")
    at = finite_time(spectrum, result.get("t_final"))
    fig.suptitle(_headline(info, f"Lyapunov exponents, finite-time estimates at {at}"
                                 f" (QR every {spectrum.get('interval', 0):g} s); "
                                 f"sum {spectrum.get('sum', float('nan')):.2e} "
                                 + (f"1/s, expected {spectrum['sum_expected']:g}" if spectrum.get("sum_expected")
                                    is not None else "1/s (no measure claimed: no expected sum)")))
    return fig


_JOB_FIGURES: dict[str, Callable[[Mapping[str, Any], Mapping[str, Any]], Figure]] = {
    "integrals": _integrals_figure,
    "poincare": _poincare_figure, "lyapunov": _lyapunov_figure,
}
