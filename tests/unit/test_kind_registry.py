"""The registry of system kinds (:mod:`nonholonomic.kinds`, :mod:`nonholonomic.systems`): every record agrees
with its module's definition, and the registry loads whatever module is imported first."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from nonholonomic.analysis.chaos_map.grid import component_index
from nonholonomic.analysis.sampling import fixable
from nonholonomic.systems import KINDS, SYSTEMS, get_system, kind_of, registered
from schemas.systems import SYSTEM_MODELS, USER_WRITTEN_MODELS
from tests.support import ROOT


@pytest.mark.parametrize("kind", sorted(SYSTEMS))
def test_a_catalog_kinds_record_agrees_with_its_definition(kind):
    record = kind_of(kind)
    assert record.name == kind == record.module.KIND and not record.written_by_user and kind in SYSTEM_MODELS
    system = get_system(kind, "zero")
    assert system.kind == kind and record.title == system.title
    vectors = {v.name for v in system.state}
    if record.sampling is not None:  # the plan solves for a state vector and fixes the energy first
        assert record.sampling.velocity in vectors and record.sampling.fixable[0] == "energy"
        assert record.sampling.position is None or record.sampling.position in vectors
        assert fixable(system)[0] == "energy"
    if record.explorer_plane is not None:
        plane = record.explorer_plane
        for name in (plane.surface, *plane.coordinates):
            component_index(system, name)  # raises KeyError for a name that is not a state component
        assert set(plane.level) <= set(fixable(system))
    assert record.singular_field is None and record.catalog_entry is None


@pytest.mark.parametrize("kind", sorted(set(KINDS) - set(SYSTEMS)))
def test_a_kind_written_by_the_user_has_its_request_model_and_catalog_entry(kind):
    record = kind_of(kind)
    assert record.written_by_user and record.sampling is None and record.theorem_1
    assert USER_WRITTEN_MODELS[kind].model_fields["kind"].annotation.__args__ == (kind,)
    assert record.catalog_entry is not None and record.catalog_entry()["kind"] == kind
    assert record.singular_field and "singular" in record.singular_field


def test_unknown_kinds():
    with pytest.raises(KeyError, match="unknown system kind 'top'; known: "):
        kind_of("top")
    assert registered("top") is None
    with pytest.raises(KeyError, match="unknown system kind 'lagrangian'"):
        get_system("lagrangian")  # its definition is built from its request


#: Modules a system module imports, or that import system modules at their top: each imported first.
FIRST = ["nonholonomic.hamiltonization.local_forms", "nonholonomic.hamiltonization.forms",
         "nonholonomic.hamiltonization.poisson", "nonholonomic.lagrangian.hamiltonization_search",
         "nonholonomic.isomorphisms", "nonholonomic.systems.generalized_chaplygin", "nonholonomic.initial_state"]


def test_the_registry_loads_whatever_module_is_imported_first():
    """A fresh interpreter per module (forked from one that imported only the third-party libraries): import it,
    then read the registry."""
    script = f"""
import os, sys
import numpy, scipy.integrate, sympy  # shared by the forks: each child imports only the project's modules
bad = []
for name in {FIRST!r}:
    pid = os.fork()
    if pid == 0:
        try:
            import importlib
            importlib.import_module(name)
            import nonholonomic.systems as s
            assert "lagrangian" in s.KINDS and "chaplygin_ball" in s.SYSTEMS
        except BaseException as exc:
            print(name, type(exc).__name__, exc, file=sys.stderr)
            os._exit(1)
        os._exit(0)
    if os.waitpid(pid, 0)[1] != 0:
        bad.append(name)
print(bad)
"""
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0 and done.stdout.strip() == "[]", done.stdout + done.stderr
