"""A hypothesis fuzzer over the job and symbolic requests: whatever comes in, the answer is a 2xx or a
4xx problem naming fields, never a 500; an accepted job ends succeeded or failed with a clear error and
its JSON holds no NaN or infinity.

Bodies start from the catalog's example of each kind, then are spoiled 0 to 3 times: a value replaced
by an extreme number or a wrong type, scaled by up to 1e300, a key deleted or an unknown one added. Expressions come from a
small grammar with the whitelist's functions and forbidden ones, huge literals and broken syntax.

Short here (``NONHOLONOMIC_FUZZ_EXAMPLES``, default 60 per request kind); ``bench/fuzz_api.py`` runs
it long.
"""

from __future__ import annotations

import json
import math
import os
import time
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

EXAMPLES = int(os.environ.get("NONHOLONOMIC_FUZZ_EXAMPLES", "60"))
PROBLEM = "application/problem+json"
#: Seconds an accepted job may run before the fuzzer cancels it (a slow job is not a failure).
JOB_WAIT_S = 20.0
#: The suite runs the same examples every time; bench/fuzz_api.py draws new ones (NONHOLONOMIC_FUZZ_RANDOM=1).
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=os.environ.get("NONHOLONOMIC_FUZZ_RANDOM") != "1",
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.filter_too_much, HealthCheck.data_too_large])

NUMBERS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64),
    st.sampled_from([0.0, -0.0, 1.0, 0.5, 2.0, 1e-12, 1e12, 1.0000001e12, 1e13, 1e-13, 1e308, -1e308, 5e-324,
                     1.7976931348623157e308]),
    st.integers(min_value=-10**20, max_value=10**20),
)
WEIRD = st.one_of(st.none(), st.booleans(), st.text(max_size=6), st.lists(NUMBERS, max_size=4),
                  st.dictionaries(st.text(max_size=4), NUMBERS, max_size=2))
VEC3 = st.one_of(st.lists(NUMBERS, min_size=3, max_size=3), st.lists(NUMBERS, min_size=3, max_size=3),
                 st.lists(st.floats(-2, 2), min_size=3, max_size=3), WEIRD)


def _strict(text: str) -> Any:
    """JSON that may not hold NaN or infinity (Python's json would accept them)."""
    def refuse(token: str) -> None:
        raise ValueError(f"non-finite number {token} in a response")

    return json.loads(text, parse_constant=refuse)


def _assert_problem(r: Any) -> None:
    assert r.headers["content-type"] == PROBLEM, r.text
    problem = _strict(r.text)
    assert problem["status"] == r.status_code and problem["title"] and problem["detail"]
    if r.status_code == 422:
        assert problem["errors"] and all(e["field"] and e["reason"] for e in problem["errors"]), problem


@pytest.fixture(scope="module")
def catalog(fuzz_client) -> list[dict[str, Any]]:
    return fuzz_client.get("/v1/systems").json()["systems"]


@pytest.fixture(scope="module")
def fuzz_client():
    from fastapi.testclient import TestClient

    from schemas.settings import get_settings
    from service.main import create_app

    saved = dict(os.environ)
    os.environ.pop("REDIS_URL", None)
    os.environ.update({"NONHOLONOMIC_WARM_UP": "false", "NONHOLONOMIC_MAX_T_FINAL": "50",
                       "NONHOLONOMIC_MAX_SAMPLES": "2001", "NONHOLONOMIC_EMBEDDED_WORKERS": "2"})
    get_settings.cache_clear()
    try:
        with TestClient(create_app()) as client:
            yield client
    finally:
        os.environ.clear()
        os.environ.update(saved)
        get_settings.cache_clear()


def _paths(value: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every path to a key or list item in a JSON value."""
    found = [prefix] if prefix else []
    if isinstance(value, dict):
        for k, v in value.items():
            found += _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            found += _paths(v, prefix + (i,))
    return found


def _parent(body: Any, path: tuple[Any, ...]) -> Any:
    for step in path[:-1]:
        body = body[step]
    return body


@st.composite
def job_bodies(draw: st.DrawFn, systems: list[dict[str, Any]]) -> dict[str, Any]:
    """A catalog example, shortened, then spoiled 0 to 3 times (0: it runs)."""
    entry = draw(st.sampled_from(systems))
    body = json.loads(json.dumps(entry["example"]))
    body["t_final"] = draw(st.floats(0.01, 20.0))
    body["samples"] = draw(st.integers(2, 40))
    for _ in range(draw(st.sampled_from([0, 0, 1, 1, 2, 3]))):
        path = draw(st.sampled_from(_paths(body)))
        parent, leaf = _parent(body, path), path[-1]
        action = draw(st.sampled_from(["number", "weird", "scale", "delete", "extra"]))
        if action == "number":
            parent[leaf] = draw(NUMBERS)
        elif action == "weird":
            parent[leaf] = draw(WEIRD)
        elif action == "scale" and isinstance(parent[leaf], (int, float)) and not isinstance(parent[leaf], bool):
            scaled = parent[leaf] * draw(st.sampled_from([1e-13, 1e-6, -1.0, 1e6, 1e13, 1e300]))
            parent[leaf] = scaled if math.isfinite(scaled) else 1e308
        elif action == "delete":
            if isinstance(parent, dict):
                del parent[leaf]
            else:
                parent.pop(leaf)
        elif isinstance(parent, dict):
            parent[draw(st.text(max_size=5))] = draw(WEIRD)
    if draw(st.integers(0, 5)) == 0:
        body["checks"] = draw(st.lists(st.sampled_from(["integrals", "measure", "bracket", "euler_angles",
                                                        "isomorphisms", "nonsense"]), max_size=3))
    return body


def _finish(client: Any, location: str) -> dict[str, Any]:
    deadline = time.monotonic() + JOB_WAIT_S
    while time.monotonic() < deadline:
        r = client.get(location)
        assert r.status_code == 200, r.text
        view = _strict(r.text)
        if view["status"] in ("succeeded", "failed", "cancelled"):
            return view
        time.sleep(0.01)
    client.delete(location)  # slow (stiff extremes): stopped, not a failure
    return _strict(client.get(location).text)


def _submit_and_end(client: Any, body: dict[str, Any], seen: dict[int, int]) -> tuple[str | None, dict | None]:
    """POST the job: a 422 problem naming fields, or a 202 whose job ends cleanly (a failure with its
    reason); counts the status in ``seen``. Returns the location and the last view (None for a 422)."""
    r = client.post("/v1/jobs", content=json.dumps(body, allow_nan=False), headers={"content-type": "application/json"})
    seen[r.status_code] = seen.get(r.status_code, 0) + 1
    assert r.status_code in (202, 422), (r.status_code, r.text, body)
    if r.status_code == 422:
        _assert_problem(r)
        return None, None
    view = _finish(client, r.headers["location"])
    assert view["status"] in ("succeeded", "failed", "cancelled"), view
    if view["status"] == "failed":
        assert view["error"]["type"] and view["error"]["message"], view
    return r.headers["location"], view


def test_fuzzed_job_requests_never_give_a_500(fuzz_client, catalog):
    seen: dict[int, int] = {}

    @FUZZ
    @given(body=job_bodies(catalog))
    def check(body: dict[str, Any]) -> None:
        location, view = _submit_and_end(fuzz_client, body, seen)
        if view is not None and view["status"] == "succeeded":
            export = fuzz_client.get(f"{location}/trajectory?format=csv")
            assert export.status_code == 200 and "nan" not in export.text.lower()

    check()
    assert seen.get(202, 0) >= EXAMPLES // 10 and seen.get(422, 0) >= EXAMPLES // 10, seen  # both paths exercised


def _grammar(names: list[str]) -> st.SearchStrategy[str]:
    """Expressions in ``names``: mostly smooth, now and then abs, sign, cot, a huge literal, broken syntax."""
    atoms = st.one_of(st.sampled_from(names * 3 + ["1", "0.5", "2", "pi", "0"]),
                      st.sampled_from(["1e308", "10**400", "M1", "__class__", "'s'", "q**pi"]),
                      st.text(alphabet="q+-*/()^.e0123456789 ", min_size=1, max_size=8))
    functions = ["sin", "cos", "exp", "sqrt", "atan", "tanh"] * 3 + ["abs", "sign", "cot", "sec", "log", "eval"]
    return st.recursive(atoms, lambda inner: st.one_of(
        st.tuples(inner, st.sampled_from(["+", "-", "*"] * 3 + ["/", "**", "%"]), inner)
        .map(lambda t: f"({t[0]}){t[1]}({t[2]})"),
        st.tuples(st.sampled_from(functions), inner).map(lambda t: f"{t[0]}({t[1]})")), max_leaves=6)


@st.composite
def user_potential_bodies(draw: st.DrawFn, systems: list[dict[str, Any]]) -> dict[str, Any]:
    """A catalog example with a potential of the user's own (and now and then a claim), short."""
    entry = draw(st.sampled_from(systems))
    body = json.loads(json.dumps(entry["example"]))
    body.update(t_final=draw(st.floats(0.01, 2.0)), samples=draw(st.integers(2, 20)), checks=["integrals"])
    names = entry["potential_expression"]["variables"] + ["q"]
    parameters = draw(st.sampled_from([{"q": draw(st.floats(-2, 2))}] * 4 + [{"q": draw(NUMBERS)}, {}, {"D": 1.0}]))
    body["system"]["potential"] = {"kind": "expression", "U": draw(_grammar(names)), "parameters": parameters}
    if draw(st.booleans()):
        components = [c for v in entry["state"] for c in v["components"]]
        body["claims"] = [{"name": "claim", "expression": draw(_grammar(components))}]
    return body


def test_fuzzed_user_potentials_and_claims_never_give_a_500(fuzz_client, catalog):
    seen: dict[int, int] = {}

    @settings(FUZZ, max_examples=max(EXAMPLES // 3, 5))
    @given(body=user_potential_bodies(catalog))
    def check(body: dict[str, Any]) -> None:
        _submit_and_end(fuzz_client, body, seen)

    check()
    assert seen.get(202, 0) >= 1 and seen.get(422, 0) >= 1, seen  # both paths exercised


NAMES = ["x", "y", "z", "a", "b"]
#: Mostly well-formed pieces, and now and then one the parser must refuse.
ATOMS = st.one_of(st.sampled_from(NAMES * 3 + ["1", "2.5", "-3", "pi", "0"] * 2),
                  st.sampled_from(["E", "1e308", "10**400", "1e-400", "I", "x_1", "__class__", "lambda: 0", "[]",
                                   "'s'", "1j"]),
                  st.text(alphabet="xyzab+-*/()^.,e0123456789 _", min_size=1, max_size=12))
FUNCTIONS = ["sin", "cos", "tan", "exp", "log", "sqrt", "atan", "sinh"] * 3 + ["abs", "sign", "eval", "__import__",
                                                                            "open", "Abs"]
EXPRESSIONS = st.recursive(
    ATOMS,
    lambda inner: st.one_of(
        st.tuples(inner, st.sampled_from(["+", "-", "*", "/", "**"] * 4 + ["%", "//", "@", "<"]), inner)
        .map(lambda t: f"({t[0]}){t[1]}({t[2]})"),
        st.tuples(st.sampled_from(FUNCTIONS), inner).map(lambda t: f"{t[0]}({t[1]})")),
    max_leaves=8)


@st.composite
def bracket_bodies(draw: st.DrawFn) -> dict[str, Any]:
    n = draw(st.integers(1, 3))
    variables = draw(st.sampled_from([NAMES[:n]] * 4 + [[f"v{i}" for i in range(n)], ["x"] * n, ["1x"] * n]))
    rows = draw(st.sampled_from([n] * 6 + [n + 1]))
    body: dict[str, Any] = {"variables": variables,
                            "matrix": [[draw(EXPRESSIONS) for _ in range(n)] for _ in range(rows)],
                            "budget_s": draw(st.sampled_from([0.5, 1.0] * 4 + [1e-6]))}
    if draw(st.booleans()):
        body["casimirs"] = draw(st.dictionaries(st.text(min_size=1, max_size=4), EXPRESSIONS, max_size=2))
    if draw(st.booleans()):
        body["parameters"] = draw(st.dictionaries(st.sampled_from(["a", "b", "k"]), NUMBERS, max_size=2))
    return body


#: Functions of the coordinates x, y only (what a1, a2, b and U must be), mostly.
IN_COORDINATES = st.one_of(st.recursive(
    st.sampled_from(["x", "y", "1", "2", "0.5", "0"]),
    lambda inner: st.one_of(st.tuples(inner, st.sampled_from(["+", "-", "*"]), inner).map(lambda t: f"({t[0]}){t[1]}({t[2]})"),
                            st.tuples(st.sampled_from(["sin", "cos"]), inner).map(lambda t: f"{t[0]}({t[1]})")),
    max_leaves=4), st.sampled_from(["x", "y", "1", "2", "0.5", "0"]), st.sampled_from(["x", "y", "1", "2", "0.5", "0"]),
    EXPRESSIONS)


@st.composite
def hamiltonize_bodies(draw: st.DrawFn) -> dict[str, Any]:
    lagrangian = draw(st.sampled_from(["(a**2 + b**2)/2", "(a**2 + (2 + cos(x))*b**2)/2", "a*b + a**2"]))
    body: dict[str, Any] = {"coordinates": ["x", "y"], "velocities": ["a", "b"],
                            "lagrangian": draw(st.one_of(st.just(lagrangian), st.just(lagrangian), EXPRESSIONS)),
                            "a1": draw(IN_COORDINATES), "a2": draw(IN_COORDINATES), "b": draw(IN_COORDINATES),
                            "budget_s": draw(st.sampled_from([0.5, 1.0]))}
    if draw(st.booleans()):
        body["potential"] = draw(IN_COORDINATES)
    if draw(st.integers(0, 4)) == 0:
        body["monopole"] = {"domain": [[draw(EXPRESSIONS), draw(EXPRESSIONS)], ["0", "2*pi"]]}
    return body


@pytest.mark.parametrize("path,bodies", [("/v1/brackets/verify", bracket_bodies()),
                                         ("/v1/hamiltonize", hamiltonize_bodies())])
def test_fuzzed_symbolic_requests_never_give_a_500(fuzz_client, path, bodies):
    seen: dict[int, int] = {}

    @FUZZ
    @given(body=bodies)
    def check(body: dict[str, Any]) -> None:
        r = fuzz_client.post(path, content=json.dumps(body, allow_nan=False),
                             headers={"content-type": "application/json"})
        seen[r.status_code] = seen.get(r.status_code, 0) + 1
        assert r.status_code in (200, 408, 422), (r.status_code, r.text, body)
        if r.status_code == 200:
            _strict(r.text)
        else:
            _assert_problem(r)

    check()
    assert seen.get(422, 0) >= 1 and seen.get(200, 0) >= 1, seen
