"""A grid on a section plane, each cell completed to a state on a level set: the cells of a chaos map.

A map asks for the section ``surface = value`` (the surface one state component, e.g. γ3 = 0), two
other components as the plane's ``coordinates`` (e.g. γ1 and M3), a ``level`` of the integrals (e.g.
H = 2, (M, γ) = 0 for Chaplygin's ball, eq. 2604-2) and a ``shape``. Each cell's centre fixes three
components; the others follow from the system's own constraints and integrals, as the level sampler
(:mod:`nonholonomic.analysis.sampling`) splits a state into positions and a velocity:

1. Positions. A position vector with one free component is completed by its constraint (|γ| = 1,
   Φ(x) = 0), read off the constraint's kernel as a polynomial of degree ≤ 2 in that component (the
   constraint itself or its square; checked at two more points): both real roots are candidates.
   A position vector with every component fixed must already satisfy its constraint.
2. The velocity ``v``: the constraints that involve it ((ω, γ) = 0) and the level's other integrals
   are read off the kernels at the cell's position (:mod:`.grid_velocity`). Linear ones ((M, γ) = c)
   leave a line ``v₀ + t n`` on which the energy is quadratic: two candidates. One quadratic one (the
   Jacobi problem's K, eq. 2804-4) leaves a plane on which it and the energy are two conics: their
   common points, up to four candidates.
3. The crossing. Of the candidates, those crossing the surface in the requested ``direction`` (the
   sign of the surface's time derivative, from the right-hand side) and, if a ``sheet`` expression is
   given, where it is > 0, are the cell's states on the section; the first is taken (the position
   roots with the free component ≥ 0 first) and ``branches`` says how many there were. A cell with
   none is ``outside`` the level.

Every completed state is checked with the kernels, the constraints and the fixed integrals to 1e-12 of
their scale (:func:`nonholonomic.analysis.sampling.verified`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from itertools import product

import numpy as np

from nonholonomic.analysis.chaos_map.grid_velocity import VelocityError, quadratic_roots, velocities
from nonholonomic.analysis.poincare.surface import SurfaceError, parse_surface
from nonholonomic.analysis.sampling import LevelError, fixable, no_plan, on_level, plan_of, verified
from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import vector_slice
from nonholonomic.numerics.kernels import NumericSystem, VectorKernel, numeric, vectorize
from nonholonomic.refusals import RefusedField

#: States drawn on the level to estimate the region it allows (the default ``ranges``).
RANGE_SAMPLES = 20000
#: The estimated region is widened by this fraction of its width on each side.
RANGE_MARGIN = 0.02


class GridError(RefusedField):
    """A grid that cannot be built, with the request field (relative to ``members.grid``) and why."""


@dataclass(frozen=True)
class Grid:
    """The section plane's grid.

    ``ranges`` None: the region the level allows (:func:`default_ranges`). Cell ``k = i · shape[1] + j``
    has its centre at ``axes()[0][i], axes()[1][j]``.
    """

    surface: str
    value: float
    coordinates: tuple[str, str]
    level: Mapping[str, float]
    shape: tuple[int, int]
    ranges: tuple[tuple[float, float], tuple[float, float]] | None = None
    direction: str = "increasing"
    sheet: str | None = None

    @property
    def cells(self) -> int:
        return self.shape[0] * self.shape[1]


@dataclass(frozen=True)
class Cells:
    """Completed cells (``start .. stop − 1``, or the ones asked for): ``states`` (NaN rows outside the
    level), ``branches`` (how many states of the level cross the section there in the direction: 0
    outside), ``values`` (each cell's two coordinates)."""

    start: int
    states: np.ndarray
    branches: np.ndarray
    values: np.ndarray

    @property
    def inside(self) -> np.ndarray:
        return self.branches > 0


def axes(grid: Grid, ranges: Sequence[Sequence[float]]) -> tuple[np.ndarray, np.ndarray]:
    """The cell centres along each coordinate: ``lo + (i + ½)(hi − lo)/n``."""
    out = []
    for (lo, hi), n in zip(ranges, grid.shape):
        out.append(lo + (np.arange(n) + 0.5) * (hi - lo) / n)
    return out[0], out[1]


def component_index(system: MechanicalSystem, name: str) -> int:
    """The state index of a component name (``gamma3``).

    Raises
    ------
    KeyError
        If ``name`` is not a state component.
    """
    names = [str(s) for s in system.state_symbols]
    if name not in names:
        raise KeyError(name)
    return names.index(name)


@dataclass(frozen=True)
class _Plan:
    """Which components each stage solves for."""

    fixed: tuple[int, ...]            # surface, then the two coordinates
    positions: tuple[tuple[int, int | None], ...]   # (constraint index, its free component or None)
    velocity: tuple[int, ...]         # the velocity vector's components
    free_velocity: tuple[int, ...]
    relations: tuple[tuple[str, int], ...]   # ("constraint" | "integral", index): relations of the velocity
    surface: int


def plan(system: MechanicalSystem, grid: Grid) -> _Plan:
    """Check that the grid determines a state per cell and say how it is completed.

    Raises
    ------
    GridError
        A name that is not a state component, a level the sampler cannot fix, a position left with
        more than one free component, a velocity not fixed to a line.
    """
    sampling = plan_of(system)
    if sampling is None:
        raise GridError("level", f"{system.kind}: {no_plan(system)}; a map needs states on a level set")
    names = [grid.surface, *grid.coordinates]
    idx = []
    for field, name in zip(["surface", "coordinates[0]", "coordinates[1]"], names):
        try:
            idx.append(component_index(system, name))
        except KeyError:
            raise GridError(field, f"{name!r} is not a state component of {system.kind}; known: "
                                   + ", ".join(str(s) for s in system.state_symbols)) from None
    if len(set(idx)) < 3:
        raise GridError("coordinates", "the surface and the two coordinates must be three different components")
    if grid.direction not in ("increasing", "decreasing"):
        raise GridError("direction", "a map's cells cross the section one way: increasing or decreasing")
    names_fixable = fixable(system)
    for name in grid.level:
        if name not in names_fixable:
            raise GridError(f"level.{name}", f"not a level {system.kind} can fix; a level may fix: "
                                             + ", ".join(names_fixable))
    if "energy" not in grid.level:
        raise GridError("level.energy", "required: the energy sets the size of the velocities")
    velocity_name = sampling.velocity
    vectors = {vec.name: range(*vector_slice(system, vec.name).indices(system.dimension)) for vec in system.state}
    velocity = tuple(vectors[velocity_name])
    positions = []
    for c, constraint in enumerate(system.constraints):
        if constraint.field == velocity_name:
            continue
        comps = vectors[constraint.field]
        free = [k for k in comps if k not in idx]
        if len(free) > 1:
            shown = ", ".join(str(system.state_symbols[k]) for k in free)
            raise GridError("coordinates", f"{constraint.field} keeps {len(free)} free components ({shown}) and only "
                                           f"one relation ({constraint.formula}): put the surface or a coordinate on "
                                           f"{constraint.field}")
        positions.append((c, free[0] if free else None))
    held = {k for c, k in positions if k is not None}
    for name, comps in vectors.items():
        if name == velocity_name:
            continue
        loose = [k for k in comps if k not in idx and k not in held]
        if loose:
            raise GridError("coordinates", f"nothing fixes {', '.join(str(system.state_symbols[k]) for k in loose)} "
                                           "on the section: choose coordinates that do")
    relations = tuple([("constraint", c) for c, con in enumerate(system.constraints) if con.field == velocity_name]
                   + [("integral", [i.name for i in system.integrals].index(name))
                      for name in grid.level if name != "energy"])
    free_velocity = tuple(k for k in velocity if k not in idx)
    if len(free_velocity) - len(relations) != 1:
        raise GridError("coordinates", f"{velocity_name} keeps {len(free_velocity)} free components and "
                                       f"{len(relations)} relations (constraints and the level's integrals "
                                       "other than the energy): a cell needs one velocity direction more than "
                                       "relations, for the energy to fix; fix more of the level or choose other "
                                       "coordinates")
    if grid.sheet is not None:
        _sheet(system, grid.sheet)
    return _Plan(tuple(idx), tuple(positions), velocity, free_velocity, relations, idx[0])


def _sheet(system: MechanicalSystem, text: str | None) -> VectorKernel | None:
    """The kernel of the ``sheet`` expression (the cells' states are those where it is > 0), or None.

    Raises
    ------
    GridError
        ``sheet``: a parse error or an unknown name (the safe parser of the sections' surfaces).
    """
    if text is None:
        return None
    try:
        expr = parse_surface(system, text)
    except SurfaceError as exc:
        where = f" (at position {exc.position})" if exc.position is not None else ""
        raise GridError("sheet", exc.reason + where) from None
    return vectorize([expr], list(system.state_symbols) + list(system.parameter_symbols))


def default_ranges(system: MechanicalSystem, p: np.ndarray, grid: Grid) -> tuple[tuple[float, float], ...]:
    """The region the level allows in each coordinate, estimated from :data:`RANGE_SAMPLES` states drawn
    on the level (seed 0) and widened by :data:`RANGE_MARGIN` of its width on each side (remembered per
    process: a POST validates the grid, then stores its ranges).

    Raises
    ------
    GridError
        If the level cannot be sampled.
    """
    return _ranges(system, tuple(np.asarray(p, dtype=float).tolist()), tuple(sorted(grid.level.items())),
                   grid.coordinates)


@lru_cache(maxsize=32)
def _ranges(system: MechanicalSystem, p: tuple[float, ...], level: tuple[tuple[str, float], ...],
            coordinates: tuple[str, str]) -> tuple[tuple[float, float], ...]:
    try:
        states = on_level(system, np.array(p), dict(level), RANGE_SAMPLES, 0)
    except LevelError as exc:
        raise GridError(exc.field, exc.reason) from None
    out = []
    for name in coordinates:
        column = states[:, component_index(system, name)]
        lo, hi = float(column.min()), float(column.max())
        pad = RANGE_MARGIN * max(hi - lo, 1e-12)
        out.append((lo - pad, hi + pad))
    return tuple(out)


def complete(system: MechanicalSystem, p: np.ndarray, grid: Grid, ranges: Sequence[Sequence[float]],
             start: int = 0, stop: int | None = None, indices: np.ndarray | None = None) -> Cells:
    """Cells ``start .. stop − 1`` (or the cells ``indices``) of ``grid`` completed to states on its level
    (module docstring).

    Raises
    ------
    GridError
        As :func:`plan`, or a position constraint that is not of degree ≤ 2 in its free component.
    """
    how = plan(system, grid)
    stop = grid.cells if stop is None else stop
    k = np.arange(start, stop) if indices is None else np.asarray(indices, dtype=int)
    u, v = axes(grid, ranges)
    values = np.column_stack([u[k // grid.shape[1]], v[k % grid.shape[1]]])
    base = np.zeros((len(k), system.dimension))
    base[:, how.fixed[0]] = grid.value
    base[:, how.fixed[1]] = values[:, 0]
    base[:, how.fixed[2]] = values[:, 1]
    kern = numeric(system)
    sheet = _sheet(system, grid.sheet)
    with np.errstate(all="ignore"):
        roots = [_position_roots(kern, p, system, base, c, free) for c, free in how.positions]
    best = np.full((len(k), system.dimension), np.nan)
    branches = np.zeros(len(k), dtype=int)
    sign = 1.0 if grid.direction == "increasing" else -1.0
    targets = dict(grid.level)
    for choice in product(*[range(len(r[1])) for r in roots]):
        states = base.copy()
        ok = np.ones(len(k), bool)
        for (free, candidates), pick in zip(roots, choice):
            if free is None:
                ok &= candidates[pick]
            else:
                states[:, free] = candidates[pick]
                ok &= np.isfinite(candidates[pick])
        try:
            with np.errstate(all="ignore"):
                found = velocities(kern, p, system, how.relations, how.free_velocity, states, targets)
        except VelocityError as exc:
            raise GridError("level", str(exc)) from None
        for t in found:
            trial = states.copy()
            trial[:, list(how.free_velocity)] = t
            good = ok & np.all(np.isfinite(trial), axis=1)
            with np.errstate(all="ignore"):
                rate = kern.rhs(np.where(good[:, None], trial, 0.0), p)[:, how.surface]
            good &= sign * rate > 0
            if sheet is not None:
                with np.errstate(all="ignore"):
                    good &= sheet(np.where(good[:, None], trial, 0.0), p)[:, 0] > 0
            good &= verified(system, p, np.where(good[:, None], trial, 0.0), targets)
            take = good & (branches == 0)
            best[take] = trial[take]
            branches += good
    return Cells(start, best, branches, values)


def _position_roots(kern: NumericSystem, p: np.ndarray, system: MechanicalSystem, base: np.ndarray, c: int,
                    free: int | None) -> tuple[int | None, list[np.ndarray]]:
    """(free component, candidate values) of one position constraint; with no free component, (None,
    [mask of the cells that satisfy it])."""
    constraint = system.constraints[c]
    target = float(constraint.value)

    def g(z: float | None) -> np.ndarray:
        trial = base.copy()
        if free is not None:
            trial[:, free] = z
        return kern.constraints(trial, p)[:, c]

    if free is None:
        scale = np.maximum(1.0, np.abs(kern.constraint_scales(base, p)[:, c]))
        return None, [np.abs(g(None) - target) <= 1e-12 * scale]
    for power in (1, 2):
        vals = {z: g(z) ** power - target ** power for z in (-1.0, 0.0, 1.0, 2.0, 0.5)}
        a0 = vals[0.0]
        a1 = (vals[1.0] - vals[-1.0]) / 2
        a2 = (vals[1.0] + vals[-1.0]) / 2 - a0
        fit = all(np.allclose(a0 + a1 * z + a2 * z * z, vals[z], rtol=1e-9, atol=1e-9)
                  for z in (2.0, 0.5) if np.all(np.isfinite(vals[z])))
        if fit:
            break
    else:
        raise GridError("coordinates", f"{constraint.formula} is not of degree <= 2 in "
                                       f"{system.state_symbols[free]}: a map cannot complete it")
    plus, minus = quadratic_roots(a0, a1, a2)
    return free, [plus, minus]
