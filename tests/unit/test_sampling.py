"""States on a level set of the integrals (:mod:`nonholonomic.analysis.sampling`)."""

from __future__ import annotations

import numpy as np
import pytest

from nonholonomic.analysis.sampling import LevelError, describe_sampling, fixable, on_level
from nonholonomic.catalog import describe
from nonholonomic.initial_state import vector_slice
from nonholonomic.numerics.kernels import numeric, parameter_vector, state_vector
from nonholonomic.systems import KINDS, SUPPORTED_POTENTIALS, SYSTEMS, get_system

#: Parameters of the potentials the catalog examples (all U = 0) do not give.
POTENTIAL_PARAMETERS = {
    "linear": {"a": [0.3, -0.2, 0.5], "b": [0.1, 0.4, -0.2]},
    "brun": {"k": 0.8},
    "quadratic": {"K": [[1.0, 0.2, 0.0], [0.2, 2.0, -0.3], [0.0, -0.3, 0.5]]},
    "harmonic": {"k": 2.0},
}
# A ball on the user's surface draws no level (its extent is unknown): test_a_users_surface_samples_no_level.
CASES = [(kind, potential) for kind, potentials in SUPPORTED_POTENTIALS.items() for potential in potentials
         if not KINDS[kind].surface]
BALL = {"inertia": [2.0, 3.0, 4.5], "D": 0.7}
JACOBI = {"D0": 0.036, "m": 1.0, "R": 0.3, "B": [1.0, 2.0, 3.0]}


def example(kind: str, potential: str):
    """(system, parameter vector, example state) from the kind's catalog example."""
    system = get_system(kind, potential)
    spec = SYSTEMS[kind].EXAMPLE
    groups = {k: v for k, v in spec["system"].items() if k not in ("kind", "potential")}
    for par in system.parameters:
        groups.setdefault(par.name, POTENTIAL_PARAMETERS.get(potential, {}).get(par.name))
    p = parameter_vector(system, groups)
    return system, p, state_vector(system, spec["initial_state"], p)


def integrals_of(system, p, X) -> dict[str, np.ndarray]:
    values = numeric(system).integrals(np.atleast_2d(X), p)
    return {claim.name: values[:, i] for i, claim in enumerate(system.integrals)}


def example_level(system, p, y, names=None) -> dict[str, float]:
    """The example state's values of the fixable integrals: a level that is reached."""
    values = integrals_of(system, p, y)
    return {name: float(values[name][0]) for name in (names or fixable(system))}


def assert_on_level(system, p, X, level) -> None:
    kernels = numeric(system)
    assert X.shape[1] == system.dimension and np.all(np.isfinite(X))
    if system.constraints:
        deviation = np.abs(kernels.constraints(X, p) - [c.value for c in system.constraints])
        scale = np.maximum(1.0, np.abs(kernels.constraint_scales(X, p)))
        assert np.max(deviation / scale) <= 1e-12, [c.field for c in system.constraints]
    values, scales = integrals_of(system, p, X), kernels.integral_scales(X, p)
    names = [c.name for c in system.integrals]
    for name, target in level.items():
        size = np.maximum(abs(target), np.abs(scales[:, names.index(name)]))
        assert np.max(np.abs(values[name] - target) / size) <= 1e-12, name


# --- every kind and potential ---------------------------------------------------------------------


def test_a_users_surface_samples_no_level():
    system = get_system("ball_on_surface", "zero")
    assert fixable(system) == () and "initial states" in describe_sampling(system)
    with pytest.raises(LevelError, match="give the members' initial states") as info:
        on_level(system, np.ones(len(system.parameter_symbols)), {"energy": 1.0}, 2, 0)
    assert info.value.field == "level"


def test_every_kind_has_a_recipe_and_energy_is_fixable():
    """Every catalog kind but the user's surface has a sampling plan in its record; kinds written by the user none."""
    assert {k for k, record in KINDS.items() if record.sampling is not None} == {
        k for k in SYSTEMS if not KINDS[k].surface}
    for kind, potential in CASES:
        system = get_system(kind, potential)
        names = fixable(system)
        assert names[0] == "energy" and set(names) <= {c.name for c in system.integrals}
        assert not {"geometric", "quadric", "constraint", "E_squared"} & set(names)
    assert fixable(get_system("chaplygin_ball", "zero")) == ("energy", "area")
    assert fixable(get_system("ball_on_quadric", "zero")) == ("energy", "K")
    assert fixable(get_system("ball_on_quadric", "harmonic")) == ("energy", "K")
    assert fixable(get_system("ball_on_quadric", "linear")) == ("energy",)
    assert fixable(get_system("veselova", "zero")) == ("energy",)
    assert fixable(get_system("veselova_e3", "zero")) == ("energy",)  # (M, Gamma) = 0 is a constraint there


@pytest.mark.parametrize("kind, potential", CASES)
def test_samples_lie_on_the_constraints_and_the_level(kind, potential):
    system, p, y = example(kind, potential)
    level = example_level(system, p, y)
    X = on_level(system, p, level, 300, seed=11)
    assert X.shape == (300, system.dimension)
    assert_on_level(system, p, X, level)
    # the energy alone
    energy = example_level(system, p, y, ["energy"])
    assert_on_level(system, p, on_level(system, p, energy, 100, seed=2), energy)


@pytest.mark.parametrize("kind, potential", CASES)
def test_same_seed_same_bits_other_seed_other_states(kind, potential):
    system, p, y = example(kind, potential)
    level = example_level(system, p, y)
    first = on_level(system, p, level, 50, seed=5)
    again = on_level(system, p, dict(level), 50, seed=5)
    assert first.tobytes() == again.tobytes()
    assert on_level(system, p, level, 20, seed=5).tobytes() == first[:20].tobytes()  # a prefix
    other = on_level(system, p, level, 50, seed=6)
    assert not np.any(np.all(other == first, axis=1))


@pytest.mark.parametrize("kind, potential", CASES)
def test_energy_is_quadratic_in_the_velocity(kind, potential):
    """The solve reads H(v0 + t u) = e0 + e1 t + e2 t^2 off the kernel at t = 0, ±1: check the form
    at other t for random positions and velocities."""
    system, p, y = example(kind, potential)
    rng = np.random.default_rng(0)
    plan = KINDS[kind].sampling
    assert plan is not None
    velocity = vector_slice(system, plan.velocity)
    states = np.tile(y, (20, 1)) + 0.3 * rng.standard_normal((20, system.dimension))
    u = rng.standard_normal((20, 3))

    def H(t: float) -> np.ndarray:
        shifted = states.copy()
        shifted[:, velocity] += t * u
        return integrals_of(system, p, shifted)["energy"]

    e0, e1, e2 = H(0.0), (H(1.0) - H(-1.0)) / 2, (H(1.0) + H(-1.0)) / 2 - H(0.0)
    for t in (-2.5, 0.4, 3.0):
        assert np.allclose(H(t), e0 + e1 * t + e2 * t * t, rtol=1e-11, atol=1e-11)


def test_catalog_lists_the_levels_of_every_kind_and_potential():
    for kind in SYSTEMS:
        for entry in describe(kind)["potentials"]:
            system = get_system(kind, entry["kind"])
            assert entry["levels"] == list(fixable(system))
            assert entry["sampling"] == describe_sampling(system)
            assert ("uniform" if not KINDS[kind].surface else "initial states") in entry["sampling"]


# --- Chaplygin's ball -----------------------------------------------------------------------------


@pytest.mark.parametrize("potential, extra", [("zero", {}), ("linear", {"a": [0.0, 0.0, 0.4]})])
def test_ball_states_on_h_c_spread_and_match_an_independent_formula(potential, extra):
    system = get_system("chaplygin_ball", potential)
    p = parameter_vector(system, BALL | extra)
    X = on_level(system, p, {"energy": 1.0, "area": 0.5}, 2000, seed=3)
    M, g = X[:, :3], X[:, 3:]
    # eq. 2604-2 by numpy: H = (M, I_Q^-1 M)/2 + U, I_Q = J - D gamma⊗gamma, J = I + D
    J = np.diag(np.array(BALL["inertia"]) + BALL["D"])
    IQ = J[None] - BALL["D"] * g[:, :, None] * g[:, None, :]
    U = g @ np.array(extra.get("a", [0.0, 0.0, 0.0]))
    H = np.einsum("ni,ni->n", M, np.linalg.solve(IQ, M[:, :, None])[:, :, 0]) / 2 + U
    assert np.max(np.abs(H - 1.0)) <= 1e-13 and np.max(np.abs(np.sum(M * g, axis=1) - 0.5)) <= 1e-13
    assert np.max(np.abs(np.linalg.norm(g, axis=1) - 1.0)) <= 1e-15
    assert np.all(np.abs(g.mean(axis=0)) < 0.1) and np.all(g.min(axis=0) < -0.95) and np.all(g.max(axis=0) > 0.95)
    # the part of M ⊥ gamma points every way
    w = M - 0.5 * g
    w_dir = w / np.linalg.norm(w, axis=1, keepdims=True)
    assert np.all(np.abs(w_dir.mean(axis=0)) < 0.1)


def test_ball_random_states_on_h_1():
    """The benchmark's "random states on H = 1": the energy alone, M's direction uniform."""
    system = get_system("chaplygin_ball", "zero")
    p = parameter_vector(system, BALL)
    X = on_level(system, p, {"energy": 1.0}, 2000, seed=0)
    assert_on_level(system, p, X, {"energy": 1.0})
    areas = np.sum(X[:, :3] * X[:, 3:], axis=1)
    assert areas.std() > 0.5 and abs(areas.mean()) < 0.1   # c is free, either sign


# --- the nonholonomic Jacobi problem ---------------------------------------------------------------


def test_jacobi_decomposition_of_energy_and_K():
    """H(a n + w) = D0 a^2/2 + (D0 + D) w^2/2 + U and K depends on w only (the derivation used)."""
    D0, m, R, k = 0.036, 1.0, 0.3, 2.0
    D = m * R * R
    system = get_system("ball_on_quadric", "harmonic")
    p = parameter_vector(system, JACOBI | {"k": k})
    rng = np.random.default_rng(1)
    x = rng.standard_normal((50, 3)) * 2
    A = np.diag(1 / np.array(JACOBI["B"]))
    n = x @ A / np.linalg.norm(x @ A, axis=1, keepdims=True)
    w = rng.standard_normal((50, 3))
    w -= np.sum(w * n, axis=1, keepdims=True) * n
    a = rng.standard_normal(50)
    states = np.hstack([x, a[:, None] * n + w])
    values = integrals_of(system, p, states)
    U = k / 2 * np.sum(x * x, axis=1)
    assert np.allclose(values["energy"], D0 * a * a / 2 + (D0 + D) * np.sum(w * w, axis=1) / 2 + U, rtol=1e-13)
    assert np.allclose(values["K"], integrals_of(system, p, np.hstack([x, w]))["K"], rtol=1e-12, atol=1e-12)
    # eq. 2804-4 by numpy, with its k-term: K = (w x n, B^-1 w x n)/(n, B n) - k (x, B^-2 x)/(D0 + D)
    wxn = np.cross(w, n)
    K = np.sum(wxn * (wxn @ A), axis=1) / np.sum(n * (n @ np.diag(JACOBI["B"])), axis=1)
    assert np.allclose(values["K"], K - k * np.sum((x @ A) ** 2, axis=1) / (D0 + D), rtol=1e-12)


def test_jacobi_states_on_h_k_spread():
    system = get_system("ball_on_quadric", "zero")
    p = parameter_vector(system, JACOBI)
    X = on_level(system, p, {"energy": 1.0, "K": 2.0}, 2000, seed=4)
    assert_on_level(system, p, X, {"energy": 1.0, "K": 2.0})
    x, omega = X[:, :3], X[:, 3:]
    assert np.all(np.abs(x.mean(axis=0)) < 0.1)
    n = x @ np.diag(1 / np.array(JACOBI["B"]))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    spin = np.sum(omega * n, axis=1)
    assert abs(np.mean(spin > 0) - 0.5) < 0.05          # (omega, n) of either sign
    assert np.all(np.abs(omega.mean(axis=0)) < 0.15 * np.abs(omega).mean(axis=0).max())


def test_jacobi_positions_are_uniform_by_area():
    """E[x_i^2] over the area of the ellipsoid (quadrature) vs the samples; the naive push-forward
    of the uniform sphere (x = B^(1/2) y) misses it by many standard errors."""
    system = get_system("ball_on_quadric", "zero")
    p = parameter_vector(system, JACOBI)
    x = on_level(system, p, {"energy": 1.0}, 5000, seed=9)[:, :3]
    semi = np.sqrt(JACOBI["B"])
    th, ph = np.meshgrid(np.linspace(0, np.pi, 601), np.linspace(0, 2 * np.pi, 1201), indexing="ij")
    d_th = np.stack([semi[0] * np.cos(th) * np.cos(ph), semi[1] * np.cos(th) * np.sin(ph), -semi[2] * np.sin(th)])
    d_ph = np.stack([-semi[0] * np.sin(th) * np.sin(ph), semi[1] * np.sin(th) * np.cos(ph), 0 * th])
    dS = np.linalg.norm(np.cross(d_th, d_ph, axis=0), axis=0)
    point = np.stack([semi[0] * np.sin(th) * np.cos(ph), semi[1] * np.sin(th) * np.sin(ph), semi[2] * np.cos(th)])
    expected = np.array([np.sum(point[i] ** 2 * dS) for i in range(3)]) / np.sum(dS)
    error = (x ** 2).std(axis=0) / np.sqrt(len(x))
    assert np.all(np.abs((x ** 2).mean(axis=0) - expected) < 4 * error)
    naive = np.array(JACOBI["B"]) / 3                    # E[x_i^2] = b_i E[y_i^2] = b_i / 3
    assert np.abs(naive[2] - expected[2]) > 6 * error[2]


# --- errors ---------------------------------------------------------------------------------------


def error(kind, potential, groups, level, count=20, seed=0) -> LevelError:
    system = get_system(kind, potential)
    with pytest.raises(LevelError) as caught:
        on_level(system, parameter_vector(system, groups), level, count, seed)
    return caught.value


def test_names_a_level_cannot_fix():
    e = error("chaplygin_ball", "zero", BALL, {"energy": 1.0, "F": 2.0})
    assert e.field == "level.F" and "energy, area" in e.reason and "(M, M)" in e.reason
    e = error("chaplygin_ball", "zero", BALL, {"energy": 1.0, "geometric": 1.0})
    assert e.field == "level.geometric"
    e = error("ball_on_quadric", "linear", JACOBI | {"a": [0, 0, 1.0]}, {"energy": 1.0, "K": 1.0})
    assert e.field == "level.K" and "not an integral" in e.reason and e.reason.endswith("energy")
    e = error("veselova", "zero", {"inertia": [1, 2, 3]}, {"energy": 1.0, "spin": 1.0})
    assert e.field == "level.spin"
    assert isinstance(e, ValueError) and str(e).startswith("level.spin: ")


def test_malformed_requests():
    assert error("chaplygin_ball", "zero", BALL, {"area": 1.0}).field == "level.energy"   # the energy is required
    assert error("chaplygin_ball", "zero", BALL, {}).field == "level.energy"
    assert error("chaplygin_ball", "zero", BALL, {"energy": float("nan")}).field == "level.energy"
    assert error("chaplygin_ball", "zero", BALL, {"energy": "1"}).field == "level.energy"
    assert error("chaplygin_ball", "zero", BALL, {"energy": 1.0}, count=0).field == "count"
    assert error("chaplygin_ball", "zero", BALL, {"energy": 1.0}, count=2.0).field == "count"
    assert error("chaplygin_ball", "zero", BALL, {"energy": 1.0}, seed=-1).field == "seed"
    e = error("chaplygin_ball_veselova", "zero", BALL, {"energy": 1.0, "gamma_E": 1.2})
    assert e.field == "level.gamma_E" and "[-1, 1]" in e.reason
    with pytest.raises(ValueError):
        on_level(get_system("chaplygin_ball"), np.ones(2), {"energy": 1.0}, 3, 0)


def test_unreachable_levels_say_what_they_need():
    e = error("ball_on_quadric", "zero", JACOBI, {"energy": 0.1, "K": 5.0})
    assert e.field == "level" and "needs energy >= " in e.reason.replace("need energy", "needs energy")
    bound = float(e.reason.split(">= ")[1].split(" ")[0])
    assert bound > 0.1
    # just above the reported bound the level is reached (the bound is the least the tries found)
    system = get_system("ball_on_quadric", "zero")
    p = parameter_vector(system, JACOBI)
    assert_on_level(system, p, on_level(system, p, {"energy": 1.5 * bound, "K": 5.0}, 5, 0),
                    {"energy": 1.5 * bound, "K": 5.0})
    e = error("ball_on_quadric", "zero", JACOBI, {"energy": 1.0, "K": -1.0})
    assert e.field == "level.K" and "K >= 0" in e.reason
    e = error("chaplygin_ball", "linear", BALL | {"a": [0, 0, 1.0]}, {"energy": -2.0})
    assert e.field == "level.energy" and -1.0 <= float(e.reason.split(">= ")[1].split(" ")[0]) < -0.99  # min U = -|a|
    e = error("chaplygin_ball", "zero", BALL, {"energy": 0.01, "area": 3.0})
    assert e.field == "level" and "area = 3" in e.reason
    e = error("neumann", "zero", {"inertia": [1, 2, 3], "c": 1.3, "k": -2.0}, {"energy": 1.0})
    assert "energy <= " in e.reason                                      # k < 0: H is bounded above
    e = error("veselova_e3", "zero", {"inertia": [1, 2, 3], "alpha": -0.7, "beta": -0.4}, {"energy": 1.0})
    assert e.field == "level.energy" and "energy <= 0" in e.reason


def test_boundary_levels():
    """(gamma, E) = ±1 and the energy at rest are reached exactly."""
    system = get_system("chaplygin_ball_veselova", "zero")
    p = parameter_vector(system, BALL)
    X = on_level(system, p, {"energy": 0.5, "gamma_E": -1.0}, 50, 1)
    assert_on_level(system, p, X, {"energy": 0.5, "gamma_E": -1.0})
    system = get_system("veselova", "zero")
    p = parameter_vector(system, {"inertia": [1, 2, 3]})
    X = on_level(system, p, {"energy": 0.0}, 10, 1)
    assert np.all(X[:, :3] == 0) and np.allclose(np.linalg.norm(X[:, 3:], axis=1), 1.0, atol=1e-15)
