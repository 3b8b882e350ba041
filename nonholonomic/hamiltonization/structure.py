"""The structural evidence of a job: Hamiltonian form after the time substitution (``bracket``) and
the Euler-angle local forms (``euler_angles``), for the kinds the paper gives them for.

The heavy modules (:mod:`nonholonomic.hamiltonization.forms`, :mod:`nonholonomic.hamiltonization.local_forms`,
:mod:`nonholonomic.evidence.brackets`) are imported when a job asks for these checks.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.measure import CheckEvidence
from nonholonomic.numerics.kernels import VectorKernel, vectorize
from nonholonomic.systems import registered

#: States at most used for the pointwise structural checks (thinned evenly from the samples).
MAX_POINTS = 50


def structural_checks(kind: str) -> tuple[str, ...]:
    """The structural checks available for ``kind``: its record's ``structure_checks`` (a Hamiltonian form after
    a time substitution, eq. 2504-10-2, 2604-5..7, or Theorem 1's; Euler-angle local forms, eq. 2504-6..9,
    Theorem 2); none for a kind no module registers."""
    record = registered(kind)
    return () if record is None else record.structure_checks


def _thin(states: np.ndarray) -> np.ndarray:
    return states[np.unique(np.linspace(0, len(states) - 1, min(len(states), MAX_POINTS)).astype(int))]


@lru_cache(maxsize=32)
def _to_bracket_variables(system: MechanicalSystem) -> tuple[VectorKernel, tuple[int, ...]]:
    from nonholonomic.hamiltonization.forms import hamiltonian_form

    form = hamiltonian_form(system)
    if form is None:
        raise ValueError(f"no Hamiltonian form is known for {system.kind}")
    args = system.state_symbols + system.parameter_symbols
    where = tuple(system.parameter_symbols.index(s) for s in form.bracket.parameters)
    return vectorize(form.to_bracket_variables, args), where


def _why_no_form(system: MechanicalSystem) -> str:
    """Why a user's system has no Hamiltonian form: its Hamiltonization verdict, else its measure's."""
    verdict = (system.structure or {}).get("hamiltonization") or {}
    return str(verdict.get("reason") or system.measure.formula)


def bracket_evidence(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> list[CheckEvidence]:
    """The time-substituted flow against the Hamiltonian vector field (and its control in time t),
    then the bracket itself (Jacobi identity, Casimirs, rank) at the mapped states."""
    from nonholonomic.evidence.brackets import structure_evidence
    from nonholonomic.hamiltonization.forms import hamiltonian_form, hamiltonian_form_evidence

    points = _thin(states)
    if hamiltonian_form(system) is None:  # a user's system without Theorem 1's multiplier
        return [CheckEvidence(name="hamiltonian_flow", quantity="d y/d tau - {H, y}", formula="none",
                              equation=system.equation, method="symbolic", residual=None, tolerance=None, passed=None,
                              detail="no Hamiltonian form: " + _why_no_form(system))]
    items = hamiltonian_form_evidence(system, parameters, points)
    to_bracket, where = _to_bracket_variables(system)
    form = hamiltonian_form(system)
    assert form is not None
    return items + structure_evidence(form.bracket, to_bracket(points, parameters), parameters[list(where)])


def euler_angle_evidence(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> list[CheckEvidence]:
    """The local forms in Euler angles against the vector forms at the job's states."""
    from nonholonomic.hamiltonization.local_forms import local_form_evidence

    return local_form_evidence(system, parameters, _thin(states))
