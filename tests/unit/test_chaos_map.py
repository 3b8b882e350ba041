"""Chaos maps' core: the grid's cells completed to states on the level (:mod:`nonholonomic.analysis.chaos_map.grid`)
and the indicators from one integration of the tangent flow (:mod:`nonholonomic.analysis.chaos_map.indicators`),
checked against independent computations."""

from __future__ import annotations

import copy
from functools import cache

import heyoka as hy
import numpy as np
import pytest

from nonholonomic.analysis.chaos_map import (
    CHECK_FRACTION,
    MapOptions,
    cell_digest,
    checked_cells,
    indicators,
    map_summary,
    run_cells,
)
from nonholonomic.analysis.chaos_map.grid import Grid, GridError, complete, default_ranges, plan
from nonholonomic.analysis.ensemble import Member
from nonholonomic.numerics.kernels import numeric, parameter_vector
from nonholonomic.systems import get_system
from tests.unit.test_sampling import assert_on_level

BALL = {"inertia": [2.0, 3.0, 4.5], "D": 0.7}
FIELD = {"a": [0.3, -0.2, 0.5]}
LEVEL = {"energy": 2.0, "area": 0.0}
GRID = Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, (12, 10))


@cache
def ball(potential: str):
    system = get_system("chaplygin_ball", potential)
    return system, parameter_vector(system, {**BALL, **(FIELD if potential == "linear" else {})})


@pytest.mark.parametrize("potential", ["zero", "linear"])
@pytest.mark.parametrize("direction", ["increasing", "decreasing"])
def test_cells_are_states_on_the_level_on_the_section_crossing_it_the_asked_way(potential, direction):
    system, p = ball(potential)
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, (12, 10), direction=direction)
    ranges = default_ranges(system, p, grid)
    cells = complete(system, p, grid, ranges)
    inside = cells.inside
    assert 0.6 < inside.mean() <= 1.0
    X = cells.states[inside]
    assert_on_level(system, p, X, LEVEL)  # |gamma| = 1, H = 2, (M, gamma) = 0 to 1e-12
    assert np.all(X[:, 5] == 0.0)  # on the section gamma3 = 0
    u = ranges[0][0] + (np.arange(12) + 0.5) * (ranges[0][1] - ranges[0][0]) / 12
    v = ranges[1][0] + (np.arange(10) + 0.5) * (ranges[1][1] - ranges[1][0]) / 10
    k = np.flatnonzero(inside)
    assert np.array_equal(X[:, 3], u[k // 10]) and np.array_equal(X[:, 2], v[k % 10])
    rate = numeric(system).rhs(X, p)[:, 5]  # d gamma3 / dt = (gamma x omega)_3
    assert np.all(rate > 0) if direction == "increasing" else np.all(rate < 0)
    # U = 0: both sheets gamma2 = ±sqrt(1 - gamma1^2) cross the same way (2 branches); the field breaks the
    # symmetry: some cells have one. Of two, gamma2 >= 0 is taken.
    two = cells.branches[inside] == 2
    assert np.all(two) if potential == "zero" else 0.5 < two.mean() < 1.0
    assert np.all(cells.branches[inside] >= 1) and np.all(X[two, 4] >= 0)
    assert np.all(np.isnan(cells.states[~inside]))


def test_the_default_ranges_are_the_levels_extent():
    system, p = ball("zero")
    (g_lo, g_hi), (m_lo, m_hi) = default_ranges(system, p, GRID)
    assert -1.05 < g_lo < -1.0 and 1.0 < g_hi < 1.05  # gamma1 spans [-1, 1], widened by 2 %
    # the largest |M3| on the level: H = (M, omega)/2 with omega = (A M + D (gamma, ...)) ... is reached with
    # M along e3 (gamma3 = 0 makes the D term vanish): M3^2 / (2 (I3 + D)) = H
    top = np.sqrt(2 * LEVEL["energy"] * (BALL["inertia"][2] + BALL["D"]))
    assert m_hi == pytest.approx(top * 1.04, rel=0.03) and m_lo == pytest.approx(-top * 1.04, rel=0.03)
    outer = complete(system, p, Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, (1, 1)), ((1.01, 1.02), (0.0, 0.1)))
    assert outer.branches[0] == 0  # |gamma1| > 1: no state


@pytest.mark.parametrize("grid, field, words", [
    (Grid("gamma4", 0.0, ("gamma1", "M3"), LEVEL, (2, 2)), "surface", "not a state component"),
    (Grid("gamma3", 0.0, ("gamma3", "M3"), LEVEL, (2, 2)), "coordinates", "three different components"),
    (Grid("M3", 0.0, ("M1", "M2"), LEVEL, (2, 2)), "coordinates", "3 free components"),
    (Grid("gamma3", 0.0, ("gamma1", "M3"), {"area": 0.0}, (2, 2)), "level.energy", "required"),
    (Grid("gamma3", 0.0, ("gamma1", "gamma2"), {"energy": 2.0}, (2, 2)), "coordinates",
     "one velocity direction more than relations"),
    (Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, (2, 2), sheet="M1 +* 2"), "sheet", "invalid syntax (at position"),
])
def test_a_grid_that_does_not_fix_a_state_is_refused_naming_the_field(grid, field, words):
    system, _ = ball("zero")
    with pytest.raises(GridError) as err:
        plan(system, grid)
    assert err.value.field == field and words in err.value.reason


def test_a_quadratic_level_with_too_many_velocity_directions_is_refused():
    system = get_system("ball_on_quadric", "zero")
    with pytest.raises(GridError) as err:
        plan(system, Grid("x2", 0.0, ("x3", "x1"), {"energy": 0.5, "K": 2.0}, (2, 2)))
    assert err.value.field == "coordinates" and "3 free components and 1 relations" in err.value.reason


def _cells(potential: str, shape=(6, 6)):
    system, p = ball(potential)
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, shape)
    cells = complete(system, p, grid, default_ranges(system, p, grid))
    return system, p, cells.states[cells.inside]


def test_the_integrable_ball_is_regular_everywhere_and_its_integrals_hold():
    """U = 0: Chaplygin's ball is integrable (eq. 2604-4): <Y> -> 2 (at most ~2.2 at T = 300), the FLI
    grows like ln T, the finite-time exponent is ~ ln T / T."""
    system, p, X = _cells("zero")
    found = indicators.run_batch(system, np.repeat(p[None], len(X), 0), X, 300.0)
    megno = np.array([f.megno for f in found])
    fli = np.array([f.fli for f in found])
    assert np.all(megno < 2.5) and np.median(megno) == pytest.approx(2.0, abs=0.5)
    assert np.all(fli < np.log(300.0) + 3.0)
    assert max(max(f.integral_drift.values()) for f in found) < 1e-12
    assert [f.integral_drift.keys() for f in found][0] == {"energy", "geometric", "area", "F"}


def test_in_the_linear_field_megno_grows_like_half_the_exponent_times_t_and_matches_the_monodromy():
    """Chaotic cells: <Y> ~ lambda T / 2 (Cincotta & Simo 2000). The finite-time exponent ln|w(T)|/T equals
    ln|Phi(T) w(0)|/T with Phi the whole tangent matrix of hy.var_ode_sys (other equations, integrated apart)
    to 1e-8 at T = 100, before the roundoff amplified by e^(lambda T) moves the orbit itself."""
    from nonholonomic.analysis.lyapunov.variational import initial_frame, variational_template

    system, p, X = _cells("linear", (8, 8))
    T = 100.0
    found = indicators.run_batch(system, np.repeat(p[None], len(X), 0), X, T)
    lam = np.array([f.lyapunov for f in found])
    megno = np.array([f.megno for f in found])
    chaotic = np.flatnonzero(megno > 4)
    assert len(chaotic) >= 4
    ratio = megno[chaotic] / (lam[chaotic] * T / 2)
    assert np.all((ratio > 0.5) & (ratio < 1.5)), ratio
    n = system.dimension
    w0 = initial_frame(n)[:, 0]
    from nonholonomic.numerics.taylor import taylor_system

    for k in list(chaotic[:3]) + list(np.flatnonzero(megno < 2.5)[:2]):
        ta = variational_template(system, indicators.MACHINE_EPSILON)
        ta = copy.deepcopy(ta)
        ta.time = 0.0
        ta.pars[:] = taylor_system(system).runtime_parameters(p)[: len(ta.pars)]
        ta.state[:n] = X[k]
        ta.state[n: n + n * n] = np.eye(n).reshape(-1)
        ta.state[-1] = 0.0
        ta.propagate_until(T)
        phi = ta.state[n: n + n * n].reshape(n, n)
        assert lam[k] == pytest.approx(np.log(np.linalg.norm(phi @ w0)) / T, rel=1e-8)


def test_megno_is_the_mean_of_y_computed_from_the_logarithm_of_the_growth():
    """z (the ODE's <Y>) against the definition applied to l(t) = ln|w(t)| read on a fine grid:
    Y(t) = (2/t) int_0^t s dl, <Y>(T) = (1/T) int_0^T Y dt, by the trapezoidal rule (1e-4)."""
    system, p, X = _cells("linear", (4, 4))
    x0 = X[len(X) // 2]
    T = 60.0
    eqs = list(indicators.indicator_equations(system))
    from nonholonomic.numerics.taylor import taylor_system

    ts = taylor_system(system)
    n = system.dimension
    y0 = np.concatenate([x0, indicators.initial_frame(n)[:, 0], [0.0, 0.0, 0.0]])
    t0 = indicators.START_FRACTION * T
    ta = hy.taylor_adaptive(eqs, y0, pars=np.append(ts.runtime_parameters(p), T), time=t0)
    grid = t0 + np.linspace(0.0, T, 60001)
    out = ta.propagate_grid(grid)[-1]
    ell = out[:, 2 * n] * T
    t = grid - t0
    ds = np.diff(ell)
    y = np.concatenate([[0.0], np.cumsum(0.5 * (t[1:] + t[:-1]) * ds)])
    Y = np.where(t > 0, 2 * y / np.where(t > 0, t, 1), 0.0)
    mean = np.trapezoid(Y, t) / T
    assert out[-1, 2 * n + 2] == pytest.approx(mean, rel=1e-4)
    # the tangent vector keeps |w| = 1 (its growth is in l)
    assert np.max(np.abs(np.linalg.norm(out[:, n:2 * n], axis=1) - 1.0)) < 1e-12


def test_cells_are_classified_and_a_sample_is_recomputed_independently():
    system, p = ball("linear")
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, (10, 10))
    cells = complete(system, p, grid, default_ranges(system, p, grid))
    members = [Member(k, p, cells.states[k], {"cell": [k // 10, k % 10]}) for k in range(100)]
    thresholds = indicators.default_thresholds(150.0)
    options = MapOptions(("megno", "fli"), thresholds, 100)
    results = run_cells(system, members, 150.0, options)
    statuses = [r.status for r in results]
    assert statuses.count("outside") == int((~cells.inside).sum())
    for r in results:
        if r.status in ("regular", "chaotic"):
            assert (r.values["megno"] > thresholds["megno"]) == (r.status == "chaotic")
    assert checked_cells(100) == checked_cells(100) and len(checked_cells(100)) == max(1, round(CHECK_FRACTION * 100))
    summary = map_summary([cell_digest(r) for r in results], ["megno", "fli"], thresholds)
    assert summary["cells"] == 100 and summary["chaotic"] == statuses.count("chaotic")
    assert summary["chaotic_fraction"] == pytest.approx(statuses.count("chaotic") / (100 - statuses.count("outside")))
    assert 0.1 < summary["chaotic_fraction"] < 0.9
    # a cell whose integral drifted past the job's tolerance counts as a member with a failed check
    from dataclasses import replace

    from nonholonomic.analysis.ensemble import summarize

    integrated = next(r for r in results if r.values)
    digests = [cell_digest(integrated), cell_digest(replace(integrated, drift_failed=("energy",)))]
    assert summarize(digests)["members_with_failed_checks"] == 1 and digests[1]["checks_failed"] == ["energy"]
    checked = [r for r in results if r.check is not None]
    assert len(checked) == len([k for k in checked_cells(100) if cells.inside[k]])


def test_a_level_with_a_quadratic_integral_cells_meet_both_conics_and_the_sheet():
    """The Jacobi problem on (H, K) = (0.5, 2) (eqs. 2804-2, 2804-4): K is quadratic in omega, so each cell's
    omega is a common point of two conics. A cell on study 1's symmetric line equals the state built by
    bench/science_geometry.jacobi_state (w + a n with |w| from K, a from H: other formulas) to 1e-12; the
    sheet a = (omega, n) > 0 halves the branches."""
    import importlib.util
    import math
    import sys
    from pathlib import Path

    bench = Path(__file__).resolve().parents[2] / "bench"
    path = bench / "science_geometry.py"
    sys.path.insert(0, str(bench))  # it imports science_config
    spec = importlib.util.spec_from_file_location("science_geometry_for_maps", path)
    geometry = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = geometry
    try:
        spec.loader.exec_module(geometry)
    finally:
        sys.path.remove(str(bench))

    jacobi = {"kind": "ball_on_quadric", "D0": 0.036, "m": 1.0, "R": 0.3, "B": [1.0, 2.0, 3.0]}
    system = get_system("ball_on_quadric", "zero")
    p = parameter_vector(system, {k: v for k, v in jacobi.items() if k != "kind"})
    level = {"energy": 0.5, "K": 2.0}
    sheet = "x1*omega1 + x3*omega3/3"
    both = complete(system, p, Grid("x2", 0.0, ("x3", "omega2"), level, (16, 16)), ((-1.7, 1.7), (-4.0, 4.0)))
    one = complete(system, p, Grid("x2", 0.0, ("x3", "omega2"), level, (16, 16), sheet=sheet),
                   ((-1.7, 1.7), (-4.0, 4.0)))
    assert set(np.unique(both.branches)) <= {0, 4} and np.array_equal(one.branches, both.branches // 2)
    X = one.states[one.inside]
    assert len(X) > 50
    assert_on_level(system, p, X, level)
    n = X[:, :3] / np.array([1.0, 2.0, 3.0])
    assert np.all(np.sum(X[:, 3:] * n, axis=1) > 0) and np.all(X[:, 0] >= 0)  # a > 0, and x1 >= 0 first
    for theta in (-0.33591693492, 0.3, -0.9):
        x3 = math.sqrt(3.0) * math.sin(theta)
        cell = complete(system, p, Grid("x2", 0.0, ("x3", "omega2"), level, (1, 1), sheet=sheet),
                        ((x3 - 1e-3, x3 + 1e-3), (-1e-3, 1e-3)))
        expected = geometry.jacobi_state(theta, 0.0, 0.5, 2.0, jacobi)
        assert cell.branches[0] == 2
        assert np.allclose(cell.states[0], expected["x"] + expected["omega"], rtol=0, atol=1e-12)
