"""Periodic orbits of the section map (:mod:`nonholonomic.analysis.periodic_orbit`) and their continuation
(:mod:`nonholonomic.analysis.periodic_orbit.continuation`), checked against independent computations: the
closing error by a second integrator, the multipliers by a finite-difference Jacobian of the return
map (events only, no variational equations), Liouville's det Φ = ρ(x₀)/ρ(x(T))."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from nonholonomic.analysis.chaos_map.grid import Grid, complete
from nonholonomic.analysis.periodic_orbit import PeriodicOrbitError, find_periodic_orbit
from nonholonomic.analysis.periodic_orbit.continuation import characteristic_signs, continue_orbit
from nonholonomic.analysis.poincare import section
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import numeric, parameter_vector
from nonholonomic.systems import get_system

BALL = {"inertia": [2.0, 3.0, 4.5], "D": 0.7}
FIELD = {"a": [0.3, -0.2, 0.5]}
LEVEL = {"energy": 2.0, "area": 0.0}


@cache
def ball(potential: str, a3: float = 0.5):
    system = get_system("chaplygin_ball", potential)
    extra = {"a": [0.3, -0.2, a3]} if potential == "linear" else {}
    return system, parameter_vector(system, {**BALL, **extra})


def on_section(system, p, gamma1: float, m3: float) -> np.ndarray:
    """The state on H = 2, (M, γ) = 0, γ3 = 0 (crossing upwards, γ2 ≥ 0) at (γ1, M3): a 1 × 1 grid."""
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, (1, 1))
    cells = complete(system, p, grid, ((gamma1 - 1e-3, gamma1 + 1e-3), (m3 - 1e-3, m3 + 1e-3)))
    assert cells.branches[0] >= 1
    return cells.states[0]


def return_map(system, p, z: np.ndarray, horizon: float) -> np.ndarray:
    """(γ1, M3) of the first return to γ3 = 0 from the chart point z, by heyoka's events alone."""
    sec = section(system, p, on_section(system, p, *z), horizon, "gamma3", max_points=3,
                  coordinates=("gamma1", "M3"))
    return sec.coordinates[sec.t > 1e-6][0]


def finite_difference_multipliers(system, p, z: np.ndarray, horizon: float, h: float = 1e-6) -> np.ndarray:
    jac = np.empty((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        jac[:, j] = (return_map(system, p, z + e, horizon) - return_map(system, p, z - e, horizon)) / (2 * h)
    return np.linalg.eigvals(jac)


def assert_checks_pass(orbit) -> None:
    failed = [(c.name, c.value, c.tolerance) for c in orbit.checks if c.passed is False]
    assert not failed, failed


@cache
def centre_orbit():
    system, p = ball("linear")
    return find_periodic_orbit(system, p, on_section(system, p, -0.2, 0.0), "gamma3",
                               coordinates=("gamma1", "M3"), t_final=100.0)


def test_the_island_centre_closes_under_a_second_integrator_with_its_multipliers_checked():
    system, p = ball("linear")
    orbit = centre_orbit()
    assert orbit.status == "found", orbit.reason
    assert_checks_pass(orbit)
    x, T = orbit.initial_state, orbit.period_t
    # an independent integration (DOP853) returns to x0 at T, to 1e-11 of the state's size
    other = integrate(system, p, x, T, 2, engine="scipy", tolerance=1e-13).states[-1]
    assert np.max(np.abs(other - x)) < 1e-11 * np.max(np.abs(x))
    assert orbit.coordinates == pytest.approx((-0.15642933, 0.13491925), abs=1e-7)  # Newton by FD (session notes)
    assert T == pytest.approx(5.1598, abs=1e-4)
    # 1 for the flow + energy, |gamma|^2, area: 4 trivial multipliers; the section map's two on the unit circle
    assert orbit.trivial_count == 4 and len(orbit.section_multipliers) == 2
    assert np.all(np.abs(np.abs(orbit.multipliers[orbit.trivial_count:]) - 1) < 1e-9)
    assert np.abs(np.prod(orbit.multipliers) - 1) < 1e-9  # det Phi = rho(x0)/rho(x(T)) = 1
    assert orbit.stability == "elliptic" and orbit.trace == pytest.approx(-1.637288, abs=1e-5)
    # the same multipliers from the return map differentiated by finite differences (events only)
    fd = finite_difference_multipliers(system, p, np.array(orbit.coordinates), 3 * T)
    assert np.sort_complex(fd) == pytest.approx(np.sort_complex(orbit.section_multipliers), abs=2e-6)
    # the reduced time over one period: the integral of rho dt from heyoka's own integration
    assert orbit.period_tau == pytest.approx(integrate(system, p, x, T, 2).tau[-1], rel=1e-12)
    assert orbit.method == "newton" and orbit.iterations[-1] < 1e-13


def test_a_hyperbolic_orbit_is_found_after_newton_wanders_and_its_multipliers_match_finite_differences():
    system, p = ball("linear")
    seed = on_section(system, p, -0.86660837, 2.57149011)  # a cell of a 6 x 6 grid whose orbit Newton cannot
    orbit = find_periodic_orbit(system, p, seed, "gamma3", coordinates=("gamma1", "M3"), t_final=100.0)
    assert orbit.status == "found", orbit.reason
    assert orbit.method == "newton, then levenberg-marquardt" and orbit.wandered
    assert_checks_pass(orbit)
    lam = orbit.section_multipliers
    assert orbit.stability == "hyperbolic" and np.all(np.abs(lam.imag) == 0)
    assert lam.real[0] == pytest.approx(10.5253, abs=1e-3) and lam.real[0] * lam.real[1] == pytest.approx(1, abs=1e-8)
    fd = finite_difference_multipliers(system, p, np.array(orbit.coordinates), 3 * orbit.period_t)
    assert np.sort(fd.real) == pytest.approx(np.sort(lam.real), abs=1e-5)  # FD: h = 1e-6, central


def test_period_two_finds_a_prime_period_two_orbit_and_says_when_it_is_the_period_one_orbit_twice():
    system, p = ball("linear")
    twice = find_periodic_orbit(system, p, on_section(system, p, -0.2, 0.0), "gamma3", period=2, t_final=100.0)
    assert twice.status == "found" and "prime period is 1" in " ".join(twice.warnings)
    assert twice.period_t == pytest.approx(2 * centre_orbit().period_t, rel=1e-10)
    # the section multipliers of the 2nd return map are those of the 1st, squared
    assert np.sort_complex(twice.section_multipliers) == pytest.approx(
        np.sort_complex(centre_orbit().section_multipliers ** 2), abs=1e-8)
    prime = find_periodic_orbit(system, p, on_section(system, p, -0.86660837, -4.29619123), "gamma3", period=2,
                                t_final=100.0)
    assert prime.status == "found" and not prime.warnings
    assert_checks_pass(prime)
    assert prime.period_t == pytest.approx(7.132003, abs=1e-5) and len(prime.crossing_times) == 2
    # its two crossings are distinct points of the section: a 2-cycle of the return map
    sec = section(system, p, prime.initial_state, prime.period_t * 1.0001, "gamma3", max_points=4)
    states = np.concatenate([sec.points["M"], sec.points["gamma"]], axis=1)[sec.t > 1e-6]
    assert np.max(np.abs(states[0] - prime.initial_state)) > 0.1
    assert np.max(np.abs(states[1] - prime.initial_state)) < 1e-9


def test_a_resonant_torus_of_the_integrable_ball_is_recognized_as_degenerate():
    """U = 0: the ball is integrable (F = (M, M) besides H and the area); on the torus of rotation number 1/3
    every orbit has period 3: the closing equations are rank-deficient, and the family keeps F."""
    system, p = ball("zero")
    orbit = find_periodic_orbit(system, p, on_section(system, p, 0.5, 0.5), "gamma3", period=3, t_final=100.0)
    assert orbit.status == "degenerate", orbit.reason
    assert orbit.family_dimension == 1 and orbit.singular_ratio < 1e-12
    assert "keeps F constant" in orbit.reason and "resonant torus" in orbit.reason
    assert_checks_pass(orbit)
    assert orbit.trivial_count == 5 and orbit.stability == "parabolic"  # F is a fifth trivial multiplier
    assert np.all(np.abs(orbit.multipliers - 1) < 1e-5)
    # a neighbour on the same torus (same F) is periodic with the same period: integrate it independently
    x = orbit.initial_state
    k = numeric(system)
    sec = section(system, p, x, 3.5 * orbit.period_t, "gamma3", max_points=7)
    neighbour = np.concatenate([sec.points["M"], sec.points["gamma"]], axis=1)[sec.t > 1e-6][0]
    F = [i.name for i in system.integrals].index("F")
    assert k.integrals(neighbour[None, :], p)[0, F] == pytest.approx(k.integrals(x[None, :], p)[0, F], rel=1e-12)
    back = integrate(system, p, neighbour, orbit.period_t, 2, engine="scipy", tolerance=1e-13).states[-1]
    assert np.max(np.abs(back - neighbour)) < 1e-9


def test_the_integrable_ball_s_isolated_centre_is_found_not_degenerate():
    system, p = ball("zero")
    orbit = find_periodic_orbit(system, p, on_section(system, p, -0.2, 0.0), "gamma3", t_final=100.0)
    assert orbit.status == "found" and orbit.stability == "elliptic" and orbit.family_dimension == 0
    assert_checks_pass(orbit)


def test_a_seed_that_does_not_return_in_time_is_not_found_with_the_reason():
    system, p = ball("linear")
    orbit = find_periodic_orbit(system, p, on_section(system, p, -0.2, 0.0), "gamma3", period=3, t_final=8.0)
    assert orbit.status == "not_found" and not orbit.closed
    assert "t_final = 8" in orbit.reason and "needs 4" in orbit.reason


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"period": 0}, "period"), ({"direction": "both"}, "direction"), ({"level": ["energy", "bogus"]}, "level[1]"),
    ({"surface": "gamma3 +"}, "surface"), ({"coordinates": ("gamma1", "nope")}, "coordinates[1]"),
])
def test_refused_fields_are_named(kwargs, field):
    system, p = ball("linear")
    args = {"surface": "gamma3", **kwargs}
    surface = args.pop("surface")
    with pytest.raises(PeriodicOrbitError) as err:
        find_periodic_orbit(system, p, on_section(system, p, -0.2, 0.0), surface, t_final=10.0, **args)
    assert err.value.field == field


def test_continuation_in_the_field_flags_the_period_doubling_where_the_trace_passes_minus_two():
    system, _ = ball("linear")
    values = [0.6, 0.7, 0.8, 0.9, 1.0]
    branch = continue_orbit(system, centre_orbit(), "a[2]", values, [ball("linear", v)[1] for v in values],
                            tolerance=np.finfo(float).eps)
    assert [o.status for o in branch.orbits] == ["found"] * 5
    traces = [o.trace for o in branch.orbits]
    assert np.all(np.diff(traces) < 0)  # the trace falls through -2 between a3 = 0.8 and 0.9
    assert traces[2] > -2 > traces[3]
    assert [(e.kind, e.between) for e in branch.events] == [("period_doubling", (0.8, 0.9))]
    assert [o.stability for o in branch.orbits] == ["elliptic"] * 3 + ["hyperbolic"] * 2
    for orbit, _v in zip(branch.orbits, values):
        assert_checks_pass(orbit)
        plus, minus = characteristic_signs(orbit.section_multipliers)
        assert plus == pytest.approx(2 - orbit.trace, abs=1e-8) and minus == pytest.approx(2 + orbit.trace, abs=1e-8)
