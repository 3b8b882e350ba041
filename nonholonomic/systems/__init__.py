"""The systems of the paper, one module each; :data:`SYSTEMS` maps a request's ``kind`` to it.

Adding a system is one new module exposing ``KIND``, ``TITLE``, ``PARAMETERS``, ``STATE``,
``POTENTIALS`` and ``define(potential) -> MechanicalSystem``, plus its entry here and its tests.
"""

from __future__ import annotations

from types import ModuleType

from nonholonomic.definition import MechanicalSystem
from nonholonomic.systems import (
    ball_on_quadric,
    chaplygin_ball,
    chaplygin_ball_veselova,
    clebsch,
    neumann,
    rubber_ball,
    veselova,
    veselova_e3,
)

SYSTEMS: dict[str, ModuleType] = {module.KIND: module for module in (
    chaplygin_ball, veselova, chaplygin_ball_veselova, rubber_ball, ball_on_quadric, neumann, clebsch, veselova_e3)}

#: Potentials each kind accepts.
SUPPORTED_POTENTIALS: dict[str, tuple[str, ...]] = {kind: tuple(m.POTENTIALS) for kind, m in SYSTEMS.items()}


def get_system(kind: str, potential: str = "zero") -> MechanicalSystem:
    """The symbolic definition of ``kind`` with ``potential``.

    Raises
    ------
    KeyError
        If the kind is unknown or does not support the potential.
    """
    if kind not in SYSTEMS:
        raise KeyError(f"unknown system kind {kind!r}; known: {sorted(SYSTEMS)}")
    if potential not in SYSTEMS[kind].POTENTIALS:
        raise KeyError(f"system {kind!r} does not support potential {potential!r}")
    return SYSTEMS[kind].define(potential)
