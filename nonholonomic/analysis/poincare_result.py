"""Poincaré sections, the result: :class:`Section` and the post-processing of the recorded crossings.

The event time reaches Python rounded to a double, so the dense-output state is off the exact
root by up to half an ulp of ``t`` (``|f|·ulp(t)/2``, ~1e-13 at t ~ 1000). One Newton step along
the flow, done for all crossings at once with the numpy kernels,
``δ = −(S(x) − value)/(∇S·f)``, ``x ← x + f(x) δ``, ``t ← t + δ``, ``τ ← τ + ρ δ``, moves each point
back onto the surface (``δ`` is accepted only while it is at the level of that rounding; a
nearly tangent crossing keeps its unrefined point and a warning says so).

Measures reported per section: the largest ``|S(x) − value|`` at the points relative to the
surface's scale (:func:`.poincare_surface.surface_scale_of`), and the largest relative drift of
every first integral at the points against the initial state, normalised as in
:mod:`nonholonomic.evidence.integrals`. Part of :mod:`.poincare` (the front door), where every
name is importable.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from nonholonomic.analysis.poincare_request import _Request
from nonholonomic.analysis.poincare_surface import _scale
from nonholonomic.integration import MACHINE_EPSILON

#: The Newton correction of a crossing time is accepted up to this many ``eps·max(|t|, h_max)``.
NEWTON_BOUND = 64.0


@dataclass(frozen=True)
class Section:
    """The crossings of one trajectory with the surface ``S = value``, in time order.

    Attributes
    ----------
    surface : the surface's text as requested; value, direction : as requested.
    t : crossing times, shape ``(count,)``.
    tau : the reduced time τ at the crossings (None for systems without one).
    points : every state vector and derived vector by name (``M``, ``gamma``, ``omega`` for the
        ball), each of shape ``(count, 3)``.
    coordinate_names, coordinates : the two chosen components, ``coordinates`` of shape ``(count, 2)``.
    surface_residual_max : ``max |S(x) − value| / surface_scale`` at the points (0 without points).
    surface_scale : see :func:`surface_scale_of`.
    integral_drift_max : per first integral of the system, ``max |I(x) − I(x0)| / max(|I(x0)|, scale)``
        over the points, ``scale`` the integral's natural size (largest over x0 and the points), as in
        :mod:`nonholonomic.evidence.integrals`.
    stopped_early : True when ``max_points`` crossings were recorded and the integration stopped
        before ``t_final``.
    warnings : what the caller should know (max_points reached, no crossing, tangent crossings).
    steps : accepted Taylor steps; wall_time_s : integration and post-processing time (for a
        member of :func:`section_batch`, its share of its batch's time). Compilation is not counted.
    t_final : the requested end time; tolerance : heyoka's tolerance.
    """

    surface: str
    value: float
    direction: str
    t: np.ndarray
    tau: np.ndarray | None
    points: dict[str, np.ndarray]
    coordinate_names: tuple[str, str]
    coordinates: np.ndarray
    surface_residual_max: float
    surface_scale: float
    integral_drift_max: dict[str, float]
    stopped_early: bool
    warnings: tuple[str, ...]
    steps: int
    wall_time_s: float
    t_final: float = 0.0
    tolerance: float = MACHINE_EPSILON

    @property
    def count(self) -> int:
        """Number of crossings."""
        return int(len(self.t))



# --------------------------------------------------------------------------------------------------
# Post-processing: Newton step onto the surface, points, coordinates, residual, drift
# --------------------------------------------------------------------------------------------------

def _finish(req: _Request, p: np.ndarray, y0: np.ndarray, t: np.ndarray, raw: np.ndarray, max_h: float,
            stopped_early: bool, steps: int, start: float, wall_share: float = 1.0) -> Section:
    system = req.system
    n = system.dimension
    kernels = req.prep.kernels
    order = np.argsort(t, kind="stable")
    t, raw = t[order], raw[order]
    x = raw[:, :n].copy()
    tau = raw[:, n].copy() if system.reduced_time is not None else None
    warnings: list[str] = []

    if len(t):
        # One Newton step along the flow: undo the rounding of the event time to a double.
        columns = kernels.newton(x, p)
        f = columns[:, 1 + n:1 + 2 * n]
        g = columns[:, 0] - req.value
        dg = np.sum(columns[:, 1:1 + n] * f, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            delta = -g / dg
        bound = NEWTON_BOUND * MACHINE_EPSILON * np.maximum(np.abs(t), max_h)
        ok = np.isfinite(delta) & (np.abs(delta) <= bound)
        delta = np.where(ok, delta, 0.0)
        if tau is not None:
            tau = tau + columns[:, 1 + 2 * n] * delta
        x = x + f * delta[:, None]
        t = t + delta
        if not np.all(ok):
            warnings.append(f"{int(np.sum(~ok))} crossing(s) nearly tangent to the surface (dS/dt ~ 0): their "
                            "points are the integrator's event points, not refined onto the surface")
    else:
        warnings.append(f"no crossing of {req.text!r} = {req.value:g} ({req.direction}) in 0 <= t <= "
                        f"{req.t_final:g}")
    if stopped_early:
        warnings.append(f"max_points = {req.max_points} reached at t = {t[-1]:.9g}; the integration stopped "
                        f"there instead of at t_final = {req.t_final:g}")

    # Everything reported, evaluated at the initial state (row 0) and the points in one kernel call.
    report = kernels.report(np.vstack([y0[None, :], x]), p)
    at_points = report[1:]
    points: dict[str, np.ndarray] = {vec.name: x[:, cols].copy() for vec, cols in zip(system.state, kernels.slices)}
    for name, cols in kernels.derived:
        points[name] = at_points[:, cols].copy()
    coordinates = np.stack([points[vec][:, i] for vec, i in (req.prep.locate[c] for c in req.coordinates)], axis=1)

    scale = _scale(kernels, x, at_points[:, 1:1 + n], req.value)
    residual = float(np.max(np.abs(at_points[:, 0] - req.value)) / scale) if len(t) else 0.0

    drift: dict[str, float] = {}
    if system.integrals:
        values = report[:, kernels.integrals]
        reference = np.maximum(np.abs(values[0]), np.max(np.abs(report[:, kernels.integral_scales]), axis=0))
        reference = np.where(reference > 0, reference, 1.0)
        rel = np.max(np.abs(values - values[0]), axis=0) / reference
        drift = {claim.name: float(rel[i]) for i, claim in enumerate(system.integrals)}

    return Section(
        surface=req.text, value=req.value, direction=req.direction, t=t, tau=tau, points=points,
        coordinate_names=req.coordinates, coordinates=coordinates, surface_residual_max=residual,
        surface_scale=scale, integral_drift_max=drift, stopped_early=stopped_early, warnings=tuple(warnings),
        steps=int(steps), wall_time_s=(time.perf_counter() - start) * wall_share, t_final=req.t_final,
        tolerance=req.tolerance,
    )
