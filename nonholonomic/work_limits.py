"""Deterministic limits on symbolic work: what a search or proof may take on, measured in operations.

A verdict must be the same on every machine, at any load, on the first call and the hundredth. So no
search or proof is cut by a clock (:mod:`nonholonomic.bounded` runs each to its end); what keeps it
small is a measure of the work decided *before* it starts: the size of an expression in sympy
operations (``count_ops``), the unknowns of an ansatz, the terms of a fraction. Past a limit the step is
not tried and its verdict is ``undecided`` with a reason that names the measure, its value and the
limit, e.g. ``"not tried: 5,210 operations > max 4,000 (max_proof_ops)"`` — the same words everywhere.

The limits a request may raise (a symbolic route's ``limits`` block) are :class:`WorkLimits`; the others
are module constants of the searches that use them.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

#: Largest expression (sympy operations) a symbolic identity proof is tried on (div(rho f) = 0, dI/dt = 0,
#: a flow identity, a bracket's Jacobi identity term by term, a closedness condition).
MAX_PROOF_OPS = 20_000
#: Largest integrand (sympy operations) given to sympy's ``integrate`` (a density from its logarithmic
#: derivatives, a gyroscopic form's exact area integral): sympy's Risch and heuristic integrators have no
#: bound of their own (measured: 95 s on an integrand of 114 operations from Veselova's system).
MAX_INTEGRATE_OPS = 60
#: Largest expression (sympy operations) that is cancelled and simplified for display or reuse
#: (larger ones are kept as they are: equal, only not shortened).
MAX_TIDY_OPS = 2000


@dataclass(frozen=True)
class WorkLimits:
    """The limits of one request's symbolic work (defaults: the module's constants)."""

    max_proof_ops: int = MAX_PROOF_OPS
    max_integrate_ops: int = MAX_INTEGRATE_OPS
    max_tidy_ops: int = MAX_TIDY_OPS


DEFAULT = WorkLimits()


def operations(*exprs: sp.Basic) -> int:
    """The sympy operation count (``count_ops``) of ``exprs`` together: a measure of the symbolic work
    on them, the same on every machine."""
    return int(sum(sp.count_ops(e) for e in exprs))


def over(size: int, limit: int, name: str, what: str = "") -> str | None:
    """The deterministic reason a step is not tried (``size`` > ``limit``), or None when it may run."""
    if size <= limit:
        return None
    return f"{what + ' ' if what else ''}not tried: {size:,} operations > max {limit:,} ({name})"
