"""Poincaré sections, the result: :class:`Section` and the post-processing of the recorded crossings.

The event time reaches Python rounded to a double, so the dense-output state is off the exact
root by up to half an ulp of ``t`` (``|f|·ulp(t)/2``, ~1e-13 at t ~ 1000). One Newton step along
the flow, done for all crossings at once by the surface's compiled function,
``δ = −(S(x) − value)/(∇S·f)``, ``x ← x + f(x) δ``, ``t ← t + δ``, ``τ ← τ + ρ δ``, moves each point
back onto the surface (``δ`` is accepted only while it is at the level of that rounding; a
nearly tangent crossing keeps its unrefined point and a warning says so).

Measures reported per section: the largest ``|S(x) − value|`` at the points relative to the
surface's scale (:func:`.surface.surface_scale_of`), and the largest relative drift of
every first integral at the points against the initial state, normalised as in
:mod:`nonholonomic.evidence.integrals`. Part of :mod:`.poincare` (the front door), where every
name is importable.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from nonholonomic.analysis.poincare.request import _Request
from nonholonomic.analysis.poincare.surface import _scale
from nonholonomic.numerics import tally
from nonholonomic.numerics.integration import MACHINE_EPSILON

#: The Newton correction of a crossing time is accepted up to this many ``eps·max(|t|, h_max)``.
NEWTON_BOUND = 64.0
_BOUND = NEWTON_BOUND * MACHINE_EPSILON


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

def _finish(req: _Request, runtime: np.ndarray, y0: np.ndarray, t: np.ndarray, raw: np.ndarray, max_h: float,
            stopped_early: bool, steps: int, start: float, wall_share: float = 1.0) -> Section:
    """The :class:`Section` of the crossings ``t, raw`` (rows: the integrator's state at each) from
    ``y0``; ``runtime``: the member's runtime parameters (:meth:`TaylorSystem.runtime_parameters`)."""
    tally.count(integrations=1, crossings=len(t))
    system = req.system
    kernels = req.prep.kernels
    n = kernels.n
    warnings: list[str] = []

    x = raw[:, :n]
    tau = raw[:, n] if kernels.has_tau else None
    if len(t):
        # One Newton step along the flow: undo the rounding of the event time to a double.
        rows = kernels.evaluate(x, runtime, req.value)
        delta = rows[kernels.delta]
        size = np.abs(delta)
        # accepted up to _BOUND·max(t, max_h) (t >= 0): all of them when the largest is within _BOUND·max_h
        ok = size.max() <= _BOUND * max_h or (size <= _BOUND * np.maximum(t, max_h)).all()  # False if not finite
        if not ok:  # nearly tangent crossings keep their points
            ok = size <= _BOUND * np.maximum(t, max_h)
            delta[~ok] = 0.0
            warnings.append(f"{int(np.sum(~ok))} crossing(s) nearly tangent to the surface (dS/dt ~ 0): their "
                            "points are the integrator's event points, not refined onto the surface")
        x = x + rows[kernels.flow].T * delta[:, None]
        t = t + delta
        if tau is not None:
            tau = tau + rows[kernels.density] * delta
    else:
        x = x.copy()
        warnings.append(f"no crossing of {req.text!r} = {req.value:g} ({req.direction}) in 0 <= t <= "
                        f"{req.t_final:g}")
    if stopped_early:
        warnings.append(f"max_points = {req.max_points} reached at t = {t[-1]:.9g}; the integration stopped "
                        f"there instead of at t_final = {req.t_final:g}")

    # Everything reported, evaluated at the initial state (column 0) and the points in one call.
    report = kernels.evaluate(np.vstack([y0[None, :], x]), runtime, req.value)
    points: dict[str, np.ndarray] = {vec.name: x[:, cols] for vec, cols in zip(system.state, kernels.slices)}
    for name, derived_rows in kernels.derived:
        points[name] = report[derived_rows, 1:].T
    coordinates = np.empty((len(t), 2))
    for j, name in enumerate(req.coordinates):
        vec, i = req.prep.locate[name]
        coordinates[:, j] = points[vec][:, i]

    scale = _scale(report[kernels.natural_scale, 1:], req.value)
    residual = float(np.abs(report[kernels.residual, 1:]).max()) / scale if len(t) else 0.0

    drift: dict[str, float] = {}
    if system.integrals:
        values = report[kernels.integrals]
        deviation = np.abs(values - values[:, :1]).max(axis=1).tolist()
        natural = np.maximum(np.abs(values[:, 0]), np.abs(report[kernels.integral_scales]).max(axis=1)).tolist()
        drift = {claim.name: d / (r if r > 0 else 1.0) for claim, d, r in zip(system.integrals, deviation, natural)}

    section = object.__new__(Section)  # every field set at once (the frozen dataclass sets them one by one)
    section.__dict__.update(
        surface=req.text, value=req.value, direction=req.direction, t=t, tau=tau, points=points,
        coordinate_names=req.coordinates, coordinates=coordinates, surface_residual_max=residual,
        surface_scale=scale, integral_drift_max=drift, stopped_early=stopped_early, warnings=tuple(warnings),
        steps=int(steps), wall_time_s=(time.perf_counter() - start) * wall_share, t_final=req.t_final,
        tolerance=req.tolerance,
    )
    return section
