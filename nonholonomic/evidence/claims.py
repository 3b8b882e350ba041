"""A researcher's own claims of conservation: a candidate integral or Casimir ``I(x)``, checked along
the trajectory (its drift, as for the system's integrals) and symbolically (its derivative along the
field, ``dI/dt = Σ ∂I/∂x_i f_i``, is identically zero: a proof run to its end, tried on a derivative of
at most ``max_proof_ops`` sympy operations, :mod:`nonholonomic.work_limits`).

The expression is parsed by the safe parser (:mod:`nonholonomic.expressions`, no eval) in the state
components and the parameters' symbols of the system (``M1``, ``gamma3``, ``I1``, ``D``, a user
potential's ``q`` ...).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import sympy as sp

from nonholonomic import bounded, work_limits
from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.integrals import integral_tolerance
from nonholonomic.expressions import _name_problem, parse_expression
from nonholonomic.numerics.integration import Trajectory
from nonholonomic.numerics.kernels import vectorize
from nonholonomic.work_limits import WorkLimits, operations, over

#: Largest numerator (terms) handed to ``sympy.simplify`` (functions of the state, e.g. trigonometric).
MAX_SIMPLIFY_TERMS = 200
#: Most claims a job may carry.
MAX_CLAIMS = 10


@dataclass(frozen=True)
class ClaimEvidence:
    """One claimed integral: its drift along the trajectory, and whether ``dI/dt ≡ 0``.

    ``max_rel_drift = max |I − I(0)| / max(|I(0)|, max |I|)`` over the samples and the accepted steps.
    ``symbolic`` is True (proven identically zero), False (not identically zero: it may still hold on
    the constraints' level set, e.g. |γ| = 1), or None (undecided: ``symbolic_detail`` says why, e.g. the
    derivative is past ``max_proof_ops``).
    """

    name: str
    expression: str
    initial: float
    final: float
    max_rel_drift: float
    tolerance: float
    passed: bool
    symbolic: bool | None
    symbolic_detail: str
    #: Samples and steps where ``I`` is not finite (its drift is then not finite, and ``passed`` False).
    not_finite_points: int = 0


def claim_names(system: MechanicalSystem) -> dict[str, sp.Symbol]:
    """The names a claim may use: the state components and the parameters' symbols."""
    symbols = (*system.state_symbols, *system.parameter_symbols)
    return {str(s): s for s in symbols if _name_problem(str(s)) is None}


def parse_claim(system: MechanicalSystem, text: str) -> sp.Expr:
    """``I(x)`` from its text (raises :class:`nonholonomic.expressions.ExpressionError`)."""
    return parse_expression(text, claim_names(system))


def claim_initial_problem(system: MechanicalSystem, parameters: np.ndarray, state: np.ndarray,
                          claim: sp.Expr) -> str | None:
    """Why ``claim`` (from :func:`parse_claim`) cannot be checked from ``state`` (the initial state): its value
    there is not a finite real number (issue 34, item 3: refused at submission, not a job that always fails).
    None if it is."""
    args = (*system.state_symbols, *system.parameter_symbols)
    with np.errstate(all="ignore"):
        value = complex(vectorize([claim], args)(np.asarray(state, dtype=float)[None, :], parameters)[0, 0])
    if np.isfinite(value.real) and value.imag == 0:
        return None
    shown = value.real if value.imag == 0 else value
    return (f"its value at the initial state is {shown}: a claim must be a finite real number there (a power of a "
            "negative number, a logarithm of one, or a value past the floating-point range is not)")


def derivative_along_field(system: MechanicalSystem, claim: sp.Expr) -> sp.Expr:
    """``dI/dt = Σ ∂I/∂x_i f_i(x)``."""
    return sp.Add(*(sp.diff(claim, x) * f for x, f in zip(system.state_symbols, system.rhs)))


def _prove_zero(derivative: sp.Expr) -> tuple[bool, str]:
    numerator = sp.expand(sp.numer(sp.together(derivative)))
    if numerator == 0:
        return True, "dI/dt = sum dI/dx_i f_i has a numerator that expands to 0"
    terms = len(sp.Add.make_args(numerator))
    if numerator.has(sp.Function) and terms <= MAX_SIMPLIFY_TERMS and sp.simplify(numerator) == 0:
        return True, "dI/dt = sum dI/dx_i f_i simplifies to 0"
    return False, f"dI/dt is not identically zero ({terms} terms); it may still vanish on the constraints' level set"


def claim_evidence(system: MechanicalSystem, parameters: np.ndarray, trajectory: Trajectory,
                   claims: Sequence[tuple[str, str]],
                   limits: WorkLimits = work_limits.DEFAULT) -> list[ClaimEvidence]:
    """Evidence for each ``(name, expression)`` claim on ``trajectory`` (the system's parameter vector
    ``parameters``): the drift at the samples and steps, and the symbolic verdict on ``dI/dt`` (a proof
    run to its end, tried on a derivative of at most ``limits.max_proof_ops`` sympy operations; past it
    the verdict is None with that reason).

    Raises
    ------
    nonholonomic.bounded.SafetyCapExceeded
        If a proof outlives the service's safety cap (a failure, not a verdict).
    """
    out = []
    points = np.vstack([trajectory.states, trajectory.step_states])
    tol = integral_tolerance(trajectory.tolerance)
    args = (*system.state_symbols, *system.parameter_symbols)
    for name, text in claims:
        claim = parse_claim(system, text)
        with np.errstate(all="ignore"):
            values = vectorize([claim], args)(points, parameters)[:, 0]
        initial, final = float(values[0]), float(values[len(trajectory.t) - 1])
        finite = np.isfinite(values)
        if finite.all():
            reference = max(abs(initial), float(np.max(np.abs(values)))) or 1.0
            drift = float(np.max(np.abs(values - initial))) / reference
        else:  # not finite somewhere along the orbit: no drift to speak of, and not passed
            drift = float("nan")
        derivative = derivative_along_field(system, claim)
        skipped = over(operations(derivative), limits.max_proof_ops, "max_proof_ops", "dI/dt: the symbolic proof")
        if skipped is not None:
            proven, detail = None, skipped
        else:
            proven, detail = bounded.prove(("claim", system, claim), _prove_zero, (derivative,))
        out.append(ClaimEvidence(name=name, expression=text, initial=initial, final=final,
                                 max_rel_drift=drift, tolerance=tol,
                                 passed=bool(np.isfinite(drift) and drift <= tol), symbolic=proven,
                                 symbolic_detail=detail, not_finite_points=int(np.count_nonzero(~finite))))
    return out
