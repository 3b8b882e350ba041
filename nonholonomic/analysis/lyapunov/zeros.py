"""Which Lyapunov exponents must vanish, and why (:mod:`nonholonomic.analysis.lyapunov`).

The variational equations live in the ambient coordinates (6 for the ball: M, γ), where the
constraints (|γ| = 1, Φ(x) = 0 ...) are first integrals too. One exponent vanishes for the time
direction (f(x(t)) = Φ f(x(t₀)) stays bounded and away from 0 on a bounded orbit off equilibria) and
one for each functionally independent first integral I (the covector dI is carried unchanged by the
adjoint flow). Dependent ones (|γ| = 1 beside (γ, γ)) are listed but not counted. If the measure
holds and only one exponent is left, it vanishes too (the sum is 0). A reversing involution is
reported (a symmetric spectrum on an invariant ergodic component) but not counted.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import sympy as sp

from nonholonomic.analysis.lyapunov.variational import FRAME_SEED
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.kernels import VectorKernel, numeric, vectorize

#: Relative tolerance of the numerical rank of the integrals' gradients (normalised rows).
RANK_TOLERANCE = 1e-7
#: A constraint counts as a first integral if ``|∇c · f| ≤ this · |∇c| |f|`` on and off its level.
LIE_TOLERANCE = 1e-9


@dataclass(frozen=True)
class ExpectedZero:
    """One structural reason for a vanishing exponent.

    Attributes
    ----------
    reason : ``"time direction"``, ``"first integral energy (eq. 2604-2)"``, ``"constraint |gamma| = 1
        (eq. 2604-2)"`` or ``"invariant measure (eq. 2604-3)"``.
    formula : the integral's or constraint's formula (empty for the time direction).
    counted : whether it adds a zero exponent (False: dependent on those above, not conserved off
        its level set, or the orbit is an equilibrium).
    note : why it counts or not.
    """

    reason: str
    formula: str
    counted: bool
    note: str


@dataclass(frozen=True)
class _StructureKernels:
    gradients: VectorKernel  # rows: integrals, then constraints; n columns each (flattened)
    n_integrals: int
    n_constraints: int


@lru_cache(maxsize=16)
def _structure_kernels(system: MechanicalSystem) -> _StructureKernels:
    exprs = [i.expression for i in system.integrals] + [c.expression for c in system.constraints]
    flat = [sp.diff(e, x) for e in exprs for x in system.state_symbols] or [sp.Integer(0)]
    return _StructureKernels(vectorize(flat, system.state_symbols + system.parameter_symbols),
                             len(system.integrals), len(system.constraints))


def _rank(rows: np.ndarray) -> int:
    """Numerical rank of gradient rows (each normalised; zero rows do not count)."""
    norms = np.linalg.norm(rows, axis=1)
    rows = rows[norms > 0] / norms[norms > 0, None]
    if len(rows) == 0:
        return 0
    s = np.linalg.svd(rows, compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * s[0]))


def reversing_involution(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> str | None:
    """A linear reversing involution G that flips the sign of some state vectors, if the field has one:
    ``f(G x) = −G f(x)`` (so t → −t, x → G x maps orbits to orbits), checked numerically at ``states``
    and at random points near them. Returns e.g. ``"M -> -M"`` or None.
    """
    X = np.atleast_2d(states)
    probes = np.vstack([X, X + 1e-2 * (1 + np.abs(X)) * np.random.default_rng(FRAME_SEED).standard_normal(X.shape)])
    kernels = numeric(system)
    sizes = [len(v.symbols) for v in system.state]
    with np.errstate(all="ignore"):
        f = kernels.rhs(probes, parameters)
    for mask in range(1, 2 ** len(system.state)):
        signs = np.concatenate([np.full(k, -1.0 if mask >> i & 1 else 1.0) for i, k in enumerate(sizes)])
        with np.errstate(all="ignore"):
            g = kernels.rhs(probes * signs, parameters)
        residual = np.linalg.norm(g + f * signs, axis=1)
        if np.all(np.isfinite(residual)) and np.all(residual <= 1e-12 * np.maximum(np.linalg.norm(f, axis=1), 1e-300)):
            return ", ".join(f"{v.name} -> -{v.name}" for i, v in enumerate(system.state) if mask >> i & 1)
    return None


def expected_zeros(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray,
                   measure_holds: bool | None) -> tuple[ExpectedZero, ...]:
    """The structural reasons for vanishing exponents of the orbit through ``states`` (its ends).

    Parameters
    ----------
    system, parameters : the system and its parameter vector.
    states : a few states of the orbit, shape ``(k, n)`` (the gradients' independence is judged
        at each; a reason counts if it adds rank at any of them).
    measure_holds : whether the observed sum agrees with the claimed measure (None: unknown).

    Returns
    -------
    tuple of ExpectedZero
        Time direction, each first integral, each constraint and, where it decides the last one,
        the invariant measure; ``counted`` marks those that add a zero exponent.
    """
    n = system.dimension
    p = np.asarray(parameters, dtype=float)
    X = np.atleast_2d(states)
    kernels = numeric(system)
    sk = _structure_kernels(system)
    with np.errstate(all="ignore"):
        f = kernels.rhs(X, p)
        grads = sk.gradients(X, p).reshape(len(X), -1, n) if sk.n_integrals + sk.n_constraints else None
    out: list[ExpectedZero] = []
    moving = bool(np.all(np.isfinite(f)) and np.all(np.linalg.norm(f, axis=1) > 0))
    out.append(ExpectedZero(
        "time direction", "f(x)", moving,
        "the flow carries f(x(t0)) into f(x(t)), bounded and non-zero on a bounded orbit off equilibria"
        if moving else "f vanishes at the orbit (an equilibrium): no time direction"))
    basis: list[np.ndarray] = [np.empty((0, n)) for _ in X]

    def try_add(row_index: int) -> tuple[bool, str]:
        assert grads is not None  # a row index exists only when there are integrals or constraints
        rows = grads[:, row_index, :]
        if not np.all(np.isfinite(rows)):
            return False, "its gradient is not finite at the orbit"
        gained = False
        for k in range(len(X)):
            extended = np.vstack([basis[k], rows[k]])
            if _rank(extended) > _rank(basis[k]):
                gained = True
        if not gained:
            return False, "functionally dependent on the ones above at the orbit (adds no rank)"
        for k in range(len(X)):
            basis[k] = np.vstack([basis[k], rows[k]])
        return True, "independent: the adjoint flow keeps its gradient, one exponent vanishes"

    for i, integral in enumerate(system.integrals):
        counted, note = try_add(i)
        out.append(ExpectedZero(f"first integral {integral.name} (eq. {integral.equation})", integral.formula,
                                counted, note))
    rng = np.random.default_rng(FRAME_SEED)
    for j, constraint in enumerate(system.constraints):
        row = sk.n_integrals + j
        # A constraint is a first integral of the ambient flow only if ∇c · f vanishes off its level too.
        probes = np.vstack([X, X + 1e-2 * (1 + np.abs(X)) * rng.standard_normal(X.shape)])
        with np.errstate(all="ignore"):
            g = sk.gradients(probes, p).reshape(len(probes), -1, n)[:, row, :]
            fp = kernels.rhs(probes, p)
        lie = np.abs(np.einsum("ij,ij->i", g, fp))
        scale = np.linalg.norm(g, axis=1) * np.linalg.norm(fp, axis=1)
        conserved = bool(np.all(np.isfinite(lie)) and np.all(lie <= LIE_TOLERANCE * np.maximum(scale, 1e-300)))
        if not conserved:
            out.append(ExpectedZero(f"constraint {constraint.formula} (eq. {constraint.equation})", constraint.formula,
                                    False, "not conserved off its level set (an invariant manifold only): "
                                           "the exponent transverse to it need not vanish"))
            continue
        counted, note = try_add(row)
        out.append(ExpectedZero(f"constraint {constraint.formula} (eq. {constraint.equation})", constraint.formula,
                                counted, "conserved by the ambient flow; " + note))
    zeros = sum(z.counted for z in out)
    reversing = reversing_involution(system, p, X)
    if reversing is not None:
        out.append(ExpectedZero(
            f"reversibility ({reversing}, t -> -t)", reversing, False,
            "not counted: if the orbit's ergodic component is invariant under the involution (typical of a chaotic "
            "sea that meets its fixed set), the spectrum is symmetric, {lambda_i} = {-lambda_i}; with an odd "
            f"number ({n - zeros}) left beside the counted zeros one more then vanishes" if (n - zeros) % 2 else
            "not counted: if the orbit's ergodic component is invariant under the involution (typical of a chaotic "
            "sea that meets its fixed set), the spectrum is symmetric, {lambda_i} = {-lambda_i}"))
    if measure_holds and n - zeros == 1:
        out.append(ExpectedZero(
            f"invariant measure (eq. {system.measure.equation})", system.measure.formula, True,
            "the spectrum sums to 0 and only one exponent is left, so it vanishes too"))
    return tuple(out)
