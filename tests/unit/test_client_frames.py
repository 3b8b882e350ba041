"""The client's tables and arrays on the edge cases a live server rarely gives: a section without
crossings, a spectrum asked for fewer exponents than the state has, an ensemble whose chunks are not
all done (pages with gaps), no member done yet, a parameter named like a component."""

from __future__ import annotations

import io
import json

import httpx
import numpy as np
import pytest

from nonholonomic_client import Client, frames

pytest.importorskip("pandas")
pytest.importorskip("xarray")

UNITS = {"t": "s", "tau": "s", "M": "kg m^2/s", "gamma": "1"}


def test_a_section_without_crossings_is_an_empty_table():
    empty = {"count": 0, "t": [], "tau": [], "points": {"M": [], "gamma": []}}
    frame = frames.section_frame([(None, empty)], UNITS, {})
    assert len(frame) == 0 and list(frame.columns) == ["t", "tau"]
    npz = {"member": np.zeros(0, dtype=np.int64), "t": np.zeros(0), "tau": np.zeros(0), "M": np.zeros((0, 3)),
           "units_json": np.array(json.dumps(UNITS)), "request_json": np.array("{}")}
    frame = frames.section_npz_frame(npz, {})
    assert len(frame) == 0 and list(frame.columns) == ["member", "t", "tau", "M1", "M2", "M3"]


def test_a_spectrum_of_fewer_exponents_than_the_state_has():
    lyapunov = {"exponents": [0.05, 0.01], "all_exponents": [0.05, 0.01, 0.0, -0.01, -0.02, -0.05],
                "moved_last_20pct": [0.004, 0.002], "zero_indices": [2, 3], "sum": -0.02, "convergence": [],
                "convergence_t": []}
    table = frames.exponents_frame(lyapunov)
    assert list(table["exponent"]) == lyapunov["all_exponents"]
    np.testing.assert_array_equal(table["moved_last_20pct"].to_numpy()[:2], [0.004, 0.002])
    assert np.isnan(table["moved_last_20pct"].to_numpy()[2:]).all()
    assert list(table["expected_zero"]) == [False, False, True, True, False, False]
    assert frames.convergence_frame(lyapunov).shape == (0, 2)


def test_a_parameter_named_like_a_component_does_not_lend_its_unit():
    trajectory = {"units": {"t": "s", "q": "rad", "q1": "as L needs"}, "t": [0.0, 1.0], "q": [[0.1, 0.2], [0.3, 0.4]]}
    ds = frames.trajectory_dataset(trajectory, {"id": "j", "request": {}, "result": {}})
    assert ds["q1"].attrs["units"] == "rad" and ds["q2"].attrs["units"] == "rad"


def test_a_systems_own_coordinates_name_its_columns():
    """A result naming its components (``system.components``: a Lagrangian system's x, theta, x_dot ...) names the
    dataset's variables, the frame's columns and a section NPZ's columns; units and long names follow the vector."""
    names = {"q": ["x", "theta"], "q_dot": ["x_dot", "theta_dot"]}
    trajectory = {"units": {"t": "s", "q": "m", "q_dot": "m/s", "x": "kg"}, "t": [0.0, 1.0],
                  "q": [[0.1, 0.2], [0.3, 0.4]], "q_dot": [[1.0, 2.0], [3.0, 4.0]]}
    view = {"id": "j", "request": {}, "result": {"system": {"components": names}}}
    ds = frames.trajectory_dataset(trajectory, view)
    assert set(ds.data_vars) == {"x", "theta", "x_dot", "theta_dot"}
    assert ds["x"].attrs["units"] == "m" and ds["theta_dot"].attrs["units"] == "m/s"  # the vector's, not x's
    assert ds["theta_dot"].attrs["long_name"] == "theta_dot: component 2 of q_dot"
    np.testing.assert_array_equal(ds["theta"].values, [0.2, 0.4])
    assert list(frames.trajectory_frame(trajectory, view).columns) == ["x", "theta", "x_dot", "theta_dot"]
    npz = {"t": np.array([0.5]), "q": np.array([[0.1, 0.2]]), "q_dot": np.array([[1.0, 2.0]]),
           "units_json": np.array(json.dumps(trajectory["units"])), "components_json": np.array(json.dumps(names))}
    assert list(frames.section_npz_frame(npz, {}).columns) == ["t", "x", "theta", "x_dot", "theta_dot"]


def _ensemble_server(total: int, undone: range, page_limit: int = 1000) -> httpx.MockTransport:
    """The members route as the service answers it: indices offset .. offset + limit - 1 of finished chunks."""
    def handler(request: httpx.Request) -> httpx.Response:
        offset, limit = int(request.url.params["offset"]), int(request.url.params["limit"])
        assert limit <= page_limit
        members = [{"index": i, "status": "succeeded", "t_final": 1.0, "lyapunov": {"exponents": [0.1 * i]}}
                   for i in range(offset, min(offset + limit, total)) if i not in undone]
        return httpx.Response(200, json={"offset": offset, "limit": limit, "total": total, "members": members})
    return httpx.MockTransport(handler)


@pytest.mark.parametrize(("undone", "expected"), [(range(500, 1000), 2000), (range(0, 1000), 1500), (range(0), 2500)])
def test_every_member_is_read_once_whatever_chunks_are_done(undone, expected):
    with Client("http://api.test", transport=_ensemble_server(2500, undone)) as api:
        table = api.members("e", format="pandas")
    assert len(table) == expected and table.index.is_unique
    assert not set(table.index) & set(undone)
    with Client("http://api.test", transport=_ensemble_server(2500, undone)) as api:
        some = api.members("e", offset=900, limit=200, format="pandas")
    assert set(some.index) == set(range(900, 1100)) - set(undone)


def test_no_member_done_yet_is_an_empty_table_with_its_columns():
    with Client("http://api.test", transport=_ensemble_server(10, range(0, 10))) as api:
        exponents = api.exponents("e", of="ensemble")
    assert len(exponents) == 0 and list(exponents.columns) == ["status"]


def test_an_ensembles_section_table_from_its_npz():
    buffer = io.BytesIO()
    np.savez(buffer, member=np.array([0, 0, 2]), t=np.array([1.0, 2.0, 1.5]), tau=np.array([0.1, 0.2, 0.15]),
             M=np.arange(9.0).reshape(3, 3), units_json=np.array(json.dumps(UNITS)), request_json=np.array("{}"))
    answer = httpx.MockTransport(lambda request: httpx.Response(200, content=buffer.getvalue()))
    with Client("http://api.test", transport=answer) as api:
        frame = api.section("e", format="pandas", of="ensemble")
    assert list(frame["member"]) == [0, 0, 2] and list(frame["M2"]) == [1.0, 4.0, 7.0]
    assert frame.attrs["units"]["M"] == "kg m^2/s"
