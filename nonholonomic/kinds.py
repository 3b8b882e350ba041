"""The record of a system kind: everything the service asks about a kind, in one typed value.

Each system module ends with ``SYSTEM_KIND = SystemKind(sys.modules[__name__], ...)``;
:mod:`nonholonomic.systems` collects the built-in ones and those other distributions declare under the
entry-point group :data:`ENTRY_POINT_GROUP`. Consumers (the catalog, the request models, the state
checks, the sampler, the structure report, the explorer, plots, pages and exports) ask the record,
never a kind's name. This module is data only: it imports no system.

Two shapes of kind:

* a **catalog kind** (``written_by_user=False``): its module declares ``KIND``, ``TITLE``,
  ``PARAMETERS``, ``STATE``, ``POTENTIALS``, ``POTENTIAL_VARIABLES``, ``EXAMPLE`` and
  ``define(potential) -> MechanicalSystem`` (``define(potential, surface)`` with ``surface=True``);
  the request model is generated from those declarations;
* a kind **written by the user** (``written_by_user=True``: a generalized Chaplygin system, a
  Lagrangian system): the request carries the whole system; its request model lives in
  :mod:`schemas.systems` (``USER_WRITTEN_MODELS``) and its catalog entry comes from ``catalog_entry``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any, Literal

#: The entry-point group under which a distribution declares modules holding a ``SYSTEM_KIND``.
ENTRY_POINT_GROUP = "nonholonomic.kinds"

#: The drawers of :mod:`nonholonomic.analysis.sampling`; ``sphere_then_velocity`` serves any kind whose
#: position is a unit vector and whose energy is quadratic in one velocity vector.
SamplingMethod = Literal["sphere_then_velocity", "chaplygin_ball_veselova", "ball_on_quadric"]


def root_words(where: str) -> str:
    """The catalog's words for the last step of every sampling recipe (``where``: the energy's equation)."""
    return (f"t solves H = h ({where}), either root with probability 1/2; positions and directions that miss "
            "the level are redrawn")


@dataclass(frozen=True)
class Sampling:
    """How :func:`nonholonomic.analysis.sampling.on_level` draws a kind's states on a level set.

    Attributes
    ----------
    method : SamplingMethod
        The drawer.
    velocity : str
        The state vector solved for on the energy level, ``v = v0 + t u``.
    fixable : tuple of str
        The integrals a level may fix, energy first (kept where the system, its potential, has them).
    energy_equation : str
        Where the energy H is written (the catalog's words cite it: ``"eq. 2604-2"``).
    position : str, optional
        ``sphere_then_velocity``: the unit state vector drawn uniform on the sphere.
    plane : bool
        ``sphere_then_velocity``: the velocity's direction ⊥ the position (a constraint (v, position) = 0).
    linear : str, optional
        ``sphere_then_velocity``: the linear integral (v, position) = c a level may fix.
    describe : callable, optional
        ``describe(fixed)``: the catalog's one line for the integrals ``fixed``; None: :meth:`words` writes it
        from a ``sphere_then_velocity`` plan.
    """

    method: SamplingMethod
    velocity: str
    fixable: tuple[str, ...]
    energy_equation: str
    position: str | None = None
    plane: bool = False
    linear: str | None = None
    describe: Callable[[tuple[str, ...]], str] | None = field(default=None, compare=False)

    def words(self, fixed: tuple[str, ...]) -> str:
        """The catalog's one line on how the states are drawn with the integrals ``fixed``."""
        if self.describe is not None:
            return self.describe(fixed)
        x, v = self.position, self.velocity
        if self.plane:
            how = f"{v} = t u with u uniform among unit vectors ⊥ {x}"
        elif self.linear is not None:
            how = (f"{v} = c {x} + t u with u uniform among unit vectors ⊥ {x} if the {self.linear} c = ({v}, {x}) "
                   f"is fixed, else {v} = t u with u uniform on the sphere")
        else:
            how = f"{v} = t u with u uniform on the sphere"
        return f"{x} uniform on the sphere; {how}; {root_words(self.energy_equation)}"


@dataclass(frozen=True)
class ExplorerPlane:
    """The section a kind's explorer page starts with (``/explore``): the surface ``surface = 0`` crossed
    increasing, the plane of two state components, and the level of the fixable integrals."""

    surface: str
    coordinates: tuple[str, str]
    level: Mapping[str, float]


@dataclass(frozen=True)
class SystemKind:
    """One kind of system, as every layer sees it.

    Attributes
    ----------
    module : ModuleType
        The kind's core module (``KIND``, ``TITLE``, ``define`` ... : see the module docstring).
    written_by_user : bool
        The request writes the whole system (coordinates, L, constraints ...), not a catalog's parameters.
    surface : bool
        The kind also takes a user's surface Φ(x) = 0 (its state check refuses an x where ∇Φ = 0).
    sampling : Sampling, optional
        How an ensemble's ``sample`` draws states on a level set; None: no recipe (the members' initial
        states or a sweep are given instead).
    hamiltonian_form : bool
        The paper's Hamiltonian form after the time substitution (:mod:`nonholonomic.hamiltonization.forms`).
    local_forms : bool
        The Euler-angle Hamiltonian forms (:mod:`nonholonomic.hamiltonization.local_forms`).
    theorem_1 : bool
        The structure comes from Theorem 1's reducing multiplier (a generalized Chaplygin system).
    explorer_plane : ExplorerPlane, optional
        The explorer's first plane; None: the first plane the chaos-map grid can complete.
    singular_field : str, optional
        A user-written kind: what makes its field not finite at a state (said when an initial state is
        refused, naming ``initial_state.q``).
    catalog_entry : callable, optional
        A user-written kind: its entry of ``GET /v1/systems`` (how to pose one).
    """

    module: ModuleType
    written_by_user: bool = False
    surface: bool = False
    sampling: Sampling | None = None
    hamiltonian_form: bool = False
    local_forms: bool = False
    theorem_1: bool = False
    explorer_plane: ExplorerPlane | None = None
    singular_field: str | None = None
    catalog_entry: Callable[[], dict[str, Any]] | None = field(default=None, compare=False)

    @property
    def name(self) -> str:
        """The request's ``kind``."""
        return str(self.module.KIND)

    @property
    def title(self) -> str:
        return str(self.module.TITLE)

    @property
    def structure_checks(self) -> tuple[str, ...]:
        """The structure checks a job of this kind may ask for (``bracket``, ``euler_angles``)."""
        return ((("bracket",) if self.hamiltonian_form or self.theorem_1 else ())
                + (("euler_angles",) if self.local_forms else ()))


def unknown_kind(name: str, known: list[str]) -> KeyError:
    """The error of a lookup of an unregistered kind."""
    return KeyError(f"unknown system kind {name!r}; known: {sorted(known)}")
