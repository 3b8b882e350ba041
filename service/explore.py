"""The section explorer's runs: a click's orbit integrated in a thread of the API process, its crossings
kept as they come (the page polls them), and the defaults the page starts from.

A click must answer within a second, so its orbit does not go through the job queue: it is integrated here,
by at most :data:`WORKERS` threads at once (the others wait their turn), each run bounded by
:data:`~schemas.explore.MAX_EXPLORE_T` and :data:`~schemas.explore.MAX_EXPLORE_POINTS`. The crossings come
from the core's sections (heyoka's events) in pieces: :data:`FIRST_PIECE` crossings first, then
:data:`PIECE` at a time, each piece starting from the last crossing's state (a restart on the surface;
its crossing at t = 0 is not counted twice). The last :data:`KEEP` runs are kept.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from nonholonomic.analysis.chaos_map.grid import Grid, GridError, plan
from nonholonomic.analysis.periodic_orbit import crossing_states
from nonholonomic.analysis.poincare import section
from nonholonomic.analysis.sampling import fixable
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import IntegrationError
from nonholonomic.numerics.kernels import numeric, parameter_vector, state_vector
from nonholonomic.systems import KINDS, SUPPORTED_POTENTIALS, SYSTEMS, get_system
from schemas.explore import ExploreSection

#: Runs integrated at once; crossings in the first piece and in each next one; runs kept.
WORKERS, FIRST_PIECE, PIECE, KEEP = 2, 100, 500, 64
#: A restart's crossing at its own start (on the surface) is below this time and is not counted.
RESTART_T = 1e-9


@dataclass
class Exploration:
    """One click's orbit: its crossings so far (``points``, the section's two coordinates)."""

    id: str
    system: MechanicalSystem
    state: np.ndarray
    branches: int
    coordinates: tuple[str, str]
    t_final: float
    max_points: int
    points: list[list[float]] = field(default_factory=list)
    t_reached: float = 0.0
    done: bool = False
    error: str | None = None
    started: float = field(default_factory=time.monotonic)


class Explorations:
    """The runs of one API process."""

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(WORKERS, thread_name_prefix="explore")
        self._runs: OrderedDict[str, Exploration] = OrderedDict()
        self._lock = threading.Lock()

    def start(self, system: MechanicalSystem, p: np.ndarray, x0: np.ndarray, branches: int,
              plane: ExploreSection, t_final: float, max_points: int) -> Exploration:
        run = Exploration(uuid.uuid4().hex, system, x0, branches, (plane.coordinates[0], plane.coordinates[1]),
                          t_final, max_points)
        with self._lock:
            self._runs[run.id] = run
            while len(self._runs) > KEEP:
                self._runs.popitem(last=False)
        self._pool.submit(_integrate, run, p, plane)
        return run

    def get(self, run_id: str) -> Exploration | None:
        with self._lock:
            return self._runs.get(run_id)


def _integrate(run: Exploration, p: np.ndarray, plane: ExploreSection) -> None:
    """Crossings in pieces, appended as they are found."""
    try:
        x, t0, piece = run.state, 0.0, FIRST_PIECE
        while len(run.points) < run.max_points and t0 < run.t_final:
            want = min(piece, run.max_points - len(run.points))
            sec = section(run.system, p, x, run.t_final - t0, plane.surface, value=plane.value,
                          direction=plane.direction, coordinates=run.coordinates, max_points=want + 1)
            keep = sec.t > RESTART_T
            new = sec.coordinates[keep][:want]
            run.points.extend(new.tolist())
            if not sec.stopped_early or not len(new):  # t_final reached
                run.t_reached = run.t_final
                break
            last = len(new) - 1  # the next piece starts from this crossing
            x = crossing_states(run.system, sec)[keep][last]
            t0 += float(sec.t[keep][last])
            run.t_reached = t0
            piece = PIECE
    except (IntegrationError, ValueError) as exc:
        run.error = str(exc)
    finally:
        run.done = True


_MADE = threading.Lock()


def explorations(app_state: Any) -> Explorations:
    """The app's runs (made on first use, once)."""
    with _MADE:
        found = getattr(app_state, "explorations", None)
        if found is None:
            found = app_state.explorations = Explorations()
    return found


def orbit_points(system: MechanicalSystem, p: np.ndarray, x0: np.ndarray, period_t: float, plane: ExploreSection,
                 period: int) -> list[list[float]]:
    """The k crossings of a periodic orbit over one period, in the plane's coordinates."""
    sec = section(system, p, x0, period_t * (1 + 1e-7), plane.surface, value=plane.value, direction=plane.direction,
                  coordinates=tuple(plane.coordinates), max_points=period + 1)
    return sec.coordinates[sec.t > RESTART_T].tolist()


# -------------------------------------------------------------------------------------------------- defaults

def explorable() -> dict[str, list[str]]:
    """The kinds (and their potentials) the explorer can draw: those with states on a level set."""
    return {kind: list(SUPPORTED_POTENTIALS[kind]) for kind in SYSTEMS if KINDS[kind].sampling is not None}


@lru_cache(maxsize=64)
def defaults(kind: str, potential: str) -> dict[str, Any]:
    """The kind's example system with ``potential``, and a plane that works for it: the level of the example's
    initial state (its fixable integrals), the section the last position component = 0, the first plane
    (another position component, a velocity component) the grid can complete.

    Raises
    ------
    KeyError
        An unknown kind or potential, or one the explorer cannot draw.
    """
    if kind not in explorable() or potential not in explorable()[kind]:
        raise KeyError(f"{kind} with the {potential} potential cannot be explored")
    module = SYSTEMS[kind]
    example = dict(module.EXAMPLE["system"])
    if potential != example.get("potential", {}).get("kind"):
        example["potential"] = dict(_potential_example(kind, potential))
    system = get_system(kind, potential)
    values = {k: v for k, v in example.items() if k not in ("kind", "potential")}
    values.update({k: v for k, v in example["potential"].items() if k != "kind"})
    p = parameter_vector(system, values)
    x = state_vector(system, dict(module.EXAMPLE["initial_state"]), p)
    names = [i.name for i in system.integrals]
    level_values = numeric(system).integrals(x[None, :], p)[0]
    level = {name: round(float(level_values[names.index(name)]), 6) for name in fixable(system)}
    record = KINDS[kind]
    assert record.sampling is not None  # explorable
    velocity = record.sampling.velocity
    vectors = {v.name: [str(s) for s in v.symbols] for v in system.state}
    positions = [c for name, comps in vectors.items() if name != velocity for c in comps]
    if record.explorer_plane is not None:  # the kind's own first plane (the ball's: the docs' chaos map's)
        preferred = record.explorer_plane
        return {"system": example, "section": {"surface": preferred.surface, "value": 0.0, "direction": "increasing",
                                               "coordinates": list(preferred.coordinates),
                                               "level": dict(preferred.level)}}
    for surface in reversed(positions):
        for first in positions:
            for second in vectors[velocity]:
                if first == surface:
                    continue
                try:
                    plan(system, Grid(surface, 0.0, (first, second), level, (1, 1)))
                except GridError:
                    continue
                return {"system": example, "section": {"surface": surface, "value": 0.0, "direction": "increasing",
                                                       "coordinates": [first, second], "level": level}}
    return {"system": example, "section": None}


def _potential_example(kind: str, potential: str) -> dict[str, Any]:
    """A potential's request block with every parameter at a generic value (1 for scalars, (0.3, −0.2, 0.5)
    for vectors, diag(0.3, 0.5, 0.8) for matrices)."""
    block: dict[str, Any] = {"kind": potential}
    for par in SYSTEMS[kind].POTENTIALS[potential].parameters:
        if par.shape == "symmetric_matrix":
            block[par.name] = [0.3, 0.5, 0.8]
        else:
            block[par.name] = [0.3, -0.2, 0.5][: len(par.symbols)] if par.is_vector else 1.0
    return block
