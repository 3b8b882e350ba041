"""heyoka expressions generated from a system's one symbolic definition.

Every heyoka integrator of the core (single trajectories, batch mode, Poincaré events, variational
equations) is built from :func:`taylor_system`, so the right-hand side is written once, in sympy,
in the system's module. State symbols become heyoka variables (``M1`` ... in the order of
``system.state_symbols``), then ``tau`` when the system has a reduced time; parameters become
runtime parameters ``hy.par[i]``, so one compiled integrator serves every parameter value.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import heyoka as hy
import numpy as np
import sympy as sp

from nonholonomic.definition import MechanicalSystem


@dataclass(frozen=True, eq=False)
class TaylorSystem:
    """The heyoka form of one :class:`MechanicalSystem`.

    Attributes
    ----------
    system : the symbolic definition it was generated from.
    variables : heyoka variables, the state symbols' names in order, then ``tau`` if ``has_tau``.
    rhs : ``d/dt`` of each variable (same order).
    n_state : number of state variables (``system.dimension``).
    has_tau : whether the reduced time τ is integrated as the last variable.
    n_pars : length of the runtime parameter vector (see :meth:`runtime_parameters`).
    """

    system: MechanicalSystem
    variables: tuple[hy.expression, ...]
    rhs: tuple[hy.expression, ...]
    n_state: int
    has_tau: bool
    n_pars: int
    _mapping: dict[sp.Symbol, hy.expression]

    @property
    def equations(self) -> list[tuple[hy.expression, hy.expression]]:
        """``[(variable, rhs), ...]`` as heyoka's integrators take them."""
        return list(zip(self.variables, self.rhs))

    @property
    def state_equations(self) -> list[tuple[hy.expression, hy.expression]]:
        """The state's equations without τ (for variational equations)."""
        return list(zip(self.variables[: self.n_state], self.rhs[: self.n_state]))

    def runtime_parameters(self, parameters: np.ndarray) -> np.ndarray:
        """heyoka's parameter vector from the system's parameters (order of ``system.parameter_symbols``).

        Works on one vector (shape ``(n,)``) or on a batch (shape ``(n, batch)``, one column per member).
        """
        return np.asarray(parameters, dtype=float)

    def expression(self, expr: sp.Expr) -> hy.expression:
        """Translate a sympy expression in the state and parameter symbols into heyoka (e.g. an
        event's surface)."""
        return hy.from_sympy(sp.sympify(expr), self._mapping)

    def initial(self, state: Sequence[float] | np.ndarray) -> np.ndarray:
        """The integrator's initial vector from a state: the state, then τ(0) = 0 if ``has_tau``."""
        y = np.asarray(state, dtype=float)
        return np.append(y, 0.0) if self.has_tau else y.copy()


@lru_cache(maxsize=64)
def taylor_system(system: MechanicalSystem) -> TaylorSystem:
    """The heyoka form of ``system`` (once per system and process)."""
    names = [str(s) for s in system.state_symbols] + (["tau"] if system.reduced_time else [])
    hvars = hy.make_vars(*names)
    if len(names) == 1:
        hvars = [hvars]
    mapping: dict[sp.Symbol, hy.expression] = dict(zip(system.state_symbols, hvars))
    mapping.update({s: hy.par[i] for i, s in enumerate(system.parameter_symbols)})
    rhs = [hy.from_sympy(f, mapping) for f in system.rhs]
    if system.reduced_time:
        rhs.append(hy.from_sympy(system.reduced_time.density, mapping))
    return TaylorSystem(system=system, variables=tuple(hvars), rhs=tuple(rhs), n_state=system.dimension,
                        has_tau=system.reduced_time is not None, n_pars=len(system.parameter_symbols),
                        _mapping=mapping)
