"""The catalog of systems (``GET /v1/systems``), read off the symbolic definitions."""

from __future__ import annotations

from typing import Any

from nonholonomic.analysis.sampling import describe_sampling, fixable
from nonholonomic.definition import Parameter
from nonholonomic.isomorphisms import maps_for
from nonholonomic.potentials import EXPRESSION, MAX_EXPRESSION_LENGTH, MAX_EXPRESSION_PARAMETERS, potential_symbols
from nonholonomic.simulation import available_checks
from nonholonomic.systems import SUPPORTED_POTENTIALS, SURFACE_KINDS, SYSTEMS, get_system, own_names, user_potential


def _parameter(par: Parameter) -> dict[str, Any]:
    entry = {"name": par.name, "shape": par.shape, "components": [str(s) for s in par.symbols],
             "meaning": par.meaning, "unit": par.unit, "admissible": par.admissible}
    if par.transform_formula:
        entry["components_are"] = f"entries 11, 12, 13, 22, 23, 33 of {par.transform_formula}, computed from {par.name}"
    return entry


def describe(kind: str) -> dict[str, Any]:
    """Everything a client needs to pose a job for ``kind``.

    Raises
    ------
    KeyError
        If the kind is unknown.
    """
    module = SYSTEMS[kind]
    potentials = SUPPORTED_POTENTIALS[kind]
    definitions = {p: get_system(kind, p) for p in potentials}
    base = definitions[potentials[0]]
    variables = potential_symbols(module.POTENTIAL_VARIABLES)
    sample = user_potential(kind, f"q*{variables[-1]}", ("q",))  # what any U written by the user keeps
    integrals: dict[str, dict[str, Any]] = {}
    for potential, system in [*definitions.items(), (EXPRESSION, get_system(kind, sample))]:
        for claim in system.integrals:
            entry = integrals.setdefault(claim.name, {"name": claim.name, "formula": claim.formula,
                                                      "equation": claim.equation, "claimed_for_potentials": []})
            entry["claimed_for_potentials"].append(potential)
    return {
        "kind": kind,
        "title": module.TITLE,
        "equation": base.equation,
        "parameters": [_parameter(p) for p in module.PARAMETERS],
        "potentials": [{"kind": p, "formula": module.POTENTIALS[p].formula,
                        "parameters": [_parameter(q) for q in module.POTENTIALS[p].parameters],
                        # what an ensemble's {"sample": {"level": {...}}} may fix, and how states are drawn
                        "levels": list(fixable(definitions[p])), "sampling": describe_sampling(definitions[p])}
                       for p in potentials],
        "potential_expression": {
            "kind": EXPRESSION, "variables": variables, "formula": "U = <expression>",
            "max_length": MAX_EXPRESSION_LENGTH, "max_parameters": MAX_EXPRESSION_PARAMETERS,
            "reserved_names": sorted(own_names(kind)),
            "example": {"kind": EXPRESSION, "U": f"q*{variables[-1]}**2", "parameters": {"q": 0.5}}},
        "surface_expression": None if kind not in SURFACE_KINDS else {
            "variables": list(module.SURFACE_VARIABLES), "formula": "Phi(x) = <expression> = 0",
            "max_length": MAX_EXPRESSION_LENGTH, "max_parameters": MAX_EXPRESSION_PARAMETERS,
            "reserved_names": sorted(own_names(kind)), "example": module.EXAMPLE["system"]["surface"]},
        "state": [{"name": v.name, "components": [str(s) for s in v.symbols], "meaning": v.meaning, "unit": v.unit}
                  for v in base.state],
        "alternative_inputs": [{"name": a.name, "replaces": a.replaces, "formula": a.formula}
                               for a in base.alternative_inputs],
        "derived": [{"name": d.name, "formula": d.formula, "meaning": d.meaning, "unit": d.unit} for d in base.derived],
        "constraints": [{"field": c.field, "formula": c.formula, "equation": c.equation, "tolerance": c.tolerance,
                         "projection": c.projection.formula if c.projection else None}
                        for c in base.constraints],
        "integrals": list(integrals.values()),
        "measure": {"formula": base.measure.formula, "equation": base.measure.equation},
        "reduced_time": None if base.reduced_time is None else {
            "formula": base.reduced_time.formula, "equation": base.reduced_time.equation,
            "unit": base.reduced_time.unit},
        "notes": list(base.notes),
        "checks": list(available_checks(base)),
        "maps": {p: maps_for(kind, p) for p in potentials if maps_for(kind, p)},
        "example": getattr(module, "EXAMPLE", None),
        "time_unit": "s",
    }


def catalog() -> dict[str, Any]:
    """The whole catalog: one entry per system kind, and how to pose a generalized Chaplygin system."""
    from nonholonomic.systems import generalized_chaplygin as gc

    return {"systems": [describe(kind) for kind in SYSTEMS], "generalized_chaplygin": {
        "kind": gc.KIND, "title": gc.TITLE, "equation": "2704-7, 2704-8, 2704-9 (Theorem 1)",
        "fields": {"coordinates": "names of q1, q2", "velocities": "names of q1_dot, q2_dot",
                   "parameters": "every constant of the expressions, with its value",
                   "L": "L(q, q_dot), quadratic in the velocities",
                   "a1": "S = a1(q) q1_dot + a2(q) q2_dot + b(q)", "a2": "see a1", "b": "see a1",
                   "potential": "U(q) subtracted from L (optional)"},
        "state": ["q", "q_dot"], "checks": ["integrals", "measure", "bracket"], "example": gc.EXAMPLE_JOB},
        "lagrangian": lagrangian_entry()}


def lagrangian_entry() -> dict[str, Any]:
    """How to pose a Lagrangian system with constraints linear in the velocities (``GET /v1/systems/lagrangian``)."""
    from nonholonomic.lagrangian.parse import RESERVED, VELOCITY_SUFFIX
    from nonholonomic.systems import lagrangian as lag
    from nonholonomic.systems.lagrangian_classics import CLASSICS

    return {
        "kind": lag.KIND, "title": lag.TITLE, "equation": lag.EQUATION,
        "fields": {"coordinates": f"names of the generalized coordinates q (1 to {lag.MAX_COORDINATES}); the velocity "
                                  f"of x is x{VELOCITY_SUFFIX}",
                   "L": "L(q, q_dot), a polynomial of degree 2 in the velocities with a regular mass matrix "
                        "d2L/dq_dot2 (a potential is part of it: L = T - U); no explicit time t",
                   "constraints": "each sum_j a_j(q) q_j_dot (meaning = 0): linear and homogeneous in the velocities, "
                                  "independent, fewer than the coordinates",
                   "parameters": "every constant of L and the constraints, with its value"},
        "max_coordinates": lag.MAX_COORDINATES, "reserved_names": sorted(RESERVED),
        "state": ["q", "q_dot"],
        "integrals": ["energy: E = (q_dot, dL/dq_dot) - L",
                      "constraint i: the i-th constraint, 0 along the motion"],
        "measure": lag.MEASURE_SEARCH,
        "initial_state": f"q and q_dot, one component per coordinate; q_dot must satisfy every constraint to "
                         f"{lag.CONSTRAINT_TOLERANCE:g} times its terms, or project_initial_state projects it",
        "integrals_search": "integrals linear and quadratic in the velocities, sought with the job in a polynomial "
                            "ansatz at the parameters' values, each proven and then checked along the trajectory "
                            "(result.system.structure.integrals; one missing is not in the ansatz, not proven absent)",
        "hamiltonization": "when the system is a Chaplygin system with two shape coordinates (eq. 2704-7): Theorem "
                           "1's reducing multiplier N, the time d tau = N dt and the Hamiltonian form, checked by the "
                           "'bracket' check (result.system.structure.hamiltonization)",
        "checks": ["integrals", "measure", "bracket"], "example": lag.EXAMPLE_JOB,
        "classics": {name: {key: classic[key] for key in ("title", "job", "facts", "measure", "hamiltonization",
                                                          "references")}
                     for name, classic in CLASSICS.items()}}
