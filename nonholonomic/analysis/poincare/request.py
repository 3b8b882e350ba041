"""Poincaré sections, the request: the checks of every field of a section request, scalar or batch.

Part of :mod:`.poincare` (the front door), where every name is importable.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import sympy as sp

from nonholonomic.analysis.poincare.surface import SurfaceError, _prepare, _Prepared
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import MACHINE_EPSILON

#: ``increasing``: S − value goes from negative to positive; ``decreasing``: the reverse; ``both``.
DIRECTIONS = ("increasing", "decreasing", "both")
#: Largest ``max_points`` accepted (the service may configure a lower one).
MAX_POINTS_LIMIT = 1_000_000


@dataclass(frozen=True)
class _Request:
    prep: _Prepared
    value: float
    direction: str
    coordinates: tuple[str, str]
    max_points: int
    t_final: float
    tolerance: float

    @property
    def system(self) -> MechanicalSystem:
        return self.prep.system

    @property
    def text(self) -> str:
        return self.prep.text

    @property
    def expr(self) -> sp.Expr:
        return self.prep.expr


#: What :func:`_prepare` made of (system, surface text) lately, by the system's identity.
_prepared_by_id: dict[tuple[int, str], tuple[MechanicalSystem, _Prepared]] = {}


def _prepared(system: MechanicalSystem, text: str) -> _Prepared:
    """:func:`_prepare`, looked up by the system's identity: its cache hashes the whole symbolic
    definition, which costs more than the rest of a short section's checks."""
    hit = _prepared_by_id.get((id(system), text))
    if hit is None or hit[0] is not system:
        if len(_prepared_by_id) >= 256:
            _prepared_by_id.clear()
        hit = _prepared_by_id[(id(system), text)] = (system, _prepare(system, text))
    return hit[1]


#: Requests validated lately, by their arguments (the system by identity): a section asked again with the
#: same fields (a service's sections of one system, an ensemble's members) skips the checks.
_validated: dict[tuple[object, ...], tuple[MechanicalSystem, _Request]] = {}


def _validate(system: MechanicalSystem, surface: str, value: float, direction: str,
              coordinates: Sequence[str] | None, max_points: int, t_final: float,
              tolerance: float | None) -> _Request:
    """The checked request (see :func:`_check`), remembered for the arguments used lately."""
    key: tuple[object, ...] | None = None
    hit = None
    if coordinates is None or type(coordinates) in (list, tuple):
        try:
            key = (id(system), surface, value, direction, coordinates and tuple(coordinates), max_points, t_final,
                   tolerance)
            hit = _validated.get(key)
        except TypeError:  # unhashable arguments: checked (and refused) below
            key = None
    if hit is not None and hit[0] is system and type(max_points) is int:
        return hit[1]
    req = _check(system, surface, value, direction, coordinates, max_points, t_final, tolerance)
    if key is not None:
        if len(_validated) >= 256:
            _validated.clear()
        _validated[key] = (system, req)
    return req


def _check(system: MechanicalSystem, surface: str, value: float, direction: str,
           coordinates: Sequence[str] | None, max_points: int, t_final: float,
           tolerance: float | None) -> _Request:
    """Every field of a section request checked (:class:`SurfaceError` names the refused one)."""
    if not isinstance(surface, str):
        raise SurfaceError("surface", f"must be a string, got {type(surface).__name__}")
    prep = _prepared(system, surface)
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise SurfaceError("value", f"must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise SurfaceError("value", f"must be finite, got {value!r}")
    if direction not in DIRECTIONS:
        raise SurfaceError("direction", f"must be one of {', '.join(DIRECTIONS)}; got {direction!r}")
    names = prep.names
    coords = prep.default_coordinates if coordinates is None else coordinates
    if isinstance(coords, str) or not isinstance(coords, Sequence) or len(coords) != 2:
        raise SurfaceError("coordinates", f"must be a list of two component names, got {coords!r}")
    for i, name in enumerate(coords):
        if not isinstance(name, str) or name not in names:
            raise SurfaceError(f"coordinates[{i}]", f"unknown component {name!r}; allowed: {', '.join(names)}")
    if coords[0] == coords[1]:
        raise SurfaceError("coordinates[1]", f"the two coordinates must differ (both are {coords[0]!r})")
    if isinstance(max_points, bool) or not isinstance(max_points, (int, np.integer)):
        raise SurfaceError("max_points", f"must be an integer, got {max_points!r}")
    if not 1 <= max_points <= MAX_POINTS_LIMIT:
        raise SurfaceError("max_points", f"must be between 1 and {MAX_POINTS_LIMIT}, got {max_points}")
    try:
        t_final = float(t_final)
    except (TypeError, ValueError):
        raise SurfaceError("t_final", f"must be a number, got {t_final!r}") from None
    if not (math.isfinite(t_final) and t_final > 0):
        raise SurfaceError("t_final", f"must be finite and > 0, got {t_final!r}")
    tol = MACHINE_EPSILON if tolerance is None else float(tolerance)
    if not (math.isfinite(tol) and 0 < tol < 1):
        raise SurfaceError("tolerance", f"must be in (0, 1), got {tolerance!r}")
    return _Request(prep, value, direction, (coords[0], coords[1]), int(max_points), t_final, tol)


def _check_arrays(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> None:
    n_par = len(system.parameter_symbols)
    if parameters.shape[-1] != n_par:
        raise SurfaceError("parameters", f"needs {n_par} values per member, got shape {parameters.shape}")
    if states.shape[-1] != system.dimension:
        raise SurfaceError("initial_state", f"needs {system.dimension} components, got shape {states.shape}")
    if not np.isfinite(parameters).all():
        raise SurfaceError("parameters", "non-finite value")
    if not np.isfinite(states).all():
        raise SurfaceError("initial_state", "non-finite component")
