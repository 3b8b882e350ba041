"""Branches of periodic orbits by pseudo-arclength continuation (:mod:`nonholonomic.analysis.periodic_orbit.branch`),
checked against independent computations: the located bifurcations' multipliers from a finite-difference
monodromy of scipy's DOP853 on the ball's equations written again in plain numpy (:mod:`tests.reference`), branch
points recomputed from scratch by scipy shooting (``least_squares`` on x(T) - x0 with the level), the energy by
its own formula. Chaplygin's ball in a linear field, I = (2, 3, 4.5), D = 0.7, a = (0.3, -0.2, a3), on
H = 2, (M, gamma) = 0, the section gamma3 = 0."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from nonholonomic.analysis.periodic_orbit import find_periodic_orbit
from nonholonomic.analysis.periodic_orbit.bifurcations import LOCATE_TOLERANCE, bifurcation_tests, crossings
from nonholonomic.analysis.periodic_orbit.branch import BranchError, BranchOptions, follow_branch
from tests.reference import ball_rhs
from tests.unit.test_periodic_orbits import BALL, ball, centre_orbit, on_section

EPS = float(np.finfo(float).eps)
A3 = 6  # the index of a3 in the ball's parameter vector (I1, I2, I3, D, a1, a2, a3)


def rhs(a3: float):
    return ball_rhs(np.array(BALL["inertia"]), BALL["D"], np.array([0.3, -0.2, a3]))


def flow(a3: float, x0: np.ndarray, t: float) -> np.ndarray:
    sol = solve_ivp(rhs(a3), (0.0, t), x0, method="DOP853", rtol=1e-12, atol=1e-12)
    assert sol.success
    return sol.y[:, -1]


def energy(a3: float, x: np.ndarray) -> float:
    """H = (M, omega) / 2 + (a, gamma), omega from I_Q omega = M (the paper's eq. for the ball, written again)."""
    M, g = x[:3], x[3:]
    IQ = np.diag(np.array(BALL["inertia"]) + BALL["D"]) - BALL["D"] * np.outer(g, g)
    return float(0.5 * M @ np.linalg.solve(IQ, M) + np.array([0.3, -0.2, a3]) @ g)


def section_trace(a3: float, x0: np.ndarray, t: float, h: float = 1e-6) -> float:
    """tr Phi(T) - 4 of the monodromy by central differences of DOP853 (4 trivial multipliers: the flow, H, the
    area, |gamma|)."""
    phi = np.empty((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        phi[:, j] = (flow(a3, x0 + e, t) - flow(a3, x0 - e, t)) / (2 * h)
    return float(np.trace(phi)) - 4.0


def shoot(a3: float, x0: np.ndarray, t: float, level_energy: float, area: float = 0.0) -> tuple[np.ndarray, float]:
    """The periodic orbit near (x0, T) on gamma3 = 0, H = level_energy, (M, gamma) = area, |gamma| = 1, by
    scipy's least_squares on the ball's equations written again (no heyoka, no variational equations)."""

    def residual(z: np.ndarray) -> np.ndarray:
        x, period = z[:6], z[6]
        return np.concatenate([flow(a3, x, period) - x,
                               [x[5], energy(a3, x) - level_energy, x[:3] @ x[3:] - area, x[3:] @ x[3:] - 1.0]])

    start = np.append(x0, t) + 1e-6 * np.array([1, -1, 1, 0, 0, 0, 1])
    fit = least_squares(residual, start, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert np.max(np.abs(fit.fun)) < 1e-10
    return fit.x[:6], float(fit.x[6])


@cache
def in_the_field():
    """The island's centre continued in a3 from 0.5 to 1.2, the period-2 branch followed from its doubling."""
    system, p = ball("linear")
    return follow_branch(system, p, centre_orbit(), BranchOptions("potential.a[2]", 1.2, parameter_index=A3,
                                                                  max_points=40, switch_points=14),
                         tolerance=EPS)


def test_the_period_doubling_in_the_field_is_located_where_the_independent_monodromy_has_a_multiplier_minus_one():
    branch = in_the_field()
    assert branch.status == "reached" and branch.points[-1].value == 1.2
    assert [b.kind for b in branch.bifurcations] == ["period_doubling"]
    pd = branch.bifurcations[0]
    assert pd.located and abs(pd.test_value) <= LOCATE_TOLERANCE
    assert pd.value == pytest.approx(0.85576535, abs=1e-7)  # between 0.85 and 0.9, where the sweep flagged it
    x0, t = pd.point.initial_state, pd.point.period_t
    assert np.max(np.abs(flow(pd.value, x0, t) - x0)) < 1e-9
    assert section_trace(pd.value, x0, t) == pytest.approx(-2.0, abs=1e-5)  # 2 + trace = P(-1) = 0
    # elliptic before it, hyperbolic after; every point closes and passes its checks
    before = [q for q in branch.points if q.value < pd.value]
    after = [q for q in branch.points if q.value > pd.value]
    assert {q.stability for q in before} == {"elliptic"} and {q.stability for q in after} == {"hyperbolic"}
    assert all(q.checks_passed for q in branch.points) and all(q.residual < 1e-9 for q in branch.points)
    checked = [q.residual_independent for q in branch.points if q.residual_independent is not None]
    assert len(checked) >= 2 and max(checked) < 1e-10


def test_the_period_two_branch_born_there_is_recomputed_by_independent_shooting():
    branch = in_the_field()
    assert len(branch.switched) == 1 and branch.bifurcations[0].switched == 0
    doubled = branch.switched[0]
    assert doubled.period == 2 and len(doubled.points) >= 10 and not doubled.warnings
    assert doubled.points[0].value == branch.bifurcations[0].value
    assert doubled.points[0].period_t == pytest.approx(2 * branch.bifurcations[0].point.period_t, rel=1e-12)
    level = energy(0.5, centre_orbit().initial_state)
    assert level == pytest.approx(2.0, abs=1e-9)  # the energy formula is the core's
    point = doubled.points[6]
    x, t = shoot(point.value, point.initial_state, point.period_t, level)
    assert np.max(np.abs(x - point.initial_state)) < 1e-8 and t == pytest.approx(point.period_t, abs=1e-8)
    assert np.max(np.abs(flow(point.value, x, t / 2) - x)) > 0.05  # a prime period-2 orbit, not the old one twice
    assert section_trace(point.value, x, t) == pytest.approx(point.trace, abs=1e-5)
    # born elliptic (trace 2 at the doubling: the old multiplier -1 squared), the resonances 1:4 and 1:3 on it
    assert doubled.points[0].trace == pytest.approx(2.0, abs=1e-7) and doubled.points[1].stability == "elliptic"
    kinds = {b.kind: b for b in doubled.bifurcations}
    assert kinds["resonance_1:4"].point.trace == pytest.approx(0.0, abs=1e-8)
    assert kinds["resonance_1:3"].point.trace == pytest.approx(-1.0, abs=1e-8)
    assert kinds["resonance_1:4"].value < kinds["resonance_1:3"].value


def test_the_family_in_energy_holds_the_area_and_loses_stability_in_a_period_doubling():
    system, p = ball("linear")
    branch = follow_branch(system, p, centre_orbit(), BranchOptions("energy", 0.7, max_points=40, switch=False),
                           tolerance=EPS)
    assert branch.status == "reached" and branch.points[-1].value == 0.7
    for q in branch.points[::5]:
        assert energy(0.5, q.initial_state) == pytest.approx(q.value, abs=1e-10)
        assert abs(q.initial_state[:3] @ q.initial_state[3:]) < 1e-10  # the area held at 0
    periods = [q.period_t for q in branch.points]
    assert np.all(np.diff(periods) > 0)  # lower energy, longer period
    [pd] = branch.bifurcations
    assert pd.kind == "period_doubling" and pd.located and pd.value == pytest.approx(0.72000494, abs=1e-7)
    x, t = shoot(0.5, pd.point.initial_state, pd.point.period_t, pd.value)
    assert t == pytest.approx(pd.point.period_t, abs=1e-8)
    assert section_trace(0.5, x, t) == pytest.approx(-2.0, abs=1e-5)


def test_the_period_two_branch_is_followed_around_its_fold_in_the_field():
    """The elliptic period-2 orbit at a3 = 2 meets a hyperbolic one at a3 = 2.0141: the branch turns back there
    (natural-parameter continuation would lose it) and comes back to a3 = 2 as a second, hyperbolic, orbit."""
    system, p = ball("linear", 2.0)
    start = find_periodic_orbit(system, p, on_section(system, p, -0.626, -1.891), "gamma3", period=2,
                                coordinates=("gamma1", "M3"), t_final=100.0)
    assert start.status == "found" and start.stability == "elliptic" and not start.warnings
    branch = follow_branch(system, p, start, BranchOptions("potential.a[2]", 2.1, parameter_index=A3, max_points=30),
                           tolerance=EPS)
    assert branch.status == "bound" and branch.points[-1].value == 2.0
    last = branch.points[-1]
    assert last.stability == "hyperbolic" and np.max(np.abs(last.initial_state - start.initial_state)) > 0.05
    [fold] = branch.bifurcations
    assert fold.kind == "fold" and fold.located and abs(fold.test_value) <= LOCATE_TOLERANCE
    assert fold.value == pytest.approx(2.0141094, abs=1e-6)
    assert max(q.value for q in branch.points) <= fold.value + 1e-9  # the value turns back at the fold
    assert section_trace(fold.value, fold.point.initial_state, fold.point.period_t) == pytest.approx(2.0, abs=1e-4)
    # the two orbits either side of the fold, both closed again by independent shooting, distinct
    i = fold.index
    a, b = branch.points[i], branch.points[i + 1]
    assert a.stability == "elliptic" and b.stability == "hyperbolic"
    level = energy(2.0, start.initial_state)
    for q in (a, b):
        x, t = shoot(q.value, q.initial_state, q.period_t, level)
        assert t == pytest.approx(q.period_t, abs=1e-8)
        assert (section_trace(q.value, x, t) - 2.0) * (q.trace - 2.0) > 0
    assert all(q.checks_passed for q in branch.points if q.stability == "elliptic")


def test_a_family_in_another_integral_moves_the_area_and_holds_the_energy():
    system, p = ball("linear")
    branch = follow_branch(system, p, centre_orbit(), BranchOptions("area", 0.5, max_points=20), tolerance=EPS)
    assert branch.status == "reached" and len(branch.points) >= 4
    for q in branch.points:
        x = q.initial_state
        assert x[:3] @ x[3:] == pytest.approx(q.value, abs=1e-12) and energy(0.5, x) == pytest.approx(2.0, abs=1e-12)
        assert q.checks_passed
    last = branch.points[-1]
    x, t = shoot(0.5, last.initial_state, last.period_t, 2.0, area=last.value)
    assert t == pytest.approx(last.period_t, abs=1e-8)


def test_a_branch_to_its_own_start_is_that_one_orbit():
    system, p = ball("linear")
    start = centre_orbit()
    branch = follow_branch(system, p, start, BranchOptions("energy", start.level["energy"]), tolerance=EPS)
    assert branch.status == "reached" and len(branch.points) == 1 and "already" in branch.reason
    assert np.max(np.abs(branch.points[0].initial_state - start.initial_state)) < 1e-12


@pytest.mark.parametrize(("options", "field"), [
    (BranchOptions("energy", 3.0, max_points=1), "max_points"),
    (BranchOptions("energy", 3.0, step=1.0, max_step=0.5), "step"),
    (BranchOptions("energy", 3.0, max_multiplier=1.0), "max_multiplier"),
    (BranchOptions("momentum", 3.0), "in"),
])
def test_refused_branch_options_are_named(options, field):
    system, p = ball("linear")
    with pytest.raises(BranchError) as err:
        follow_branch(system, p, centre_orbit(), options, tolerance=EPS)
    assert err.value.field == field


def _monodromy(section: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A monodromy with 4 trivial multipliers (1) and the given section block; its section multipliers."""
    k = len(section)
    phi = np.eye(4 + k)
    phi[4:, 4:] = section
    return phi, np.linalg.eigvals(section)


def _rotation(theta: float, r: float = 1.0) -> np.ndarray:
    return r * np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])


def _tests(section: np.ndarray, t_lambda: float = 1.0, measure: bool = True):
    phi, mu = _monodromy(section)
    return bifurcation_tests(t_lambda, phi, 4, mu, measure)


def test_the_test_functions_change_sign_at_their_bifurcations_only():
    """Each test function against the multipliers it stands for: P(+-1) = 1 -+ tr + det of the section block,
    the resonances at trace -1 and 0, Neimark-Sacker at |mu| = 1 of a complex pair, Krein by the count."""
    ell = _tests(_rotation(2.0))
    assert ell.plus_one == pytest.approx(2 - 2 * np.cos(2.0)) and ell.minus_one == pytest.approx(2 + 2 * np.cos(2.0))
    hyper = np.diag([-1.2, -1 / 1.2])
    assert [c.kind for c in crossings(_tests(_rotation(2.9)), _tests(hyper))] == ["period_doubling"]
    # through +1 with the branch turning back: a fold; without the turn: a tangent bifurcation
    saddle = np.diag([1.3, 1 / 1.3])
    assert [c.kind for c in crossings(_tests(_rotation(0.1)), _tests(saddle, -1.0))] == ["fold"]
    assert [c.kind for c in crossings(_tests(_rotation(0.1)), _tests(saddle))] == ["tangent"]
    # the elliptic angle through 2 pi / 3 (trace -1) and pi / 2 (trace 0)
    kinds = [c.kind for c in crossings(_tests(_rotation(1.5)), _tests(_rotation(2.2)))]
    assert kinds == ["resonance_1:3", "resonance_1:4"]
    assert crossings(_tests(_rotation(1.5)), _tests(_rotation(1.52))) == []
    # a map that does not preserve a measure: a complex pair leaving the unit circle
    assert [c.kind for c in crossings(_tests(_rotation(1.0, 0.99), measure=False),
                                      _tests(_rotation(1.0, 1.01), measure=False))] == ["neimark_sacker"]
    # a four-dimensional section map: two pairs collide on the circle and leave it (Krein)
    on = np.zeros((4, 4))
    on[:2, :2], on[2:, 2:] = _rotation(1.0), _rotation(1.2)
    off = np.zeros((4, 4))
    off[:2, :2], off[2:, 2:] = _rotation(1.1, 1.05), _rotation(1.1, 1 / 1.05)
    [krein] = crossings(_tests(on), _tests(off))
    assert krein.kind == "krein_collision" and not krein.smooth
