"""A nonholonomic system written by the user as a Lagrangian L(q, q̇) in its own coordinates and constraints
linear and homogeneous in the velocities, as a :class:`MechanicalSystem` in the state (q, q̇).

The equations are the Lagrange–d'Alembert equations with the multipliers eliminated
(:func:`nonholonomic.lagrangian.derive`)::

    M(q) q̈ + h(q, q̇) = Aᵀ λ,   A(q) q̇ = 0,   M = ∂²L/∂q̇∂q̇,

the state being (q, q̇) (vectors ``q`` and ``q_dot``, n components each, n ≤ 8). Claimed along the motion:

* the energy E = (q̇, ∂L/∂q̇) − L (the constraint forces do no work: q̇ᵀAᵀλ = 0);
* every constraint fᵢ = Σⱼ Aᵢⱼ(q) q̇ⱼ, which stays 0 (the derived field keeps A q̇ constant);
* an invariant measure only when the search on the constraint manifold finds and proves one
  (:func:`nonholonomic.lagrangian.measure_search.measure_verdict`, with ``reduce``): ρ(q) dq du there, u the
  independent velocities. In the state (q, q̇) this is the density ρ(q) |det A_D(q)| (A_D the columns of
  A of the dependent velocities: (u, A q̇) are coordinates of q̇ with Jacobian det A_D), and div(ρ |det A_D| f)
  vanishes on the manifold, where the motion is (proven with the dependent velocities substituted,
  :attr:`InvariantMeasure.on_manifold`). A verdict ``none`` (an obstruction proven) or ``undecided`` claims
  nothing and says which in the ``measure`` check;
* with ``reduce``, the integrals linear and quadratic in the velocities that the ansatz search proves
  (:func:`nonholonomic.lagrangian.integral_search.integral_search`), each checked along the trajectory too;
* with ``reduce``, when the system is a Chaplygin system with two shape coordinates: Theorem 1's time
  dτ = N dt (integrated beside t) and Hamiltonian form, checked by the ``bracket`` check
  (:mod:`nonholonomic.lagrangian.hamiltonization_search`).

An initial q̇ off a constraint is refused (tolerance :data:`CONSTRAINT_TOLERANCE` relative to the
constraint's terms) or, on request, projected onto the constraints: orthogonally (Euclidean) onto the
rows of A made orthogonal by Gram–Schmidt, one constraint after the other, so that after the i-th
projection the first i constraints hold.

Jobs integrate autonomous systems: an L or a constraint with the time t explicitly is refused here
(:class:`~nonholonomic.lagrangian.DataError` naming the field).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from functools import lru_cache
from typing import Any

import sympy as sp

from nonholonomic.definition import (
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Parameter,
    Projection,
    StateConstraint,
    StateVector,
)
from nonholonomic.kinds import SystemKind
from nonholonomic.lagrangian import DataError, LagrangianData, derive
from nonholonomic.lagrangian.checks import number, sample_points
from nonholonomic.lagrangian.equations import energy_of, plain_field
from nonholonomic.lagrangian.hamiltonization_search import Hamiltonization, hamiltonization
from nonholonomic.lagrangian.integral_search import integral_search
from nonholonomic.lagrangian.measure_search import MeasureVerdict, implied_by_multiplier, measure_verdict
from nonholonomic.lagrangian.parse import KIND, MAX_COORDINATES, RESERVED, VELOCITY_SUFFIX
from nonholonomic.lagrangian.regular_forms import dependent_velocities, regular_density, regular_form
from nonholonomic.memo import remembered
from nonholonomic.systems.lagrangian_classics import CLASSICS

__all__ = ["CONSTRAINT_TOLERANCE", "EXAMPLE", "EXAMPLE_JOB", "KIND", "MAX_COORDINATES", "TITLE", "define", "outline"]

TITLE = "Lagrangian system with constraints linear in the velocities, written by the user"
#: The equations' source, for the results.
EQUATION = "Lagrange-d'Alembert"
#: An initial q̇ may violate a constraint by this much times max(1, Σⱼ |Aᵢⱼ q̇ⱼ|).
CONSTRAINT_TOLERANCE = 1e-10
#: Why no invariant measure is claimed before the search ran (the request's validation).
NO_MEASURE = "none claimed yet: the invariant-measure search runs with the job"
#: What an outline (a request's validation) says of its equations.
OUTLINE = ("the equations of motion are derived with the job: a request is checked against the plain elimination's "
           "field (the same field, not simplified)")
#: Why a definition shared by a parameter sweep claims less.
GENERIC = ("an ensemble sweeping a parameter shares one definition: only what holds for every value of the "
           "parameters is claimed (the ansatz's integrals and anything found only at the parameters' values are not)")
#: The measure search, for the catalog.
MEASURE_SEARCH = ("sought with the job on the constraint manifold, as rho(q) dq du (u the independent velocities): "
                  "found (the density, proven symbolically and checked pointwise, then claimed and checked along "
                  "the trajectory as rho |det A_D| in (q, q_dot)), none (an obstruction proven at the parameters' "
                  "values) or undecided (a deterministic limit on the search's work, named in the reason); "
                  "result.system.structure.measure says which and why")

#: Chaplygin's sleigh: a knife edge at distance a from the centre of mass, in the plane.
EXAMPLE: dict[str, Any] = {
    "kind": KIND, "coordinates": ["x", "y", "theta"],
    "L": "m/2*((x_dot - a*sin(theta)*theta_dot)**2 + (y_dot + a*cos(theta)*theta_dot)**2) + J/2*theta_dot**2",
    "constraints": ["-sin(theta)*x_dot + cos(theta)*y_dot"],
    "parameters": {"m": 1.3, "a": 0.4, "J": 0.25}}
#: A job request with it.
EXAMPLE_JOB: dict[str, Any] = {"system": EXAMPLE, "initial_state": {"q": [0.2, -0.1, 0.0], "q_dot": [0.9, 0.0, 0.7]},
                               "t_final": 20.0, "samples": 201, "checks": ["integrals", "measure"]}


def _autonomous(data: LagrangianData) -> None:
    """Refuse an explicit time (the integrators take autonomous fields)."""
    for field, expr in (("L", data.L), *((f"constraints[{i}]", f) for i, f in enumerate(data.constraints))):
        if expr.has(data.t):
            raise DataError(field, "depends on the time t explicitly: jobs integrate autonomous systems only "
                                   "(a time-dependent L or constraint is not supported yet)")


def _projections(data: LagrangianData) -> tuple[Projection, ...]:
    """Per constraint, q̇ projected orthogonally onto the i-th row of A made orthogonal to the rows before it
    (Gram–Schmidt): applied in order, the i-th leaves the first i constraints satisfied."""
    v = sp.Matrix(data.v)
    rows: list[sp.Matrix] = []
    out = []
    for i in range(data.A.shape[0]):
        e = data.A[i, :].T
        for r in rows:
            e = e - r * (e.dot(r) / r.dot(r))
        rows.append(e)
        projected = v - e * (e.dot(v) / e.dot(e))
        out.append(Projection("q_dot", tuple(projected),
                              f"q_dot - e{i + 1} (e{i + 1}, q_dot)/|e{i + 1}|^2, e{i + 1} = row {i + 1} of A made "
                              "orthogonal to the rows before it (Gram-Schmidt)"))
    return tuple(out)


def _measure(data: LagrangianData, verdict: MeasureVerdict | None = None) -> tuple[InvariantMeasure, dict[str, Any]]:
    """The invariant measure the search proves (or none claimed, with the verdict), and the verdict as JSON."""
    verdict = measure_verdict(data) if verdict is None else verdict
    summary: dict[str, Any] = {"verdict": verdict.status, "reason": verdict.reason,
                               "seconds": round(verdict.seconds, 3),
                               "independent_velocities": [str(u) for u in verdict.velocities],
                               "dependent_velocities": {str(s): sp.sstr(e) for s, e in verdict.dependent}}
    if verdict.status != "found" or verdict.density is None:
        return InvariantMeasure(None, f"verdict {verdict.status}: {verdict.reason}", EQUATION), summary
    dependent = [data.v.index(s) for s, _ in verdict.dependent]
    minor = sp.factor(sp.Matrix(data.A).extract(list(range(len(dependent))), dependent).det()) if dependent else 1
    sign = 1
    point = sample_points(data)[0]
    if dependent and (value := number(minor, point)) is not None and value < 0:
        sign = -1
    density = sp.factor(verdict.density * sign * minor)
    regular = regular_density(density, point)
    density = density if regular is None else regular
    u = ", ".join(map(str, verdict.velocities))
    formula = (f"rho dq du = {sp.sstr(verdict.density)} dq du on the constraint manifold (u = ({u})), i.e. the density "
               f"{sp.sstr(density)} in (q, q_dot) there")
    summary.update(density=sp.sstr(verdict.density), density_in_state=sp.sstr(density), residual=verdict.residual,
                   at_values="substituted exactly" in verdict.reason)
    verified = verdict.reason if "randomized identity test" in verdict.reason else None
    return InvariantMeasure(density, formula, EQUATION, on_manifold=verdict.dependent, verified=verified), summary


def _with_multiplier(data: LagrangianData, measure: InvariantMeasure, summary: dict[str, Any],
                     theorem: Hamiltonization) -> tuple[InvariantMeasure, dict[str, Any]]:
    """The measure verdict made consistent with Theorem 1's (issue 33): a reducing multiplier N implies the measure
    N det M* |det d(q_dot_shape)/du| (:func:`implied_by_multiplier`), proven like the search's. Where the search
    did not find one, the implied one is claimed once proven (the search's own verdict kept in the reason); where
    it did, the two densities are compared at the sample points (their ratio, if not constant, is an integral)."""
    if theorem.summary.get("verdict") != "found" or theorem.L_star is None or theorem.reduced_time is None:
        return measure, summary
    implied = implied_by_multiplier(data, theorem.reduced_time.density, theorem.shape, theorem.L_star)
    if summary["verdict"] == "found":
        agree = None
        if implied.status == "found" and measure.density is not None:
            other, _ = _measure(data, implied)
            assert other.density is not None
            ratios = [number(measure.density / other.density, point) for point in sample_points(data)]
            known = [r for r in ratios if r is not None]
            agree = bool(known) and max(known) - min(known) <= 1e-12 * max(abs(r) for r in known)
        summary = {**summary, "implied_by_multiplier": {
            "verdict": implied.status, "density": None if implied.density is None else sp.sstr(implied.density),
            "same_up_to_a_constant": agree, "reason": implied.reason}}
        return measure, summary
    if implied.status != "found":
        return measure, {**summary, "reason": f"{summary['reason']}; Theorem 1's reducing multiplier implies a "
                                              f"measure, not proven: {implied.reason}"}
    search = f"the search alone: {summary['verdict']} ({summary['reason']})"
    if summary["verdict"] == "none":
        search = ("the search's obstruction is contradicted by this proof, which is kept (please report the "
                  f"system); {search}")
    measure, found = _measure(data, implied)
    return measure, {**found, "derived_from": "reducing_multiplier", "reason": f"{found['reason']}; {search}"}


def _consistent(measure: dict[str, Any], theorem: dict[str, Any]) -> dict[str, Any]:
    """Theorem 1's verdict, never ``none`` beside a proven measure of a system it reduced: for a Chaplygin system
    with two shape coordinates a measure ρ(q) gives a reducing multiplier (Theorem 1), so the pair would contradict
    each other; the verdict is then ``undecided``, saying so (it does not happen in the tests: a guard)."""
    if theorem.get("verdict") != "none" or measure.get("verdict") != "found" or measure.get("at_values"):
        return theorem
    return {**theorem, "verdict": "undecided", "reason": (
        f"Theorem 1 found no multiplier ({theorem.get('reason')}), yet the measure {measure.get('density')} was "
        "proven, which implies one for a Chaplygin system (Theorem 1's proof): the two disagree, so neither "
        "'none' is said")}


def _integrals(data: LagrangianData) -> tuple[list[FirstIntegral], dict[str, Any]]:
    """The proven integrals of the ansatz besides the energy, as claims checked along the trajectory, and the
    search as JSON. An integral whose form in (q, u) has a denominator that vanishes (powers of the constraints'
    minor) is claimed and shown in the full velocities where that form is regular (:func:`regular_form`; equal on
    the constraint manifold), its form in (q, u) kept beside it."""
    search = integral_search(data)
    dependent = dependent_velocities(data) if search.integrals else ()
    claims, found = [], []
    for integral in search.integrals:
        regular = regular_form(data, integral.expression, dependent)
        expression = integral.expression if regular is None else regular
        shown: dict[str, Any] = {"name": integral.name, "degree": integral.degree, "expression": sp.sstr(expression),
                                 "proof": integral.proof}
        if regular is not None:
            shown["expression_on_manifold"] = sp.sstr(integral.expression)
        found.append(shown)
        if integral.name == "energy" or not integral.proven:
            continue
        scale = sum((sp.Abs(term) for term in sp.Add.make_args(sp.expand(expression))), sp.Integer(0))
        formula = integral.formula if regular is None else f"{integral.name} = {sp.sstr(regular)} (on the manifold)"
        claims.append(FirstIntegral(integral.name, expression, scale, formula,
                                    "ansatz linear/quadratic in the velocities"))
    summary = {"status": search.status, "ansatz": search.ansatz, "seconds": round(search.seconds, 3),
               "found": found, "omitted": search.omitted, "reason": search.reason}
    return claims, summary


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(data: LagrangianData, reduce: bool = True, generic: bool = False) -> MechanicalSystem:
    """The user's system as a :class:`MechanicalSystem` in the state (q, q̇).

    Parameters
    ----------
    data : LagrangianData
        From :func:`nonholonomic.lagrangian.lagrangian_data` (parsed and checked).
    reduce : bool
        Run the structure searches (the invariant measure on the constraint manifold, the integrals, Theorem 1;
        each bounded by deterministic limits on its work, never by a clock); without it no measure is claimed.
    generic : bool
        Claim only what holds for every value of the parameters (an ensemble sweeping one shares this
        definition): not the ansatz's integrals, which are sought at the parameters' values, nor a measure
        or Hamiltonian form found only at them.

    Returns
    -------
    MechanicalSystem
        State vectors ``q`` and ``q_dot``; integrals: the energy and each constraint; the measure the search
        proved, if any; ``structure``: the verdicts as JSON.

    Raises
    ------
    DataError
        ``L`` or ``constraints[i]`` with the time t explicitly.
    DerivationError
        Sympy failed on the derivation.
    nonholonomic.bounded.SafetyCapExceeded
        A symbolic step still running after the safety cap (a failure of the job, not a verdict).
    """
    _autonomous(data)
    return _assemble(data, derive(data).qddot, reduce, generic)


@lru_cache(maxsize=64)
@remembered("outline")  # keyed by its inputs: its field is a DAG that a key by content would print as a tree
def outline(data: LagrangianData) -> MechanicalSystem:
    """What a request for ``data`` is checked against, in milliseconds: every name, integral and constraint
    of :func:`define` (without ``reduce``), the field by :func:`~nonholonomic.lagrangian.equations.plain_field`
    (the same field, not simplified: never compiled on the request path). The derivation, the elimination
    and the structure searches run with the job.

    Raises
    ------
    DataError
        ``L`` or ``constraints[i]`` with the time t explicitly.
    """
    _autonomous(data)
    system = _assemble(data, plain_field(data), reduce=False, generic=False)
    return replace(system, structure={"equations": OUTLINE})


def _assemble(data: LagrangianData, rhs: tuple[sp.Expr, ...], reduce: bool, generic: bool) -> MechanicalSystem:
    """The :class:`MechanicalSystem` of ``data`` with the field ``rhs`` (q̈), the structure searched if ``reduce``."""
    q, v, L = data.q, data.v, data.L
    texts = dict(data.texts)
    half = sp.expand(sum((vi * sp.diff(L, vi) for vi in v), sp.Integer(0)) / 2)  # T₂ + T₁/2: the size of E's terms
    energy = energy_of(data)
    assert energy is not None  # L has no t (checked by the callers)
    integrals = [FirstIntegral("energy", energy, sp.Abs(half) + sp.Abs(L - half), "E = (q_dot, dL/dq_dot) - L",
                               EQUATION)]
    constraints = []
    for i, (f, projection) in enumerate(zip(data.constraints, _projections(data))):
        scale = sum((sp.Abs(data.A[i, j] * v[j]) for j in range(len(v)) if data.A[i, j] != 0), sp.Integer(0))
        text = texts[f"constraints[{i}]"]
        integrals.append(FirstIntegral(f"constraint {i + 1}", f, scale, f"{text} = 0 (constraint {i + 1})", EQUATION))
        constraints.append(StateConstraint("q_dot", f, 0.0, f"{text} = 0 (constraint {i + 1})", EQUATION,
                                           tolerance=CONSTRAINT_TOLERANCE, scale=scale, projection=projection))
    form, reduced_time, structure = None, None, None
    if reduce:
        measure, summary = _measure(data)
        # the ansatz is solved at the parameters' values: a generic definition does not seek it
        found, integrals_summary = ([], {"status": "not sought", "reason": GENERIC}) if generic else _integrals(data)
        theorem = hamiltonization(data)
        measure, summary = _with_multiplier(data, measure, summary, theorem)
        form, reduced_time = theorem.form, theorem.reduced_time
        if generic and measure.density is not None and summary.get("at_values"):  # found only at the values
            measure = InvariantMeasure(None, f"not claimed: {GENERIC}; {measure.formula}", EQUATION)
            summary = {**summary, "claimed": False}
        theorem_summary = _consistent(summary, theorem.summary)
        if generic and form is not None and theorem.summary.get("at_values"):  # found only at the values
            form, reduced_time = None, None
            theorem_summary = {**theorem.summary, "verdict": "not claimed", "reason": GENERIC}
        integrals += found
        structure = {"measure": summary, "integrals": integrals_summary, "hamiltonization": theorem_summary}
    else:
        measure = InvariantMeasure(None, NO_MEASURE, EQUATION)
    return MechanicalSystem(
        kind=KIND,
        potential="zero",
        title=TITLE,
        equation=EQUATION,
        parameters=tuple(Parameter(str(s), (s,), "parameter of the user's system", "as L needs")
                         for s in data.parameters),
        state=(StateVector("q", q, f"generalized coordinates ({', '.join(map(str, q))})", "as L's coordinates"),
               StateVector("q_dot", v, f"generalized velocities ({', '.join(map(str, v))})", "q's unit/s")),
        rhs=(*v, *rhs),
        integrals=tuple(integrals),
        measure=measure,
        reduced_time=reduced_time,
        potential_formula="U: part of L",
        constraints=tuple(constraints),
        notes=(f"L = {texts['L']}",
               "constraints: " + ("; ".join(f"{texts[f'constraints[{i}]']} = 0" for i in range(len(data.constraints)))
                                  or "none"),
               "Lagrange-d'Alembert equations derived symbolically, the multipliers eliminated"),
        structure=structure,
        hamiltonian_form=form,
    )


def catalog_entry() -> dict[str, Any]:
    """How to pose a Lagrangian system with constraints linear in the velocities (``GET /v1/systems/lagrangian``)."""
    return {
        "kind": KIND, "title": TITLE, "equation": EQUATION,
        "fields": {"coordinates": f"names of the generalized coordinates q (1 to {MAX_COORDINATES}); the velocity "
                                  f"of x is x{VELOCITY_SUFFIX}",
                   "L": "L(q, q_dot), a polynomial of degree 2 in the velocities with a regular mass matrix "
                        "d2L/dq_dot2 (a potential is part of it: L = T - U); no explicit time t",
                   "constraints": "each sum_j a_j(q) q_j_dot (meaning = 0): linear and homogeneous in the velocities, "
                                  "independent, fewer than the coordinates",
                   "parameters": "every constant of L and the constraints, with its value"},
        "max_coordinates": MAX_COORDINATES, "reserved_names": sorted(RESERVED),
        "state": ["q", "q_dot"],
        "integrals": ["energy: E = (q_dot, dL/dq_dot) - L",
                      "constraint i: the i-th constraint, 0 along the motion"],
        "measure": MEASURE_SEARCH,
        "initial_state": f"q and q_dot, one component per coordinate; q_dot must satisfy every constraint to "
                         f"{CONSTRAINT_TOLERANCE:g} times its terms, or project_initial_state projects it",
        "integrals_search": "integrals linear and quadratic in the velocities, sought with the job in a polynomial "
                            "ansatz at the parameters' values, each proven and then checked along the trajectory "
                            "(result.system.structure.integrals; one missing is not in the ansatz, not proven absent)",
        "hamiltonization": "when the system is a Chaplygin system with two shape coordinates (eq. 2704-7): Theorem "
                           "1's reducing multiplier N, the time d tau = N dt and the Hamiltonian form, checked by the "
                           "'bracket' check (result.system.structure.hamiltonization)",
        "checks": ["integrals", "measure", "bracket"], "example": EXAMPLE_JOB,
        "classics": {name: {key: classic[key] for key in ("title", "job", "facts", "measure", "hamiltonization",
                                                          "references")}
                     for name, classic in CLASSICS.items()}}


#: The kind's record (nonholonomic.kinds): written by the user; Theorem 1's structure when it is a Chaplygin system
#: with two shape coordinates.
SYSTEM_KIND = SystemKind(
    sys.modules[__name__], written_by_user=True, theorem_1=True, catalog_entry=catalog_entry,
    singular_field="the mass matrix d2L/dq_dot2 (or A M^-1 A^T) is singular there, or L or a constraint is")
