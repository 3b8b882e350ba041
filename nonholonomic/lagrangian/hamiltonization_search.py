"""Theorem 1 for a user's Lagrangian system that is a Chaplygin system with two shape coordinates: the
reducing multiplier N, the time dτ = N dt (eq. 2704-8) and the Hamiltonian form (2704-9) of the reduced
system, as a form of the user's system in its state (q, q̇).

The reduction (:func:`nonholonomic.lagrangian.chaplygin.chaplygin_reduction`) gives the generalized
Chaplygin system (2704-7) in the shape coordinates; :func:`nonholonomic.systems.generalized_chaplygin.theorem_1`
gives N and the form in (q₁, q₂, p₁, p₂), p = N ∂L*/∂q̇. Its map from the state uses only the shape
coordinates and velocities, so it is a map of the user's state; the flow = Hamiltonian field check then runs
on the trajectory (which is on the constraint manifold, where the reduced field is the user's field).

A form is given only when the reduced field is *proven* equal to the Lagrange–d'Alembert field of the user's
system on the constraint manifold (the dependent velocities substituted, the difference cancelled), so that
Theorem 1's proof for (2704-7) applies to the user's equations. Theorem 1 is tried with the parameters
symbolic, then (when it finds no multiplier) at their values exactly (the sleigh with a = 0 has one that a
symbolic a hides).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import sympy as sp

from nonholonomic import bounded
from nonholonomic.definition import ReducedTime
from nonholonomic.expressions.smoothness import analytic_and_positive
from nonholonomic.lagrangian.chaplygin import ChaplyginReduction, chaplygin_reduction
from nonholonomic.lagrangian.equations import derive, tidy
from nonholonomic.lagrangian.parse import KIND, LagrangianData
from nonholonomic.numerics.precision import working_digits

__all__ = ["Hamiltonization", "hamiltonization"]

#: A difference of the two fields with at most this many operations is cancelled symbolically.
CANCEL_OPS = 400
#: Random exact states of the identity test of larger differences.
IDENTITY_POINTS = 4


@dataclass(frozen=True)
class Hamiltonization:
    """Theorem 1's verdict for a user's system.

    Attributes
    ----------
    form : HamiltonianForm or None
        In the user's state; None when there is none (``summary`` says why).
    reduced_time : ReducedTime or None
        dτ = N dt when there is a form.
    summary : dict
        JSON: ``verdict`` (``found``, ``none`` when Theorem 1 gives no multiplier, ``not applicable`` when
        the system is not a Chaplygin system with 2 shape coordinates, ``undecided``), ``reason`` and, when
        reduced, the reduced system (2704-7) and N.
    shape : tuple of int
        The shape coordinates' indices, when found.
    L_star : sympy.Expr or None
        The reduced Lagrangian's velocity terms (the kinetic matrix M* = ∂²L*/∂q̇²), when found.
    """

    form: Any
    reduced_time: ReducedTime | None
    summary: dict[str, Any]
    shape: tuple[int, ...] = ()
    L_star: sp.Expr | None = None


def _reduced_text(reduction: ChaplyginReduction) -> dict[str, Any]:
    data = reduction.data
    assert data is not None
    texts = dict(data.texts)
    return {"shape": [str(s) for s in data.q],
            "cyclic_velocities": {str(s): sp.sstr(e) for s, e in reduction.dependent},
            "L_star": texts["L"], "U": texts["potential"], "a1": texts["a1"], "a2": texts["a2"],
            "b": texts["b"], "equation": "2704-7"}


def _same_field(data: LagrangianData, reduction: ChaplyginReduction) -> tuple[bool | None, str]:
    """Whether the reduced accelerations (2704-7) equal the user's shape accelerations on the manifold: each
    difference cancelled to 0 when it is small enough, else a randomized identity test (exact rational
    states and parameters, 50 digits; a rational function of the state, sin and cos that vanishes at
    :data:`IDENTITY_POINTS` random points is 0 but with negligible probability)."""
    import mpmath

    from nonholonomic.systems.generalized_chaplygin import accelerations

    reduced_data = reduction.data
    assert reduced_data is not None  # called on a reduced system only
    eqs = derive(data)
    on = dict(reduction.dependent)
    rng = np.random.default_rng(20261126)
    variables = (*data.q, *data.v, *data.parameters)
    points = [[mpmath.mpf(int(rng.integers(150, 850))) / 1000 for _ in variables] for _ in range(IDENTITY_POINTS)]
    if data.parameters:  # the parameters' own values at the first point (the job's system)
        points[0][len(data.q) + len(data.v):] = [mpmath.mpf(v) for v in data.values]
    how = "cancelled to 0"
    for i, reduced in zip(reduction.shape, accelerations(reduced_data)):
        user = eqs.qddot[i].xreplace(on)
        difference = user - reduced
        if sp.count_ops(difference) <= CANCEL_OPS and tidy(difference) == 0:
            continue
        user_at, reduced_at = (sp.lambdify(variables, e, modules="mpmath") for e in (user, reduced))
        with working_digits(50):
            for point in points:
                a, b = user_at(*point), reduced_at(*point)
                if abs(a - b) > mpmath.mpf(10) ** -40 * (abs(a) + 1):
                    return False, f"the accelerations differ by {float(abs(a - b)):.3g} at a random state"
        how = f"equal at {IDENTITY_POINTS} random states to 50 digits (randomized identity test)"
    return True, how


def _hamiltonization(data: LagrangianData) -> Hamiltonization:
    """Theorem 1 for ``data`` through its Chaplygin reduction, or why not.

    Parameters
    ----------
    data : LagrangianData
        Parsed and checked, autonomous.

    Returns
    -------
    Hamiltonization
    """
    from nonholonomic.systems.generalized_chaplygin import theorem_1

    reduction = chaplygin_reduction(data)
    if reduction.data is None:
        return Hamiltonization(None, None, {"verdict": "not applicable", "reason": reduction.reason})
    summary: dict[str, Any] = {"reduced": _reduced_text(reduction)}
    same, how = _same_field(data, reduction)
    if same is not True:
        return Hamiltonization(None, None, {**summary, "verdict": "undecided", "reason": (
            "the Chaplygin reduction's field was not shown equal to the Lagrange-d'Alembert field on the "
            f"constraint manifold: {how}")})
    form, why = theorem_1(reduction.data)
    at_values = ""
    L_star = reduction.data.L
    if form is None and data.parameters:
        exact = chaplygin_reduction(data, at_values=True)
        if exact.data is not None:
            form, _ = theorem_1(exact.data)
            L_star = exact.data.L
            at_values = " (at the parameters' values; with them symbolic: " + why + ")" if form is not None else ""
    if form is None:
        return Hamiltonization(None, None, {**summary, "verdict": "none", "reason": (
            f"Theorem 1 gives no reducing multiplier for the reduced system (2704-7): {why}")})
    n = len(data.q)
    shape = reduction.shape
    N = form.time_density
    proven = form.proof[0] if how == "cancelled to 0" else None  # a randomized test is evidence, not a proof
    proof = (proven, form.proof[1] + "; the reduced system (2704-7) is the Lagrange-d'Alembert field on the "
                                     f"constraint manifold ({how})")
    form = replace(form, system_kind=KIND, proof=proof, from_indices=(*shape, *(n + i for i in shape)))
    reduced_time = ReducedTime(N, f"d tau = N dt, N = {sp.sstr(N)} (Theorem 1, on the Chaplygin reduction)", "2704-8",
                               "s (times N's unit)", regular=analytic_and_positive(N))
    return Hamiltonization(form, reduced_time, {**summary, "verdict": "found", "reducing_multiplier": sp.sstr(N),
                                                "hamiltonian_form": form.formula,
                                                "reason": "Theorem 1: N solves dN/dq1 = N A2, dN/dq2 = -N A1 "
                                                          "(the integrability condition "
                                                          f"holds){at_values}; the reduced system is the user's "
                                                          f"field on the constraint manifold ({how})",
                                                "at_values": bool(at_values)}, shape, L_star)


def hamiltonization(data: LagrangianData) -> Hamiltonization:
    """Theorem 1 for ``data`` through its Chaplygin reduction, or why not.

    The reduction, the field comparison and Theorem 1 run to their end (:func:`nonholonomic.bounded.run`);
    their sizes are bounded by deterministic limits (``CANCEL_OPS``, the work limits of
    :func:`nonholonomic.hamiltonization.reducing_multiplier.hamiltonize`), so the verdict is the same on every machine.

    Parameters
    ----------
    data : LagrangianData
        Parsed and checked, autonomous.

    Returns
    -------
    Hamiltonization
    """
    outcome = bounded.run(("lagrangian.hamiltonization", data), _hamiltonization, (data,))
    if outcome.status != "done":
        return Hamiltonization(None, None, {"verdict": "undecided", "reason": f"sympy failed: {outcome.message}"})
    return outcome.value
