"""A generalized Chaplygin system with two degrees of freedom written by the user, integrated in t and,
when Theorem 1 gives a reducing multiplier, in τ with its Hamiltonian form.

Paper, section "Generalized Chaplygin systems", eq. (2704-7)::

    d/dt ∂L/∂q̇₁ − ∂L/∂q₁ = q̇₂ S,   d/dt ∂L/∂q̇₂ − ∂L/∂q₂ = −q̇₁ S,   S = a₁(q) q̇₁ + a₂(q) q̇₂ + b(q),

with L(q, q̇) quadratic in the velocities (Theorem 1), here L − U for a potential U(q). Solved for q̈::

    G q̈ = (q̇₂ S, −q̇₁ S) + ∂L/∂q − (∂²L/∂q̇∂q) q̇,   G = ∂²L/∂q̇∂q̇,

the state being (q, q̇). The energy E = (q̇, ∂L/∂q̇) − L is an integral (S does no work:
q̇₁ q̇₂ S − q̇₂ q̇₁ S = 0). Theorem 1 (:func:`nonholonomic.hamiltonization.reducing_multiplier.hamiltonize`) decides
whether an invariant measure ρ(q) dP₁dP₂dq₁dq₂ exists (P = ∂L/∂q̇) and finds ρ; then

* the measure in the state (q, q̇) is ρ(q) det G(q) dq dq̇ (dP = det G dq̇ at fixed q), checked like
  every kind's: div(ρ det G f) = 0 symbolically and pointwise — an independent check of ρ;
* N = ρ is the reducing multiplier, dτ = N dt (eq. 2704-8), integrated beside t;
* in p = N ∂L/∂q̇ the τ-flow is Hamiltonian with H̄(q, p) = E and the bracket (2704-9)
  {q_i, p_j} = δ_ij, {p₁, p₂} = S̄ = N B (ERRATA 6, 14) in Theorem 1's convention dx/dτ = {x, H̄};
  :mod:`nonholonomic.hamiltonization.poisson` uses dx/dτ = {H, x}, so the form here carries the same matrix with
  the opposite sign. The flow = Hamiltonian field, the Jacobi identity and H̄ = E are checked along
  the trajectory (the ``bracket`` check).

Every text is parsed by the safe parser (:mod:`nonholonomic.expressions`, never eval), in the user's
coordinate, velocity and parameter names.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import sympy as sp

from nonholonomic.definition import (
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Parameter,
    ReducedTime,
    StateVector,
)
from nonholonomic.expressions import ExpressionError, declare_symbols, parse_expression
from nonholonomic.expressions.smoothness import analytic_and_positive
from nonholonomic.kinds import SystemKind
from nonholonomic.memo import remembered
from nonholonomic.potentials import MAX_EXPRESSION_LENGTH, MAX_EXPRESSION_PARAMETERS, smooth_potential
from nonholonomic.refusals import RefusedField

KIND = "generalized_chaplygin"
TITLE = "Generalized Chaplygin system with two degrees of freedom, written by the user"
#: Names a coordinate, velocity or parameter may not take.
RESERVED = frozenset({"t", "tau", "N", "q", "q_dot", "qdot"})
#: The expression fields, in the order they are parsed.
EXPRESSION_FIELDS = ("L", "a1", "a2", "b", "potential")


def _example() -> dict[str, Any]:
    from nonholonomic.hamiltonization.local_forms import veselova_generalized_chaplygin

    veselova = veselova_generalized_chaplygin()
    return {"kind": KIND, "coordinates": veselova["coordinates"].split(","),
            "velocities": veselova["velocities"].split(","), "parameters": {"I1": 1.0, "I2": 2.0, "I3": 3.5},
            **{k: veselova[k] for k in ("L", "a1", "a2", "b")}}


#: The Veselova system in Euler angles (eq. 2504-8, ERRATA 2; the worked example of Theorem 1) as a system.
EXAMPLE: dict[str, Any] = _example()
#: A job request with it.
EXAMPLE_JOB: dict[str, Any] = {"system": EXAMPLE, "initial_state": {"q": [0.7, 0.4], "q_dot": [0.3, -0.5]},
                               "t_final": 50.0, "samples": 101, "checks": ["integrals", "measure", "bracket"]}


class DataError(RefusedField):
    """A field of the user's system that cannot be used, with the field's name."""


@dataclass(frozen=True)
class ChaplyginData:
    """The user's system, parsed: L (without U), U, a₁, a₂, b in q = ``coordinates``, q̇ = ``velocities``
    and the scalar ``parameters``; ``texts`` keeps what the user wrote, by field."""

    q: tuple[sp.Symbol, sp.Symbol]
    v: tuple[sp.Symbol, sp.Symbol]
    L: sp.Expr
    U: sp.Expr
    a1: sp.Expr
    a2: sp.Expr
    b: sp.Expr
    parameters: tuple[sp.Symbol, ...]
    texts: tuple[tuple[str, str], ...]

    def text(self, field: str) -> str:
        return dict(self.texts)[field]


def declared(coordinates: tuple[str, ...], velocities: tuple[str, ...],
             parameters: tuple[str, ...]) -> dict[str, sp.Symbol]:
    """The symbols of the names; raises :class:`DataError` naming the field of a bad name."""
    seen: set[str] = set()
    for field, names in (("coordinates", coordinates), ("velocities", velocities), ("parameters", parameters)):
        for name in names:
            if name in RESERVED:
                raise DataError(field, f"{name!r} is reserved here ({', '.join(sorted(RESERVED))}); choose another")
            if name in seen:
                raise DataError(field, f"{name!r} is used twice among the coordinates, velocities and parameters")
            seen.add(name)
        try:
            declare_symbols(list(names))
        except ExpressionError as exc:
            raise DataError(field, str(exc)) from None
    if len(parameters) > MAX_EXPRESSION_PARAMETERS:
        raise DataError("parameters", f"at most {MAX_EXPRESSION_PARAMETERS}")
    return declare_symbols([*coordinates, *velocities, *parameters])


def parse_field(field: str, text: str, symbols: dict[str, sp.Symbol], velocities: tuple[str, ...]) -> sp.Expr:
    """``text`` of ``field`` parsed (never eval) and made smooth; a₁, a₂, b and U may not use the
    velocities, L must be a polynomial of degree ≤ 2 in them (Theorem 1)."""
    try:
        expr = smooth_potential(parse_expression(text, symbols, max_length=MAX_EXPRESSION_LENGTH))
    except ExpressionError as exc:
        raise DataError(field, str(exc)) from None
    v = [symbols[name] for name in velocities]
    if field != "L":
        used = sorted(str(s) for s in expr.free_symbols & set(v))
        if used:
            raise DataError(field, f"may not depend on the velocities ({', '.join(used)}): eq. 2704-7 has "
                                   f"{field}(q)")
        return expr
    degree = velocity_degree(expr, frozenset(v))
    if degree is None:
        raise DataError(field, f"must be a polynomial of degree <= 2 in the velocities {', '.join(velocities)} "
                               "(Theorem 1: L quadratic in the velocities)")
    if degree > 2:
        raise DataError(field, f"has degree {degree} in the velocities; Theorem 1 needs degree <= 2")
    if degree < 2 or all(sp.diff(expr, a, b) == 0 for a in v for b in v):
        raise DataError(field, "has no kinetic term: d2L/dq_dot2 is zero")
    return expr


def velocity_degree(expr: sp.Expr, v: frozenset[sp.Symbol]) -> int | None:
    """The degree of ``expr`` as a polynomial in the symbols ``v``, read off the tree without expanding
    (a bound: sums take the max, products add, integer powers multiply); None if ``v`` appears in a
    denominator, a root or a function."""
    if not expr.free_symbols & v:
        return 0
    if expr in v:
        return 1
    if isinstance(expr, sp.Add):
        parts = [velocity_degree(a, v) for a in expr.args]
        known = [d for d in parts if d is not None]
        return max(known) if len(known) == len(parts) else None
    if isinstance(expr, sp.Mul):
        parts = [velocity_degree(a, v) for a in expr.args]
        known = [d for d in parts if d is not None]
        return sum(known) if len(known) == len(parts) else None
    if isinstance(expr, sp.Pow) and expr.exp.is_Integer and expr.exp > 0:
        base = velocity_degree(expr.base, v)
        return None if base is None else base * int(expr.exp)
    return None


@lru_cache(maxsize=128)
def chaplygin_data(lagrangian: str, coordinates: tuple[str, ...], velocities: tuple[str, ...], a1: str, a2: str,
                   b: str, potential: str | None = None, parameters: tuple[str, ...] = ()) -> ChaplyginData:
    """The user's system parsed and checked (cached by its texts and names).

    Raises
    ------
    DataError
        Naming the field: a bad name, a text that is not an expression of the declared names, L not
        quadratic in the velocities, a₁, a₂, b or U depending on them, a parameter none of them uses
        (``parameters.<name>``).
    """
    if len(coordinates) != 2 or len(velocities) != 2:
        raise DataError("coordinates" if len(coordinates) != 2 else "velocities", "give exactly two names")
    symbols = declared(coordinates, velocities, parameters)
    texts = {"L": lagrangian, "a1": a1, "a2": a2, "b": b, "potential": potential or "0"}
    parsed = {field: parse_field(field, texts[field], symbols, velocities) for field in EXPRESSION_FIELDS}
    used = set().union(*(expr.free_symbols for expr in parsed.values()))
    for name in parameters:
        if symbols[name] not in used:  # heyoka refuses a parameter value its system has no slot for
            raise DataError(f"parameters.{name}", f"not used by any expression ({', '.join(EXPRESSION_FIELDS)}): "
                                                  "remove it, or use it")
    return ChaplyginData(
        q=(symbols[coordinates[0]], symbols[coordinates[1]]), v=(symbols[velocities[0]], symbols[velocities[1]]),
        L=parsed["L"], U=parsed["potential"], a1=parsed["a1"], a2=parsed["a2"], b=parsed["b"],
        parameters=tuple(symbols[name] for name in parameters), texts=tuple(texts.items()))


def kinetic_matrix(L: sp.Expr, v: tuple[sp.Symbol, sp.Symbol]) -> sp.Matrix:
    """``G = ∂²L/∂q̇∂q̇``."""
    return sp.Matrix(2, 2, lambda i, j: sp.diff(L, v[i], v[j]))


def accelerations(data: ChaplyginData) -> tuple[sp.Expr, sp.Expr]:
    """``q̈ = G⁻¹ ((q̇₂ S, −q̇₁ S) + ∂L/∂q − (∂²L/∂q̇∂q) q̇)``: eq. (2704-7) solved, L − U as the Lagrangian."""
    L, q, v = data.L - data.U, data.q, data.v
    S = data.a1 * v[0] + data.a2 * v[1] + data.b
    G = kinetic_matrix(L, v)
    rhs = (sp.Matrix([v[1] * S, -v[0] * S]) + sp.Matrix([sp.diff(L, qi) for qi in q])
           - sp.Matrix(2, 2, lambda i, j: sp.diff(L, v[i], q[j])) * sp.Matrix(v))
    det = G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]
    return ((G[1, 1] * rhs[0] - G[0, 1] * rhs[1]) / det, (G[0, 0] * rhs[1] - G[1, 0] * rhs[0]) / det)


def energy(data: ChaplyginData) -> sp.Expr:
    """``E = (q̇, ∂L/∂q̇) − L + U``: the energy integral of eq. (2704-7)."""
    return sum(vi * sp.diff(data.L, vi) for vi in data.v) - data.L + data.U


def theorem_1(data: ChaplyginData) -> tuple[Any, str]:
    """Theorem 1 for the data: (the Hamiltonian form or None, why not)."""
    from nonholonomic.hamiltonization.forms import HamiltonianForm
    from nonholonomic.hamiltonization.poisson import PoissonStructure
    from nonholonomic.hamiltonization.reducing_multiplier import hamiltonize

    result = hamiltonize(data.L, data.q, data.v, data.a1, data.a2, data.b, potential=data.U)
    N = result.reducing_multiplier
    if N is None:
        return None, result.reason or "Theorem 1 gives no reducing multiplier"
    if N.has(sp.Integral):
        return None, "the density was found only as an unevaluated line integral: it cannot be integrated in tau"
    L = data.L - data.U
    v = data.v
    G = kinetic_matrix(L, v)
    w = sp.Matrix([sp.diff(L, vi).xreplace({v[0]: 0, v[1]: 0}) for vi in v])
    p = result.momenta
    det = G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]
    velocity = sp.Matrix([[G[1, 1], -G[0, 1]], [-G[1, 0], G[0, 0]]]) * (sp.Matrix(p) / N - w) / det  # G⁻¹(p/N − w)
    theorem = result.bracket
    assert theorem is not None  # set with the reducing multiplier
    bracket = PoissonStructure(
        KIND, "2704-9", theorem.variables, -theorem.matrix, parameters=theorem.parameters,
        formula="{q_i, p_j} = delta_ij, {p1, p2} = S_bar(q) with dx/dtau = {x, H_bar} (Theorem 1); stored with the "
                "opposite sign for the convention dx/dtau = {H, x}")
    symbolic = result.verification.get("symbolic")
    form = HamiltonianForm(
        system_kind=KIND, bracket=bracket,
        to_bracket_variables=(*data.q, *(N * sp.diff(L, vi) for vi in v)),
        from_bracket_variables=(*data.q, *velocity),
        hamiltonian=result.hamiltonian, time_density=N,
        formula=f"p = N dL/dq_dot, N = {sp.sstr(N)}; d tau = N dt; H_bar(q, p) = E(q, p/N); S_bar = N B = "
                f"{sp.sstr(result.S_bar)}",
        equation="2704-8, 2704-9",
        proof=(True if symbolic else None,
               "Theorem 1 proved for arbitrary L, a1, a2, b and every N with dN/dq1 = N A2, dN/dq2 = -N A1, and this "
               "N satisfies them exactly" if symbolic else
               "not proved symbolically for this N: " + str(result.verification.get("detail", ""))[:300]),
    )
    return form, ""


@lru_cache(maxsize=64)  # as the kernels and integrators compiled from it
@remembered("definition")  # derived once per machine and version (nonholonomic.memo)
def define(data: ChaplyginData, reduce: bool = True) -> MechanicalSystem:
    """The user's system as a :class:`MechanicalSystem` in the state (q, q̇).

    ``reduce`` runs Theorem 1 (every step to its end, within the deterministic limits of
    :mod:`nonholonomic.work_limits`, so the same data give the same definition everywhere): the
    measure, the time τ and the Hamiltonian form; without it (the API's validation) they are left to
    the job.
    """
    L = data.L - data.U
    q, v = data.q, data.v
    G = kinetic_matrix(L, v)
    T = sum(vi * sp.diff(L, vi) for vi in v) / 2  # the size of E's terms
    parameters = tuple(Parameter(str(s), (s,), "parameter of the user's system", "as L needs")
                       for s in data.parameters)
    form, why = theorem_1(data) if reduce else (None, "Theorem 1 runs with the job")
    if form is not None:
        N = form.time_density
        measure = InvariantMeasure(N * (G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]),
                                   f"rho(q) det G(q), rho = N = {sp.sstr(N)}, G = d2L/dq_dot2 (density for dq dq_dot; "
                                   "rho dP dq of Theorem 1 with dP = det G dq_dot)", "2704-8")
        reduced = ReducedTime(N, f"d tau = N dt, N = {sp.sstr(N)} (Theorem 1)", "2704-8", "s (times N's unit)",
                              regular=analytic_and_positive(N))
    else:
        measure = InvariantMeasure(None, f"none claimed: {why}", "2704-7")
        reduced = None
    texts = dict(data.texts)
    return MechanicalSystem(
        kind=KIND,
        potential="zero" if data.U == 0 else "expression",
        title=TITLE,
        equation="2704-7",
        parameters=parameters,
        state=(StateVector("q", q, f"generalized coordinates ({q[0]}, {q[1]})", "as L's coordinates"),
               StateVector("q_dot", v, f"generalized velocities ({v[0]}, {v[1]})", "q's unit/s")),
        rhs=(v[0], v[1], *accelerations(data)),
        integrals=(FirstIntegral("energy", energy(data), sp.Abs(T) + sp.Abs(L - T) + sp.Abs(data.U),
                                 "E = (q_dot, dL/dq_dot) - L + U", "2704-7"),),
        measure=measure,
        reduced_time=reduced,
        potential_formula=f"U = {texts['potential']}",
        notes=(f"L = {texts['L']}", f"S = ({texts['a1']}) {v[0]} + ({texts['a2']}) {v[1]} + ({texts['b']})",
               *([] if form is not None else [f"no Hamiltonian form: {why}"])),
        hamiltonian_form=form,
    )


def catalog_entry() -> dict[str, Any]:
    """How to pose a generalized Chaplygin system (its entry of ``GET /v1/systems``)."""
    return {
        "kind": KIND, "title": TITLE, "equation": "2704-7, 2704-8, 2704-9 (Theorem 1)",
        "fields": {"coordinates": "names of q1, q2", "velocities": "names of q1_dot, q2_dot",
                   "parameters": "every constant of the expressions, with its value",
                   "L": "L(q, q_dot), quadratic in the velocities",
                   "a1": "S = a1(q) q1_dot + a2(q) q2_dot + b(q)", "a2": "see a1", "b": "see a1",
                   "potential": "U(q) subtracted from L (optional)"},
        "state": ["q", "q_dot"], "checks": ["integrals", "measure", "bracket"], "example": EXAMPLE_JOB}


#: The kind's record (nonholonomic.kinds): written by the user, its structure from Theorem 1.
SYSTEM_KIND = SystemKind(
    sys.modules[__name__], written_by_user=True, theorem_1=True, catalog_entry=catalog_entry,
    singular_field="the kinetic matrix d2L/dq_dot2 is singular there, or L, S or U is")
