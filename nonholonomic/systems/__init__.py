"""The registry of system kinds: one module per kind, each ending with its record ``SYSTEM_KIND``
(:class:`nonholonomic.kinds.SystemKind`); ``KINDS`` maps a request's ``kind`` to it.

Adding a kind is one new module plus its tests (``docs/layout.md``, "Adding a system kind"): a module of
this package named in :data:`BUILT_IN`, or a module of another distribution declared under the entry-point
group ``nonholonomic.kinds`` (:data:`nonholonomic.kinds.ENTRY_POINT_GROUP`), loaded with the built-in ones.
A catalog kind's module declares ``KIND``, ``TITLE``, ``PARAMETERS``, ``STATE``, ``POTENTIALS``,
``POTENTIAL_VARIABLES``, ``EXAMPLE`` and ``define(potential) -> MechanicalSystem`` (``define(potential,
surface)`` for a kind with ``surface=True``); ``SYSTEMS`` maps those kinds to their modules,
``SUPPORTED_POTENTIALS`` to their built-in potentials' names, ``POTENTIAL_NAMES`` to the names a user's
potential may use.

The registry is collected on first use (``KINDS`` and the others are read lazily), not when this package
is imported: a system module, or a module it imports, may import a sibling module without waiting for
every kind to load. A module may not ask for the registry while it is being collected.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from functools import cache
from importlib.metadata import entry_points
from types import ModuleType
from typing import TYPE_CHECKING, Any

from nonholonomic.definition import MechanicalSystem
from nonholonomic.expressions import ExpressionError
from nonholonomic.kinds import ENTRY_POINT_GROUP, SystemKind, unknown_kind
from nonholonomic.potentials import Potential, expression, potential_symbols

if TYPE_CHECKING:
    from nonholonomic.systems.ball_on_surface import Surface

#: The built-in kinds' modules, in the catalog's order.
BUILT_IN = ("chaplygin_ball", "veselova", "chaplygin_ball_veselova", "rubber_ball", "ball_on_quadric",
            "ball_on_surface", "neumann", "clebsch", "veselova_e3", "generalized_chaplygin", "lagrangian")


def kind_of(kind: str) -> SystemKind:
    """The record of ``kind``.

    Raises
    ------
    KeyError
        If no module registers the kind.
    """
    kinds = _registry().kinds
    if kind not in kinds:
        raise unknown_kind(kind, list(kinds))
    return kinds[kind]


def registered(kind: str) -> SystemKind | None:
    """The record of ``kind``, or None for a kind no module registers (a definition built by hand)."""
    return _registry().kinds.get(kind)


def get_system(kind: str, potential: str | Potential = "zero", surface: Surface | None = None) -> MechanicalSystem:
    """The symbolic definition of the catalog kind ``kind`` with ``potential``: the name of a built-in one,
    or one written by the user (:func:`user_potential`); for a kind that takes a surface, on ``surface``
    (:func:`nonholonomic.systems.ball_on_surface.surface`; None: the kind's example surface).

    Raises
    ------
    KeyError
        If the kind is unknown (or written by the user: its definition is built from its request) or does
        not support the potential.
    """
    registry = _registry()
    if kind not in registry.systems:
        raise unknown_kind(kind, list(registry.systems))
    module = registry.systems[kind]
    if not isinstance(potential, Potential) and potential not in module.POTENTIALS:
        raise KeyError(f"system {kind!r} does not support potential {potential!r}")
    if surface is not None:
        if not registry.kinds[kind].surface:
            raise KeyError(f"system {kind!r} takes no surface")
        return module.define(potential, surface)
    return module.define(potential)


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
    return expression(text, tuple(parameters), _registry().systems[kind].POTENTIAL_VARIABLES)


@cache
def own_names(kind: str) -> frozenset[str]:
    """Names a user's potential (or surface) parameter may not take: the system's parameters and their
    symbols, its state and derived vectors and their components, the times."""
    system = get_system(kind, "zero")
    own = _registry().systems[kind].PARAMETERS
    names = {p.name for p in own} | {str(s) for p in own for s in p.symbols}
    names |= {v.name for v in system.state} | {str(s) for v in system.state for s in v.symbols}
    names |= {d.name for d in system.derived} | {f"{d.name}{i}" for d in system.derived for i in (1, 2, 3)}
    return frozenset(names | {"t", "tau"})


@dataclass(frozen=True)
class _Registry:
    kinds: dict[str, SystemKind]
    systems: dict[str, ModuleType]
    supported_potentials: dict[str, tuple[str, ...]]
    potential_names: dict[str, list[str]]


_collecting = False


@cache
def _registry() -> _Registry:
    """The records of the built-in modules, then of the modules declared under the entry-point group."""
    global _collecting
    if _collecting:
        raise ImportError("a system module asked for the registry of kinds while it is being collected: read it "
                          "when called, not when imported")
    _collecting = True
    try:
        modules = [importlib.import_module(f"{__name__}.{name}") for name in BUILT_IN]
        modules += [entry.load() for entry in entry_points(group=ENTRY_POINT_GROUP)]
    finally:
        _collecting = False
    kinds: dict[str, SystemKind] = {}
    for module in modules:
        record = getattr(module, "SYSTEM_KIND", None)
        if not isinstance(record, SystemKind):
            raise TypeError(f"{module.__name__} registers no kind: it needs SYSTEM_KIND = SystemKind(...)")
        if record.name in kinds:
            raise ValueError(f"two modules register the kind {record.name!r}: {kinds[record.name].module.__name__} "
                             f"and {module.__name__}")
        kinds[record.name] = record
    systems = {name: k.module for name, k in kinds.items() if not k.written_by_user}
    return _Registry(kinds, systems, {kind: tuple(m.POTENTIALS) for kind, m in systems.items()},
                     {kind: potential_symbols(m.POTENTIAL_VARIABLES) for kind, m in systems.items()})


if TYPE_CHECKING:
    #: Every kind by its request name: the built-in ones, then those of other distributions.
    KINDS: dict[str, SystemKind]
    #: The catalog kinds (parameters and a potential, not written by the user) by name, to their modules.
    SYSTEMS: dict[str, ModuleType]
    #: Built-in potentials each catalog kind accepts (besides a user's expression, :func:`user_potential`).
    SUPPORTED_POTENTIALS: dict[str, tuple[str, ...]]
    #: The names a potential of each catalog kind may use.
    POTENTIAL_NAMES: dict[str, list[str]]

_LAZY = {"KINDS": "kinds", "SYSTEMS": "systems", "SUPPORTED_POTENTIALS": "supported_potentials",
         "POTENTIAL_NAMES": "potential_names"}


def __getattr__(name: str) -> Any:
    """``KINDS``, ``SYSTEMS``, ``SUPPORTED_POTENTIALS``, ``POTENTIAL_NAMES``: read off the registry (collected
    on first use)."""
    if name in _LAZY:
        return getattr(_registry(), _LAZY[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
