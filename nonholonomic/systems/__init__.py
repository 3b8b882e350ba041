"""The systems of the paper, one module each; :data:`SYSTEMS` maps a request's ``kind`` to it.

Adding a system is one new module exposing ``KIND``, ``TITLE``, ``PARAMETERS``, ``STATE``,
``POTENTIALS`` and ``define(potential) -> MechanicalSystem``, plus its entry here and its tests.
A kind whose geometry the user writes (``ball_on_surface``: the surface Φ) also takes it:
``define(potential, surface)``; :data:`SURFACE_KINDS` lists them.
"""

from __future__ import annotations

from functools import cache
from types import ModuleType

from nonholonomic.definition import MechanicalSystem
from nonholonomic.expressions import ExpressionError
from nonholonomic.potentials import Potential, expression, potential_symbols
from nonholonomic.systems import (
    ball_on_quadric,
    ball_on_surface,
    chaplygin_ball,
    chaplygin_ball_veselova,
    clebsch,
    neumann,
    rubber_ball,
    veselova,
    veselova_e3,
)

SYSTEMS: dict[str, ModuleType] = {module.KIND: module for module in (
    chaplygin_ball, veselova, chaplygin_ball_veselova, rubber_ball, ball_on_quadric, ball_on_surface, neumann, clebsch,
    veselova_e3)}
#: Kinds that take a user's surface Φ(x) = 0 besides the potential.
SURFACE_KINDS = frozenset({ball_on_surface.KIND})

#: Built-in potentials each kind accepts (besides a user's expression, :func:`user_potential`).
SUPPORTED_POTENTIALS: dict[str, tuple[str, ...]] = {kind: tuple(m.POTENTIALS) for kind, m in SYSTEMS.items()}


def get_system(kind: str, potential: str | Potential = "zero",
               surface: ball_on_surface.Surface | None = None) -> MechanicalSystem:
    """The symbolic definition of ``kind`` with ``potential``: the name of a built-in one, or one
    written by the user (:func:`user_potential`); for a kind of :data:`SURFACE_KINDS`, on ``surface``
    (:func:`nonholonomic.systems.ball_on_surface.surface`; None: the kind's example surface).

    Raises
    ------
    KeyError
        If the kind is unknown or does not support the potential.
    """
    if kind not in SYSTEMS:
        raise KeyError(f"unknown system kind {kind!r}; known: {sorted(SYSTEMS)}")
    if not isinstance(potential, Potential) and potential not in SYSTEMS[kind].POTENTIALS:
        raise KeyError(f"system {kind!r} does not support potential {potential!r}")
    if surface is not None:
        if kind not in SURFACE_KINDS:
            raise KeyError(f"system {kind!r} takes no surface")
        return SYSTEMS[kind].define(potential, surface)
    return SYSTEMS[kind].define(potential)


def user_potential(kind: str, text: str, parameters: tuple[str, ...]) -> Potential:
    """The potential ``U = text`` of ``kind``, in the components of its :data:`POTENTIAL_VARIABLES` and
    the scalar ``parameters``, whose names may not be the system's own.

    Raises
    ------
    ExpressionError
        For a text that is not such an expression, or a parameter's name the system already uses.
    """
    own = own_names(kind)
    for name in parameters:
        if name in own:
            raise ExpressionError(f"parameter name {name!r} is already a name of {kind}: choose another")
    return expression(text, tuple(parameters), SYSTEMS[kind].POTENTIAL_VARIABLES)


@cache
def own_names(kind: str) -> frozenset[str]:
    """Names a user's potential (or surface) parameter may not take: the system's parameters and their
    symbols, its state and derived vectors and their components, the times."""
    system = SYSTEMS[kind].define("zero")
    own = SYSTEMS[kind].PARAMETERS
    names = {p.name for p in own} | {str(s) for p in own for s in p.symbols}
    names |= {v.name for v in system.state} | {str(s) for v in system.state for s in v.symbols}
    names |= {d.name for d in system.derived} | {f"{d.name}{i}" for d in system.derived for i in (1, 2, 3)}
    return frozenset(names | {"t", "tau"})


#: The names a potential of each kind may use.
POTENTIAL_NAMES: dict[str, list[str]] = {kind: potential_symbols(m.POTENTIAL_VARIABLES) for kind, m in SYSTEMS.items()}
