"""Numeric failure is never a 500 (issue 34, item 2): property-based tests over expression trees built to
overflow, underflow or exhaust precision, on every route that takes an expression.

The trees are towers of exponentials (``exp(exp(exp(x)))``, up to six deep), huge and tiny constants
(``1e300``, ``1e-300``, ``10**-400``, ``710``, subnormals), their products, quotients and logarithms, and
cosh/sinh of them. Each goes into one field of an otherwise good request:

- ``POST /v1/hamiltonize``: L, a1, a2, b, U;
- ``POST /v1/brackets/verify``: a matrix entry, a Casimir;
- ``POST /v1/jobs``: a catalog kind's expression potential U, a claim, a Poincaré surface; a generalized
  Chaplygin system's L, a1, a2, b, U; a Lagrangian system's L;
- ``POST /v1/explore/plane``: a potential U.

The answer is a 2xx, a 422 problem naming a field, or a 503 past the machine's safety cap (never a verdict);
an accepted job ends succeeded, or failed with its reason (never hangs: it is cancelled after a wait); no
answer holds NaN or infinity. Tallies of the answers are printed (the closing note quotes them).
"""

from __future__ import annotations

import json
from typing import Any

import pytest
from hypothesis import given, settings, strategies as st

from tests.api.test_fuzz import EXAMPLES, FUZZ, _assert_problem, _strict, _submit_and_end, catalog, fuzz_client

__all__ = ["catalog", "fuzz_client"]  # the fixtures, shared with test_fuzz.py

#: Constants at the edges of double precision (and past them: the parser refuses those).
EDGES = ["1e300", "1e-300", "1e308", "2.2e-308", "5e-324", "10**-400", "10**400", "710", "-745", "1e-16",
         "1e16", "0.0"]


def _numeric_hazards(names: list[str]) -> st.SearchStrategy[str]:
    """Trees of towers of exp, edge constants, and what combines them."""
    leaf = st.one_of(st.sampled_from(names), st.sampled_from(EDGES))
    tower = st.builds(lambda k, a: "exp(" * k + a + ")" * k, st.integers(1, 6), leaf)
    piece = st.one_of(tower, leaf)
    return st.recursive(piece, lambda inner: st.one_of(
        st.tuples(inner, st.sampled_from(["+", "-", "*", "/", "**"]), inner).map(lambda t: f"({t[0]}){t[1]}({t[2]})"),
        st.tuples(st.sampled_from(["log", "cosh", "sinh", "sqrt", "exp"]), inner).map(lambda t: f"{t[0]}({t[1]})")),
        max_leaves=4)


def _tally(seen: dict[int, int], status: int) -> None:
    seen[status] = seen.get(status, 0) + 1


def _answered(r: Any, seen: dict[int, int], ok: tuple[int, ...] = (200,)) -> None:
    _tally(seen, r.status_code)
    assert r.status_code in (*ok, 422, 503), (r.status_code, r.text)
    if r.status_code in ok:
        _strict(r.text)
    else:
        _assert_problem(r)


HAMILTONIZE = {"coordinates": ["x", "y"], "velocities": ["a", "b"], "L": "(a**2 + b**2)/2",
               "a1": "sin(x)", "a2": "cos(y)", "b": "1"}


def test_numeric_hazards_in_a_hamiltonization_are_never_a_500(fuzz_client):
    seen: dict[int, int] = {}

    @settings(FUZZ, max_examples=max(EXAMPLES // 3, 10))
    @given(field=st.sampled_from(["L", "a1", "a2", "b", "potential"]), text=_numeric_hazards(["x", "y"]))
    def check(field: str, text: str) -> None:
        body = {**HAMILTONIZE, field: text if field != "L" else f"(a**2 + b**2)/2 + {text}"}
        _answered(fuzz_client.post("/v1/hamiltonize", json=body), seen)

    check()
    print(f"/v1/hamiltonize numeric hazards: {seen}")
    assert seen.get(422, 0) >= 1, seen


def test_numeric_hazards_in_a_bracket_are_never_a_500(fuzz_client):
    seen: dict[int, int] = {}

    @settings(FUZZ, max_examples=max(EXAMPLES // 3, 10))
    @given(text=_numeric_hazards(["x", "y", "z"]), where=st.sampled_from(["entry", "casimir"]))
    def check(text: str, where: str) -> None:
        matrix = [["0", "z", "-y"], ["-z", "0", "x"], ["y", "-x", "0"]]
        body: dict[str, Any] = {"variables": ["x", "y", "z"], "matrix": matrix}
        if where == "entry":
            matrix[0][1], matrix[1][0] = text, f"-({text})"
        else:
            body["casimirs"] = {"C": text}
        _answered(fuzz_client.post("/v1/brackets/verify", json=body), seen)

    check()
    print(f"/v1/brackets/verify numeric hazards: {seen}")


@st.composite
def hazardous_jobs(draw: st.DrawFn, systems: list[dict[str, Any]]) -> dict[str, Any]:
    """A short catalog example with one expression field made of numeric hazards."""
    entry = draw(st.sampled_from(systems))
    body = json.loads(json.dumps(entry["example"]))
    body.update(t_final=draw(st.sampled_from([0.05, 0.5])), samples=3, checks=["integrals"])
    system = body["system"]
    user_fields = [f for f in ("L", "a1", "a2", "b") if isinstance(system.get(f), str)]
    if user_fields:  # a system written by the user: one of its expressions
        names = system.get("coordinates", []) + system.get("velocities", []) + list(system.get("parameters", {}))
        field = draw(st.sampled_from(user_fields))
        text = draw(_numeric_hazards(names))
        system[field] = f"{system[field]} + {text}" if field == "L" else text
        return body
    components = [c for v in entry["state"] for c in v["components"]]
    where = draw(st.sampled_from(["potential", "claim", "poincare"]))
    if where == "potential" and entry.get("potential_expression"):
        names = entry["potential_expression"]["variables"]
        system["potential"] = {"kind": "expression", "U": draw(_numeric_hazards(names)), "parameters": {}}
    elif where == "claim":
        body["claims"] = [{"name": "claim", "expression": draw(_numeric_hazards(components))}]
    else:
        body["poincare"] = {"surface": draw(_numeric_hazards(components)), "max_points": 3}
    return body


def test_numeric_hazards_in_jobs_are_never_a_500_and_accepted_jobs_end_clearly(fuzz_client, catalog):
    seen: dict[int, int] = {}
    ends: dict[str, int] = {}

    @settings(FUZZ, max_examples=max(EXAMPLES // 2, 10))
    @given(body=hazardous_jobs(catalog))
    def check(body: dict[str, Any]) -> None:
        _, view = _submit_and_end(fuzz_client, body, seen)
        if view is not None:
            key = view["status"] if view["status"] != "failed" else f"failed: {view['error']['type']}"
            ends[key] = ends.get(key, 0) + 1

    check()
    print(f"/v1/jobs numeric hazards: answers {seen}, accepted jobs ended {ends}")
    assert seen.get(202, 0) >= 1 and seen.get(422, 0) >= 1, seen


def test_numeric_hazards_in_an_explored_potential_are_never_a_500(fuzz_client, catalog):
    seen: dict[int, int] = {}
    ball = next(e for e in catalog if e["kind"] == "chaplygin_ball")

    @settings(FUZZ, max_examples=max(EXAMPLES // 6, 8))
    @given(text=_numeric_hazards(ball["potential_expression"]["variables"]))
    def check(text: str) -> None:
        system = {**ball["example"]["system"], "potential": {"kind": "expression", "U": text, "parameters": {}}}
        body = {"system": system, "section": {"surface": "gamma3", "coordinates": ["gamma1", "M3"],
                                              "level": {"energy": 2.0, "area": 0.0}}}
        _answered(fuzz_client.post("/v1/explore/plane", json=body), seen)

    check()
    print(f"/v1/explore/plane numeric hazards: {seen}")


@pytest.mark.parametrize("text", ["exp(exp(exp(exp(exp(x)))))", "exp(exp(exp(exp(exp(y)))))*1e-300",
                                  "log(exp(exp(exp(exp(x)))))", "cosh(exp(exp(exp(710))))"])
def test_the_audits_towers_are_answered_without_a_500_on_every_field(fuzz_client, text):
    seen: dict[int, int] = {}
    for field in ("a1", "a2", "b", "potential"):
        _answered(fuzz_client.post("/v1/hamiltonize", json={**HAMILTONIZE, field: text}), seen)
    assert set(seen) <= {200, 422}, seen
