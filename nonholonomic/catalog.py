"""The catalog of systems (``GET /v1/systems``), read off the symbolic definitions."""

from __future__ import annotations

from typing import Any

from nonholonomic.analysis.sampling import describe_sampling, fixable
from nonholonomic.definition import Parameter
from nonholonomic.isomorphisms import maps_for
from nonholonomic.potentials import EXPRESSION, MAX_EXPRESSION_LENGTH, MAX_EXPRESSION_PARAMETERS, potential_symbols
from nonholonomic.simulation import available_checks
from nonholonomic.systems import KINDS, SUPPORTED_POTENTIALS, SYSTEMS, get_system, own_names, user_potential


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
        "surface_expression": None if not KINDS[kind].surface else {
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
    """The whole catalog: one entry per catalog kind under ``systems``, and under its own name, how to pose a
    system of each kind written by the user (its record's ``catalog_entry``)."""
    written = {name: record.catalog_entry() for name, record in KINDS.items()
               if record.written_by_user and record.catalog_entry is not None}
    return {"systems": [describe(kind) for kind in SYSTEMS], **written}
