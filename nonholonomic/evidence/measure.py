"""Invariant measures: ``div(ρ f) = 0`` for the claimed density ρ, symbolically and pointwise.

Symbolic: ``div(ρ f) = ρ (div f + (f, ∇ ln ρ))``, and for the paper's densities the bracket is a
rational function of the state; it is put over a common denominator and its numerator expanded.
The proof is parameter-free (parameters stay symbols), runs under a time budget and is cached per
process. Pointwise: the exact derivatives ``∂(ρ f_i)/∂x_i`` (symbolic differentiation, compiled) at
sampled states; the residual is ``|Σ_i ∂(ρ f_i)/∂x_i| / Σ_i |∂(ρ f_i)/∂x_i|`` (relative to the size
of the terms that cancel), maximised over the states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from nonholonomic import bounded
from nonholonomic.definition import MechanicalSystem
from nonholonomic.kernels import numeric

#: Pointwise relative residual accepted as round-off.
POINTWISE_TOLERANCE = 1e-10
#: Seconds the symbolic proof may take before the check falls back to pointwise only.
SYMBOLIC_BUDGET_S = 20.0


@dataclass(frozen=True)
class CheckEvidence:
    """One machine check: what was checked, how, against which tolerance, and the verdict.

    ``passed`` is None when the check could not decide (e.g. the symbolic budget ran out).
    """

    name: str
    quantity: str
    formula: str
    equation: str
    method: str
    residual: float | None
    tolerance: float | None
    passed: bool | None
    detail: str


def divergence_bracket(system: MechanicalSystem, density: sp.Expr) -> sp.Expr:
    """``div f + (f, ∇ ln ρ)`` = ``div(ρ f) / ρ`` as an unsimplified sympy expression."""
    x = system.state_symbols
    # ln ρ with products and powers split (ρ > 0): ln R^(-1/2) = -ln R/2 leaves no root to differentiate
    log_rho = sp.expand_log(sp.log(density), force=True)
    return sum(sp.diff(f, xi) + f * sp.diff(log_rho, xi) for f, xi in zip(system.rhs, x))


def _prove(system: MechanicalSystem, density: sp.Expr) -> tuple[bool | None, str]:
    bracket = divergence_bracket(system, density)
    where = ""
    if system.measure.on_manifold:  # the claim holds on an invariant manifold: its equations solved first
        bracket = bracket.xreplace(dict(system.measure.on_manifold))
        where = (" on the invariant manifold (" + ", ".join(f"{s} = {sp.sstr(e)}" for s, e in system.measure.on_manifold)
                 + ")")
    numerator = sp.expand(sp.numer(sp.together(bracket)))
    if numerator == 0:
        return True, f"numerator of div(rho f)/rho over a common denominator expands to 0{where}"
    angles = tuple(sorted({x for f in numerator.atoms(sp.sin, sp.cos) for x in f.free_symbols
                           if x in system.state_symbols}, key=str))
    if angles:  # sin² + cos² = 1 is not seen by expand: decide it with t = tan(q/2)
        from nonholonomic.rational_trig import rational_trig_is_zero

        verdict = rational_trig_is_zero(numerator, angles)
        if verdict is True:
            return True, f"numerator of div(rho f)/rho vanishes identically after t = tan(q/2) for the angles{where}"
        if verdict is None:
            return None, f"div(rho f)/rho{where}: not reduced to a rational function of tan(q/2) (square roots left)"
    return False, f"div(rho f)/rho{where} has a non-zero numerator with {len(sp.Add.make_args(numerator))} terms"


def symbolic_divergence_vanishes(system: MechanicalSystem, density: sp.Expr | None = None,
                                 budget_s: float = SYMBOLIC_BUDGET_S) -> tuple[bool | None, str]:
    """Whether ``div(ρ f) ≡ 0`` identically (parameters symbolic). None if undecided in ``budget_s``.

    The proof keeps running after a timeout and later calls get its result
    (:mod:`nonholonomic.bounded`).
    """
    density = system.measure.density if density is None else density
    return bounded.prove(("measure", system, density), _prove, (system, density), budget_s)


def pointwise_divergence_residual(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> float:
    """``max |div(ρ f)| / Σ|∂(ρ f_i)/∂x_i|`` over ``states`` (shape ``(n, dim)``)."""
    terms = numeric(system).divergence_terms(states, parameters)
    scale = np.sum(np.abs(terms), axis=1)
    scale = np.where(scale > 0, scale, 1.0)
    return float(np.max(np.abs(np.sum(terms, axis=1)) / scale))


def measure_evidence(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray,
                     budget_s: float = SYMBOLIC_BUDGET_S, max_points: int = 200) -> list[CheckEvidence]:
    """Symbolic and pointwise evidence that ``system.measure`` is invariant.

    ``states`` (e.g. a trajectory's samples) are thinned to at most ``max_points``.
    """
    claim = system.measure
    if claim.density is None:
        return [CheckEvidence(name="invariant_measure", quantity="div(rho f)", formula=claim.formula,
                              equation=claim.equation, method="symbolic", residual=None, tolerance=None, passed=None,
                              detail="no invariant measure is claimed for this system: " + claim.formula)]
    proven, detail = symbolic_divergence_vanishes(system, budget_s=budget_s)
    idx = np.unique(np.linspace(0, len(states) - 1, min(len(states), max_points)).astype(int))
    residual = pointwise_divergence_residual(system, parameters, states[idx])
    return [
        CheckEvidence(
            name="invariant_measure", quantity="div(rho f)", formula=claim.formula, equation=claim.equation,
            method="symbolic", residual=0.0 if proven else None, tolerance=0.0,
            passed=proven, detail=detail + "; parameters kept symbolic",
        ),
        CheckEvidence(
            name="invariant_measure", quantity="div(rho f)", formula=claim.formula, equation=claim.equation,
            method="pointwise", residual=residual, tolerance=POINTWISE_TOLERANCE,
            passed=bool(np.isfinite(residual) and residual <= POINTWISE_TOLERANCE),
            detail=f"max over {len(idx)} trajectory samples of |sum_i d(rho f_i)/dx_i| / sum_i |d(rho f_i)/dx_i|, "
                   "derivatives exact (symbolic, compiled)"
                   + ("; the samples lie on the invariant manifold the claim is made on" if claim.on_manifold else ""),
        ),
    ]
