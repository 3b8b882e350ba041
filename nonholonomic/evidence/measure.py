"""Invariant measures: ``div(ρ f) = 0`` for the claimed density ρ, symbolically and pointwise.

Symbolic: ``div(ρ f) = ρ (div f + (f, ∇ ln ρ))``, and for the paper's densities the bracket is a
rational function of the state; it is put over a common denominator and its numerator expanded.
The proof is parameter-free (parameters stay symbols), runs to its end and is cached per process
(:mod:`nonholonomic.bounded`); it is tried only on a bracket of at most ``max_proof_ops`` sympy operations
(:mod:`nonholonomic.work_limits`), else the verdict is undecided with that reason, the same on every
machine. Pointwise: the exact derivatives ``∂(ρ f_i)/∂x_i`` (symbolic differentiation, compiled) at
sampled states; the residual is ``|Σ_i ∂(ρ f_i)/∂x_i| / Σ_i |∂(ρ f_i)/∂x_i|`` (relative to the size
of the terms that cancel), maximised over the states.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import sympy as sp

from nonholonomic import bounded, work_limits
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.kernels import numeric
from nonholonomic.work_limits import WorkLimits, operations, over

#: Pointwise relative residual accepted as round-off.
POINTWISE_TOLERANCE = 1e-10


@dataclass(frozen=True)
class CheckEvidence:
    """One machine check: what was checked, how, against which tolerance, and the verdict.

    ``passed`` is None when the check could not decide (e.g. the proof was past a work limit of
    :mod:`nonholonomic.work_limits`, or sympy could not reduce it); ``detail`` then says why.
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


@lru_cache(maxsize=128)
def _to_prove(system: MechanicalSystem, density: sp.Expr) -> tuple[sp.Expr, str]:
    """``div(ρ f)/ρ`` as the proof takes it (on the claim's invariant manifold, if any), and where."""
    bracket = divergence_bracket(system, density)
    where = ""
    if system.measure.on_manifold:  # the claim holds on an invariant manifold: its equations solved first
        bracket = bracket.xreplace(dict(system.measure.on_manifold))
        where = (" on the invariant manifold ("
                 + ", ".join(f"{s} = {sp.sstr(e)}" for s, e in system.measure.on_manifold) + ")")
    return bracket, where


def _prove(system: MechanicalSystem, density: sp.Expr) -> tuple[bool | None, str]:
    bracket, where = _to_prove(system, density)
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


def _not_tried(system: MechanicalSystem, density: sp.Expr, limits: WorkLimits) -> str | None:
    """Why the proof is not tried (its bracket past ``limits.max_proof_ops``), or None."""
    return over(operations(_to_prove(system, density)[0]), limits.max_proof_ops, "max_proof_ops",
                "div(rho f)/rho: the symbolic proof")


def start_divergence_proof(system: MechanicalSystem, density: sp.Expr | None = None,
                           limits: WorkLimits = work_limits.DEFAULT) -> None:
    """Start the proof of :func:`symbolic_divergence_vanishes` in its own thread and return at once (a
    later call of it waits for the same computation). Nothing is started past the size limit."""
    density = system.measure.density if density is None else density
    if system.measure.verified is not None:
        return
    if density is not None and _not_tried(system, density, limits) is None:
        bounded.start(("measure", system, density), _prove, (system, density))


def symbolic_divergence_vanishes(system: MechanicalSystem, density: sp.Expr | None = None,
                                 limits: WorkLimits = work_limits.DEFAULT) -> tuple[bool | None, str]:
    """Whether ``div(ρ f) ≡ 0`` identically (parameters symbolic).

    Parameters
    ----------
    system : the system (its field ``rhs``; its claim's invariant manifold, if any).
    density : ρ (default: the system's claimed density).
    limits : the proof is tried on a bracket ``div(ρ f)/ρ`` of at most ``limits.max_proof_ops`` sympy
        operations; past it the verdict is None with that reason.

    Returns
    -------
    (verdict, detail)
        True (proved), False (a non-zero numerator), None (undecided, the detail says why). The proof
        runs to its end and is cached (:mod:`nonholonomic.bounded`).

    Raises
    ------
    nonholonomic.bounded.SafetyCapExceeded
        If the proof outlives the service's safety cap (a failure, not a verdict).
    """
    density = system.measure.density if density is None else density
    if density is None:
        return None, "no invariant measure is claimed for this system: " + system.measure.formula
    skipped = _not_tried(system, density, limits)
    if skipped is not None:
        return None, skipped
    return bounded.prove(("measure", system, density), _prove, (system, density))


def pointwise_divergence_residual(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> float:
    """``max |div(ρ f)| / Σ|∂(ρ f_i)/∂x_i|`` over ``states`` (shape ``(n, dim)``)."""
    terms = numeric(system).divergence_terms(states, parameters)
    scale = np.sum(np.abs(terms), axis=1)
    scale = np.where(scale > 0, scale, 1.0)
    return float(np.max(np.abs(np.sum(terms, axis=1)) / scale))


def measure_evidence(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray,
                     limits: WorkLimits = work_limits.DEFAULT, max_points: int = 200) -> list[CheckEvidence]:
    """Symbolic and pointwise evidence that ``system.measure`` is invariant.

    ``states`` (e.g. a trajectory's samples) are thinned to at most ``max_points``; ``limits`` bounds the
    symbolic proof (:func:`symbolic_divergence_vanishes`).
    """
    claim = system.measure
    if claim.density is None:
        return [CheckEvidence(name="invariant_measure", quantity="div(rho f)", formula=claim.formula,
                              equation=claim.equation, method="symbolic", residual=None, tolerance=None, passed=None,
                              detail="no invariant measure is claimed for this system: " + claim.formula)]
    if claim.verified is not None:  # no closed form of the field: established by a randomized identity test
        first = CheckEvidence(name="invariant_measure", quantity="div(rho f)", formula=claim.formula,
                              equation=claim.equation, method="randomized identity test", residual=None,
                              tolerance=None, passed=True, detail=claim.verified)
    else:
        proven, detail = symbolic_divergence_vanishes(system, limits=limits)
        first = CheckEvidence(name="invariant_measure", quantity="div(rho f)", formula=claim.formula,
                              equation=claim.equation, method="symbolic", residual=0.0 if proven else None,
                              tolerance=0.0, passed=proven, detail=detail + "; parameters kept symbolic")
    idx = np.unique(np.linspace(0, len(states) - 1, min(len(states), max_points)).astype(int))
    residual = pointwise_divergence_residual(system, parameters, states[idx])
    return [
        first,
        CheckEvidence(
            name="invariant_measure", quantity="div(rho f)", formula=claim.formula, equation=claim.equation,
            method="pointwise", residual=residual, tolerance=POINTWISE_TOLERANCE,
            passed=bool(np.isfinite(residual) and residual <= POINTWISE_TOLERANCE),
            detail=f"max over {len(idx)} trajectory samples of |sum_i d(rho f_i)/dx_i| / sum_i |d(rho f_i)/dx_i|, "
                   "derivatives exact (symbolic, compiled)"
                   + ("; the samples lie on the invariant manifold the claim is made on" if claim.on_manifold else ""),
        ),
    ]
