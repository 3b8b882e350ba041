"""Poincaré sections (nonholonomic.analysis.poincare) of Chaplygin's ball (eq. 2604-1).

The crossings are checked against what does not depend on the section code: the surface evaluated
with plain numpy, ω = I_Q⁻¹ M by a linear solve, the integrals of eq. (2604-2)/(2604-4) written out,
scipy DOP853's own event location on the independent right-hand side of tests/reference.py, and
the core integrator at the crossing times.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from nonholonomic import get_system
from nonholonomic.analysis.poincare import (
    DIRECTIONS,
    MAX_POINTS_LIMIT,
    Section,
    SurfaceError,
    default_coordinates,
    parse_surface,
    section,
    section_batch,
    surface_names,
)
from nonholonomic.numerics.integration import IntegrationCancelled, IntegrationError, integrate
from nonholonomic.numerics.kernels import numeric, parameter_vector
from tests.reference import ball_rhs

INERTIA = np.array([2.0, 3.0, 4.5])
D = 0.7
A = np.array([0.3, -0.2, 0.5])
Y0 = np.array([0.5, -0.2, 0.1, 0.0, 0.6, 0.8])
POTENTIALS = {"zero": {}, "linear": {"a": A}}


def ball(potential: str = "zero", d: float = D):
    system = get_system("chaplygin_ball", potential)
    return system, parameter_vector(system, {"inertia": INERTIA, "D": d, **POTENTIALS[potential]})


def omega_by_solve(M: np.ndarray, g: np.ndarray, d: float = D) -> np.ndarray:
    """ω = I_Q⁻¹ M with I_Q = diag(I + D) − D γγᵀ, by a batched linear solve."""
    IQ = np.diag(INERTIA + d)[None] - d * g[:, :, None] * g[:, None, :]
    return np.linalg.solve(IQ, M[:, :, None])[:, :, 0]


def integrals_by_hand(M: np.ndarray, g: np.ndarray, potential: str) -> np.ndarray:
    """Columns H, (γ, γ), (M, γ), and F = (M, M) for U = 0 (eq. 2604-2, 2604-4)."""
    H = 0.5 * np.einsum("ij,ij->i", M, omega_by_solve(M, g))
    cols = [H + (g @ A if potential == "linear" else 0.0), np.einsum("ij,ij->i", g, g), np.einsum("ij,ij->i", M, g)]
    if potential == "zero":
        cols.append(np.einsum("ij,ij->i", M, M))
    return np.stack(cols, axis=1)


def scipy_crossings(potential: str, t_final: float, direction: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Times and states of γ3 = 0 located by scipy DOP853's event finder (rtol = atol = 1e-13)."""
    def gamma3(t, y):
        return y[5]
    gamma3.direction = direction
    sol = solve_ivp(ball_rhs(INERTIA, D, A if potential == "linear" else None), (0.0, t_final), Y0,
                    method="DOP853", rtol=1e-13, atol=1e-13, events=gamma3)
    assert sol.success, sol.message
    return sol.t_events[0], sol.y_events[0]


def state_of(s: Section) -> np.ndarray:
    return np.hstack([s.points["M"], s.points["gamma"]])


# --- crossings on the surface, integrals, independent event location ----------------------------

@pytest.mark.parametrize("potential", sorted(POTENTIALS))
def test_crossings_lie_on_the_surface_and_keep_every_integral(potential):
    system, p = ball(potential)
    s = section(system, p, Y0, 1000.0, "gamma3")
    assert s.count >= 25  # ~31 (U = 0) and ~90 (linear) crossings
    assert s.surface_scale == pytest.approx(1.0, abs=1e-12)  # |∂γ3/∂γ| |γ| = 1
    assert s.surface_residual_max <= 1e-13
    assert np.max(np.abs(s.points["gamma"][:, 2])) <= 1e-13  # the surface, evaluated directly
    assert not s.stopped_early and s.warnings == ()
    # drift at the points, reported and recomputed by hand from eq. (2604-2)
    expected = {"energy", "geometric", "area"} | ({"F"} if potential == "zero" else set())
    assert set(s.integral_drift_max) == expected
    assert max(s.integral_drift_max.values()) <= 1e-12
    values = integrals_by_hand(s.points["M"], s.points["gamma"], potential)
    initial = integrals_by_hand(Y0[None, :3], Y0[None, 3:], potential)[0]
    assert np.max(np.abs(values - initial) / np.maximum(np.abs(initial), 1.0)) <= 1e-12
    # ω at the points is I_Q⁻¹ M (a derived vector, by a linear solve)
    assert np.allclose(s.points["omega"], omega_by_solve(s.points["M"], s.points["gamma"]), rtol=0, atol=1e-14)
    assert s.coordinate_names == ("gamma1", "gamma2")
    assert np.array_equal(s.coordinates, s.points["gamma"][:, :2])
    assert np.all(np.diff(s.t) > 0) and np.all(np.diff(s.tau) > 0)


@pytest.mark.parametrize("potential,t_final", [("zero", 1000.0), ("linear", 150.0)])
def test_crossing_times_agree_with_scipy_dop853_event_location(potential, t_final):
    system, p = ball(potential)
    s = section(system, p, Y0, t_final, "gamma3")
    t_ref, y_ref = scipy_crossings(potential, t_final)
    assert s.count == len(t_ref) >= 10
    dt = np.max(np.abs(s.t - t_ref))
    assert dt <= 1e-9, dt  # DOP853 at 1e-13 locates these crossings to ~2e-11
    assert np.max(np.abs(state_of(s) - y_ref)) <= 1e-9


def test_points_equal_the_core_integrator_at_the_crossing_times():
    system, p = ball()
    s = section(system, p, Y0, 1000.0, "gamma3")
    trajectory = integrate(system, p, Y0, 0.0, 0, times=np.concatenate([[0.0], s.t]))
    assert np.max(np.abs(trajectory.states[1:] - state_of(s))) <= 1e-12
    assert np.max(np.abs(trajectory.tau[1:] - s.tau)) <= 1e-12 * max(1.0, s.tau[-1])


def test_direction_filtering_follows_the_sign_of_dS_dt():
    system, p = ball()
    rhs = numeric(system).rhs
    by_direction = {d: section(system, p, Y0, 500.0, "gamma3", direction=d) for d in DIRECTIONS}
    up, down, both = (by_direction[d] for d in DIRECTIONS)
    assert np.all(rhs(state_of(up), p)[:, 5] > 0)  # dγ3/dt from the rhs kernel
    assert np.all(rhs(state_of(down), p)[:, 5] < 0)
    assert up.count >= 10 and down.count >= 10 and both.count == up.count + down.count
    assert np.allclose(both.t, np.sort(np.concatenate([up.t, down.t])), rtol=1e-13, atol=0)
    # increasing and decreasing crossings alternate along the orbit
    signs = np.sign(rhs(state_of(both), p)[:, 5])
    assert np.all(signs[1:] == -signs[:-1])


def test_a_derived_component_is_a_surface():
    system, p = ball()
    s = section(system, p, Y0, 1000.0, "omega3", value=0.01, direction="both", coordinates=("M1", "omega2"))
    assert s.count >= 10
    omega = omega_by_solve(s.points["M"], s.points["gamma"])
    assert np.max(np.abs(omega[:, 2] - 0.01)) <= 1e-13 * s.surface_scale
    assert s.surface_residual_max <= 1e-13
    assert 0.05 < s.surface_scale < 1.0  # |∂ω3/∂M||M| + |∂ω3/∂γ||γ| ~ |ω|
    assert np.allclose(s.coordinates, np.stack([s.points["M"][:, 0], omega[:, 1]], axis=1), rtol=0, atol=1e-14)


def test_surface_with_parameters_and_level():
    # parameters may appear in a surface; the level is a runtime parameter of one compiled integrator
    system, p = ball()
    expr = parse_surface(system, "M1 - I1*omega1")
    assert expr.free_symbols >= {sp.Symbol("I1", positive=True)}
    s1 = section(system, p, Y0, 300.0, "gamma3", value=0.3)
    s2 = section(system, p, Y0, 300.0, "gamma3", value=-0.3)
    assert s1.count >= 5 and s2.count >= 5
    assert np.allclose(s1.points["gamma"][:, 2], 0.3, rtol=0, atol=1e-15)
    assert np.allclose(s2.points["gamma"][:, 2], -0.3, rtol=0, atol=1e-15)


def test_the_integrable_ball_crosses_on_a_curve_the_chaotic_one_spreads():
    # U = 0: four integrals (eq. 2604-2, 2604-4) leave a curve on the section γ3 = 0, so (M1, γ1)
    # along the crossings sorted by γ1's angle varies smoothly; the linear potential keeps only
    # three integrals and the crossings scatter over an area.
    def roughness(s: Section) -> float:
        order = np.argsort(np.arctan2(s.points["gamma"][:, 1], s.points["gamma"][:, 0]))
        m = s.points["M"][order]
        return float(np.sum(np.linalg.norm(np.diff(m, axis=0), axis=1)) / np.ptp(m, axis=0).max())

    integrable = section(*ball("zero"), Y0, 4000.0, "gamma3")
    chaotic = section(*ball("linear"), Y0, 1300.0, "gamma3")
    assert integrable.count >= 100 and chaotic.count >= 100
    assert roughness(integrable) < 10 < roughness(chaotic)


# --- batch mode -----------------------------------------------------------------------------------

def members(n: int = 6):
    system, _ = ball()
    d = np.linspace(0.5, 0.9, n)
    P = np.stack([parameter_vector(system, {"inertia": INERTIA, "D": di}) for di in d])
    Y = np.tile(Y0, (n, 1)) * np.linspace(1.0, 1.2, n)[:, None]
    Y[:, 3:] /= np.linalg.norm(Y[:, 3:], axis=1)[:, None]
    return system, P, Y


def test_section_batch_equals_section_per_member_and_is_reproducible():
    system, P, Y = members()
    first = section_batch(system, P, Y, 1000.0, "gamma3")
    again = section_batch(system, P, Y, 1000.0, "gamma3")
    assert len(first) == len(Y)
    for i, (b, b2) in enumerate(zip(first, again)):
        assert isinstance(b, Section)
        single = section(system, P[i], Y[i], 1000.0, "gamma3")
        assert b.count == single.count >= 20
        assert np.max(np.abs(b.t - single.t) / np.maximum(1.0, single.t)) <= 1e-13
        assert np.max(np.abs(state_of(b) - state_of(single))) <= 1e-13
        assert b.surface_residual_max <= 1e-13 and max(b.integral_drift_max.values()) <= 1e-12
        assert np.array_equal(b.t, b2.t) and np.array_equal(state_of(b), state_of(b2))
        assert np.array_equal(b.tau, b2.tau)
    # members differ: the batch lanes really carry their own parameters and states
    assert len({b.count for b in first}) > 1


def test_a_failing_member_fails_alone():
    system, P, Y = members()
    Y[2, 0] = 1e200  # the energy overflows at once: non-finite state
    # |γ| = 1.04 > 1 with I1 = 0.01: det I_Q = det J (1 − D (γ, J⁻¹γ)) reaches 0 as γ turns towards e1,
    # some time after the start (heyoka halts every lane then; the others must resume unchanged)
    P[4] = parameter_vector(system, {"inertia": [0.01, 3.0, 4.5], "D": D})
    Y[4] = [0.5, -0.2, 0.3, 0.0, 0.6, 0.85]
    results = section_batch(system, P, Y, 1000.0, "gamma3")
    for i in (2, 4):
        assert isinstance(results[i], IntegrationError)
        with pytest.raises(IntegrationError, match="err_nf_state"):
            section(system, P[i], Y[i], 1000.0, "gamma3")
    assert "between t = 0 and" not in str(results[4])  # it failed mid-run
    for i in (0, 1, 3, 5):
        single = section(system, P[i], Y[i], 1000.0, "gamma3")
        assert results[i].count == single.count
        assert np.max(np.abs(state_of(results[i]) - state_of(single))) <= 1e-13


def test_max_points_stops_early_with_a_warning():
    system, p = ball()
    full = section(system, p, Y0, 1000.0, "gamma3")
    s = section(system, p, Y0, 1000.0, "gamma3", max_points=5)
    assert s.count == 5 and s.stopped_early
    assert any("max_points = 5 reached at t = " in w for w in s.warnings)
    assert s.steps < full.steps / 2  # it stopped integrating, not only recording
    assert np.allclose(s.t, full.t[:5], rtol=1e-14, atol=0)
    exact = section(system, p, Y0, full.t[4] + 1.0, "gamma3", max_points=5)  # 5 crossings up to t_final: not early
    assert exact.count == 5 and not exact.stopped_early
    system_b, P, Y = members(5)
    batch = section_batch(system_b, P, Y, 1000.0, "gamma3", max_points=7)
    assert all(b.count == 7 and b.stopped_early for b in batch)


def test_progress_is_reported_and_cancels():
    system, p = ball()
    seen: list[float] = []
    section(system, p, Y0, 1000.0, "gamma3", progress=lambda f: seen.append(f) or True)
    assert seen[-1] == 1.0 and all(np.diff(seen) > 0) and len(seen) >= 2
    with pytest.raises(IntegrationCancelled):
        section(system, p, Y0, 1000.0, "gamma3", progress=lambda f: f < 0.3)


def test_batch_progress_covers_every_member_and_cancels():
    system, P, Y = members(6)
    seen: list[float] = []
    # long enough for several segments whatever the SIMD width (6 members: 2 batches of 4 with AVX2,
    # 1 batch of 8 with AVX-512, where t_final = 200 took two segments only)
    section_batch(system, P, Y, 3000.0, "gamma3", progress=lambda f: seen.append(f) or True)
    assert seen[-1] == pytest.approx(1.0) and all(np.diff(seen) > 0) and len(seen) >= 4
    with pytest.raises(IntegrationCancelled):
        section_batch(system, P, Y, 3000.0, "gamma3", progress=lambda f: f < 0.3)


def test_threads_use_their_own_integrator_copies():
    system, P, Y = members(4)
    serial = [section(system, P[i], Y[i], 500.0, "gamma3") for i in range(4)]
    with ThreadPoolExecutor(max_workers=2) as pool:
        threaded = list(pool.map(lambda i: section(system, P[i], Y[i], 500.0, "gamma3"), range(4)))
    for a, b in zip(serial, threaded):
        assert np.array_equal(a.t, b.t) and np.array_equal(state_of(a), state_of(b))


def test_no_crossing_is_an_empty_section_with_a_warning():
    system, p = ball()
    s = section(system, p, Y0, 100.0, "gamma3", value=2.0)  # |γ| = 1
    assert s.count == 0 and s.points["M"].shape == (0, 3) and s.coordinates.shape == (0, 2)
    assert s.surface_residual_max == 0.0 and any("no crossing" in w for w in s.warnings)


# --- names, parsing and refused input ---------------------------------------------------------------

def test_surface_names_include_state_and_derived_components():
    system, p = ball()
    names = surface_names(system)
    assert list(names)[:6] == ["M1", "M2", "M3", "gamma1", "gamma2", "gamma3"]
    assert {"omega1", "omega2", "omega3"} <= set(names)
    state = np.array([[0.3, -0.1, 0.7, 0.6, 0.0, 0.8]])
    f = sp.lambdify(system.state_symbols + system.parameter_symbols, names["omega1"])
    assert f(*state[0], *p) == pytest.approx(omega_by_solve(state[:, :3], state[:, 3:])[0, 0], rel=1e-14)
    veselova = get_system("veselova", "zero")
    assert names.keys() != surface_names(veselova).keys() and "omega1" in surface_names(veselova)
    assert default_coordinates(system) == ("gamma1", "gamma2")
    assert default_coordinates(get_system("ball_on_quadric", "zero")) == ("x1", "x2")


@pytest.mark.parametrize("text,position,words", [
    ("gamma4 + 1", 0, "allowed names: D, I1"),  # unknown name: where, and which names exist
    ("M1 + foo", 5, "omega1"),
    ("gamma3 + * 2", 9, "syntax"),
    ("gamma3 ^ 2", 7, "**"),
    ("abs(gamma3)", 0, "smooth"),
    ("2*sign(M1)", 2, "smooth"),
])
def test_bad_surfaces_name_the_field_and_the_position(text, position, words):
    system, _ = ball()
    with pytest.raises(SurfaceError) as err:
        parse_surface(system, text)
    assert err.value.field == "surface" and err.value.position == position and words in err.value.reason


@pytest.mark.parametrize("text", ["1", "pi", "I1", "2*D + 1", "gamma3 - gamma3"])
def test_a_surface_must_depend_on_the_state(text):
    system, _ = ball()
    with pytest.raises(SurfaceError, match="not a function of the state") as err:
        parse_surface(system, text)
    assert err.value.field == "surface"


@pytest.mark.parametrize("kwargs,field", [
    ({"coordinates": ("gamma1", "x9")}, "coordinates[1]"),
    ({"coordinates": ("I1", "gamma1")}, "coordinates[0]"),
    ({"coordinates": ("gamma1",)}, "coordinates"),
    ({"coordinates": ("M1", "M1")}, "coordinates[1]"),
    ({"direction": "up"}, "direction"),
    ({"max_points": 0}, "max_points"),
    ({"max_points": MAX_POINTS_LIMIT + 1}, "max_points"),
    ({"max_points": 2.5}, "max_points"),
    ({"value": float("nan")}, "value"),
    ({"tolerance": -1.0}, "tolerance"),
])
def test_bad_request_fields_are_named(kwargs, field):
    system, p = ball()
    with pytest.raises(SurfaceError) as err:
        section(system, p, Y0, 10.0, "gamma3", **kwargs)
    assert err.value.field == field and isinstance(err.value, ValueError)


def test_bad_times_and_arrays_are_named():
    system, p = ball()
    for t_final in (-1.0, 0.0, float("inf")):
        with pytest.raises(SurfaceError) as err:
            section(system, p, Y0, t_final, "gamma3")
        assert err.value.field == "t_final"
    with pytest.raises(SurfaceError) as err:
        section(system, p, Y0[:5], 10.0, "gamma3")
    assert err.value.field == "initial_state"
    with pytest.raises(SurfaceError) as err:
        section_batch(system, np.tile(p, (3, 1)), np.tile(Y0, (2, 1)), 10.0, "gamma3")
    assert err.value.field == "parameters"
