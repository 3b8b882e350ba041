"""One refusal for every layer (nonholonomic.refusals): every look-alike is a RefusedField, keeps its class,
fields and message across processes (pickle), and is named from the block it sits in."""

from __future__ import annotations

import pickle

import pytest

from nonholonomic.analysis.chaos_map.grid import GridError
from nonholonomic.analysis.periodic_orbit import PeriodicOrbitError
from nonholonomic.analysis.poincare.surface import SurfaceError
from nonholonomic.analysis.sampling import LevelError
from nonholonomic.isomorphisms import MapInputError
from nonholonomic.lagrangian.parse import DataError as LagrangianDataError
from nonholonomic.refusals import RefusedField, RefusedFields
from nonholonomic.systems.generalized_chaplygin import DataError as ChaplyginDataError
from schemas.ensembles import LevelProblem

SINGLE = [RefusedField, GridError, PeriodicOrbitError, SurfaceError, LevelError, LagrangianDataError,
          ChaplyginDataError, LevelProblem]


@pytest.mark.parametrize("cls", SINGLE, ids=lambda c: c.__qualname__)
def test_each_refusal_is_one_kind_and_survives_a_process_boundary(cls: type[RefusedField]) -> None:
    refusal = cls("coordinates[1]", "'x' is declared twice", 4)
    back = pickle.loads(pickle.dumps(refusal))
    assert isinstance(refusal, RefusedField) and isinstance(refusal, ValueError)
    assert type(back) is cls
    assert (back.field, back.reason, back.position) == ("coordinates[1]", "'x' is declared twice", 4)
    assert str(back) == str(refusal) == "coordinates[1]: 'x' is declared twice (at position 4)"
    assert back.problems() == [("coordinates[1]", "'x' is declared twice")]


def test_several_fields_at_once() -> None:
    refusal = MapInputError([("states[0].gamma", "|gamma| = 2, not 1"), ("states[2].M", "not finite")])
    back = pickle.loads(pickle.dumps(refusal))
    assert isinstance(back, MapInputError) and isinstance(back, RefusedFields)
    assert back.problems() == [("states[0].gamma", "|gamma| = 2, not 1"), ("states[2].M", "not finite")]
    assert str(back) == "states[0].gamma: |gamma| = 2, not 1; states[2].M: not finite"
    with pytest.raises(ValueError, match="at least one field"):
        RefusedFields([])


def test_a_refusal_is_named_from_its_block() -> None:
    assert GridError("shape", "at most 200 x 200").within("members.grid").problems() == [
        ("members.grid.shape", "at most 200 x 200")]
    assert RefusedField("[2]", "empty").within("constraints").problems() == [("constraints[2]", "empty")]
    nested = MapInputError([("gamma", "a"), ("M", "b")]).within("states[3]").within("body")
    assert nested.problems() == [("body.states[3].gamma", "a"), ("body.states[3].M", "b")]
    assert RefusedField("L", "no kinetic term").within("").problems() == [("L", "no kinetic term")]
