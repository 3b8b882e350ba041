"""A swept parameter, as a request names it (``D``, ``inertia[1]``, ``potential.a[2]``): shared by an
ensemble's ``sweep`` members and a periodic orbit's continuation."""

from __future__ import annotations

import re
from typing import Any

from nonholonomic.definition import MechanicalSystem, Parameter

#: A parameter path: a group name, ``potential.`` allowed before it, a component index after a vector's.
PATH = re.compile(r"^(?:potential\.)?([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")


def sweep_target(system: MechanicalSystem, path: str) -> tuple[Parameter, int | None]:
    """The parameter group and component a sweep path names (``inertia[1]`` → inertia, 1)."""
    match = PATH.match(path.strip())
    groups = {p.name: p for p in system.parameters}
    if not match or match.group(1) not in groups:
        raise ValueError(f"{path!r} names no parameter of {system.kind}; known: "
                         + ", ".join(p.name + ("[i]" if p.is_vector else "") for p in system.parameters))
    par = groups[match.group(1)]
    index = None if match.group(2) is None else int(match.group(2))
    if par.shape == "symmetric_matrix":
        raise ValueError(f"{par.name} is a matrix; sweeps take a scalar or a vector component")
    if par.is_vector and (index is None or index >= len(par.symbols)):
        last = len(par.symbols) - 1
        raise ValueError(f"{par.name} is a vector: name a component {par.name}[0] .. {par.name}[{last}]")
    if not par.is_vector and index is not None:
        raise ValueError(f"{par.name} is a scalar: no index")
    return par, index


def swept(parameters: dict[str, Any], par: Parameter, index: int | None, value: float) -> dict[str, Any]:
    """The request's parameter groups with the swept one's component set to ``value``."""
    values = dict(parameters)
    if index is None:
        values[par.name] = value
    else:
        vector = list(values[par.name])
        vector[index] = value
        values[par.name] = vector
    return values
