"""Pseudo-arclength continuation, the equations: the closing equations with the continued value as an unknown.

A branch of periodic orbits is a curve z(s) = (x₀, T, λ) of solutions of the closing equations of
:mod:`.newton` in which λ is

* a **level** of an integral (``"energy"``, or another of the system's integrals): that integral's row has
  target λ, the level's other integrals keep the seed's values; ∂R/∂λ is −1 in that row (scaled like it),
  zero elsewhere;
* a **parameter** (its index in the parameter vector): the whole level is held; ∂R/∂λ is ∂x(T)/∂λ from
  heyoka's parameter sensitivities (``hy.var_ode_sys`` with the state variables and the runtime parameters
  that λ moves as arguments, of the one definition: :func:`.newton.flow` with ``pars``) and ∂(rows)/∂λ of
  the algebraic rows.

The extended Jacobian J_λ = [J | ∂R/∂λ] has a one-dimensional kernel on a regular branch, folds included:
its unit kernel vector is the branch's tangent t (the smallest right singular vector, oriented along the
previous one). A step predicts z + h t and corrects by Gauss–Newton on R(z) = 0 with one more row,
t·(z − z_pred) = 0 (Keller's pseudo-arclength condition), which stays regular where λ turns back.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from nonholonomic.analysis.periodic_orbit.newton import Closing, Flow, flow
from nonholonomic.numerics.integration import IntegrationError
from nonholonomic.numerics.taylor import taylor_system

#: The corrector stops when the scaled residual is below this ...
CORRECTOR_TARGET = 1e-12
#: ... and accepts a point whose residual is below this (the one-orbit search's closing tolerance).
CORRECTOR_ACCEPT = 1e-9
#: Gauss–Newton iterations of one correction.
CORRECTOR_ITERATIONS = 8
#: Relative step of the central difference of the derived runtime parameters in λ (algebraic functions).
DERIVED_STEP = 1e-6


@dataclass(frozen=True)
class Continued:
    """What λ is: ``level_row`` (the algebraic row of the integral whose target λ is) or ``parameter_index``
    (λ = p[index])."""

    name: str
    level_row: int | None = None
    parameter_index: int | None = None


@dataclass
class ArcClosing(Closing):
    """The closing equations R(x₀, T, λ) = 0 of a branch and their Jacobian J_λ = [J | ∂R/∂λ], the last
    evaluation kept (z = (x₀, T, λ); ``p`` and ``targets`` are the start's, λ replaces what it moves)."""

    continued: Continued = field(default_factory=lambda: Continued(""))
    _moved: tuple[int, ...] | None = field(default=None, repr=False)

    def parameters(self, lam: float) -> np.ndarray:
        """The parameter vector at λ."""
        p = self.p.copy()
        if self.continued.parameter_index is not None:
            p[self.continued.parameter_index] = lam
        return p

    def targets_at(self, lam: float) -> np.ndarray:
        """The rows' targets at λ."""
        targets = self.targets.copy()
        if self.continued.level_row is not None:
            targets[self.continued.level_row] = lam
        return targets

    def _moved_pars(self, lam: float) -> tuple[tuple[int, ...], np.ndarray]:
        """The runtime parameters λ moves and their derivatives at λ (the user's parameter exactly, derived ones by a
        central difference of their algebraic formulas). Which ones move is fixed at the first call, so one
        sensitivity integrator serves the whole branch."""
        ts = taylor_system(self.system)
        h = DERIVED_STEP * max(1.0, abs(lam))
        up, down = ts.runtime_parameters(self.parameters(lam + h)), ts.runtime_parameters(self.parameters(lam - h))
        d = (up - down) / (2 * h)
        index = self.continued.parameter_index
        assert index is not None
        d[index] = 1.0
        if self._moved is None:
            self._moved = tuple(int(i) for i in np.flatnonzero(np.abs(d) > 1e-12 * max(1.0, float(np.max(np.abs(d))))))
        return self._moved, d[list(self._moved)]

    def evaluate(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, Flow]:
        """R(z), J_λ(z) (rows × (n + 2)) and the flow, for z = (x₀, T, λ)."""
        key = z.tobytes()
        if self._last is not None and self._last[0] == key:
            return self._last[1], self._last[2], self._last[3]
        n = self.system.dimension
        x0, t, lam = z[:n], float(z[n]), float(z[n + 1])
        p = self.parameters(lam)
        self.cancel.tick()
        if self.continued.parameter_index is None:
            fl = flow(self.system, p, x0, t, self.tolerance)
        else:
            fl = flow(self.system, p, x0, t, self.tolerance, *self._moved_pars(lam))
        R, J, norms = self.assemble(x0, p, self.targets_at(lam), fl, 1)
        if fl.dx_dlambda is not None:
            J[:n, n + 1] = fl.dx_dlambda / self.scale
        if self.continued.level_row is not None:
            J[n + self.continued.level_row, n + 1] = -1.0 / norms[self.continued.level_row] / self.scale
        else:
            h = DERIVED_STEP * max(1.0, abs(lam))
            up = self.rows.values(x0[None, :], self.parameters(lam + h))[0]
            down = self.rows.values(x0[None, :], self.parameters(lam - h))[0]
            J[n:, n + 1] = (up - down) / (2 * h) / norms / self.scale
        self._last = (key, R, J, fl)
        return R, J, fl


def tangent(J: np.ndarray, previous: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The unit kernel vector of J_λ (its smallest right singular vector), oriented along ``previous``; and the
    ratio of its second-smallest to largest singular value (near 0: the kernel is not one-dimensional, a
    branch point or a family of orbits)."""
    _, sv, vt = np.linalg.svd(J)
    t = vt[-1].copy()
    if previous is not None and float(t @ previous) < 0:
        t = -t
    return t, float(sv[-2] / sv[0]) if len(sv) >= 2 else 1.0


@dataclass
class Correction:
    """The corrector's outcome: the point, its residual, iterations, and the last Jacobian and flow."""

    z: np.ndarray
    residual: float
    iterations: int
    J: np.ndarray
    flow: Flow | None
    converged: bool


def correct(closing: ArcClosing, z_pred: np.ndarray, normal: np.ndarray, offset: float,
            record: Callable[[float], None] | None = None) -> Correction:
    """Gauss–Newton on R(z) = 0 with the extra row ``normal · z = offset`` from ``z_pred``.

    Pseudo-arclength: ``normal`` the tangent and ``offset = normal · z_pred``; a fixed λ: ``normal`` the unit
    vector of λ and ``offset`` its value.
    """
    z = z_pred.copy()
    best: Correction | None = None
    for i in range(CORRECTOR_ITERATIONS + 1):
        try:
            R, J, fl = closing.evaluate(z)
        except IntegrationError:
            break
        extra = float(normal @ z - offset)
        r = max(float(np.max(np.abs(R))), abs(extra))
        if record is not None:
            record(r)
        if best is not None and not r < best.residual:
            break
        best = Correction(z.copy(), r, i, J, fl, r <= CORRECTOR_ACCEPT)
        if r <= CORRECTOR_TARGET or i == CORRECTOR_ITERATIONS:
            break
        A = np.vstack([J, normal[None, :]])
        step = np.linalg.lstsq(A, -np.append(R, extra), rcond=1e-14)[0]
        n = closing.system.dimension
        if not np.all(np.isfinite(step)) or abs(step[n]) > 0.5 * z[n]:
            break
        z = z + step
    if best is None:
        return Correction(z_pred, float("inf"), 0, np.zeros((0, 0)), None, False)
    return best
