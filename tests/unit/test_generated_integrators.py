"""The generated heyoka right-hand sides (nonholonomic.numerics.taylor) and the integration paths built on
them (nonholonomic.numerics.integration): same equations as the sympy definitions, fewer operations, step
states without a Python call per step on long runs, batch mode member by member like integrate()."""

from __future__ import annotations

import heyoka as hy
import numpy as np
import pytest
import sympy as sp

from nonholonomic import get_system
from nonholonomic.evidence.integrals import integral_evidence, integral_evidence_batch
from nonholonomic.numerics import integration as integ
from nonholonomic.numerics.integration import (
    IntegrationCancelled,
    IntegrationError,
    StepRecorder,
    Trajectory,
    integrate,
)
from nonholonomic.numerics.integration_batch import integrate_batch
from nonholonomic.numerics.kernels import numeric, parameter_vector
from nonholonomic.numerics.taylor import taylor_system
from nonholonomic.systems import SUPPORTED_POTENTIALS

KINDS = [(kind, potential) for kind, potentials in SUPPORTED_POTENTIALS.items() for potential in potentials]

#: Operations (``len(decomposition) - 2 * n_vars``) of the literal ``hy.from_sympy`` transcription,
#: measured before the generator optimised it (heyoka 7.13).
LITERAL_OPERATIONS = {
    ("chaplygin_ball", "zero"): 85, ("chaplygin_ball", "linear"): 97, ("chaplygin_ball", "brun"): 103,
    ("veselova", "zero"): 77, ("veselova", "linear"): 101, ("veselova", "brun"): 106, ("veselova", "quadratic"): 138,
    ("chaplygin_ball_veselova", "zero"): 173, ("chaplygin_ball_veselova", "linear"): 188,
    ("rubber_ball", "zero"): 119, ("rubber_ball", "linear"): 128,
    ("ball_on_quadric", "zero"): 109, ("ball_on_quadric", "linear"): 127, ("ball_on_quadric", "harmonic"): 130,
    # the torus of the catalog example (measured with heyoka 7.13 when the kind was added)
    ("ball_on_surface", "zero"): 159, ("ball_on_surface", "linear"): 181, ("ball_on_surface", "harmonic"): 186,
    ("neumann", "zero"): 28, ("clebsch", "zero"): 68, ("veselova_e3", "zero"): 103,
}

BALL = get_system("chaplygin_ball")
P_BALL = parameter_vector(BALL, {"inertia": [2.0, 3.0, 4.5], "D": 0.7})
Y_BALL = np.array([0.5, -0.2, 0.1, 0.0, 0.6, 0.8])


def ball_states(count: int, seed: int = 3) -> np.ndarray:
    """Ball states with |γ| = 1 and moderate M."""
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(count, 3))
    return np.hstack([0.5 * rng.normal(size=(count, 3)), g / np.linalg.norm(g, axis=1)[:, None]])


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


# --- the generated right-hand side -----------------------------------------------------------------

@pytest.mark.parametrize("kind,potential", KINDS)
def test_generated_rhs_is_the_sympy_rhs(kind, potential):
    """Pointwise, at random states and parameters (one parameter vector per point: the batch shape of
    runtime_parameters), against the numpy kernels of the same definition, τ density included."""
    system = get_system(kind, potential)
    ts = taylor_system(system)
    rng = np.random.default_rng(11)
    n = 64
    X = 0.3 * rng.normal(size=(n, system.dimension))
    P = rng.uniform(0.5, 2.0, size=(n, len(system.parameter_symbols)))
    kernels = numeric(system)
    ref = np.stack([kernels.rhs(X[i:i + 1], P[i])[0] for i in range(n)])
    if ts.has_tau:
        ref = np.hstack([ref, np.array([kernels.time_density(X[i:i + 1], P[i])[0] for i in range(n)])])
    inputs = np.hstack([X, np.zeros((n, 1))]) if ts.has_tau else X
    got = hy.cfunc(list(ts.rhs), list(ts.variables))(np.ascontiguousarray(inputs.T),
                                                     pars=np.ascontiguousarray(ts.runtime_parameters(P.T))).T
    finite = np.isfinite(ref)
    assert finite.mean() > 0.5
    scale = np.abs(ref) + 1e-3 * np.max(np.abs(ref[finite]))
    assert np.max(np.abs(got - ref)[finite] / scale[finite]) < 1e-13
    assert np.array_equal(np.isfinite(got), finite)


@pytest.mark.parametrize("kind,potential", KINDS)
def test_generated_rhs_has_no_more_operations_than_the_literal_one(kind, potential):
    ts = taylor_system(get_system(kind, potential))
    assert ts.operations <= LITERAL_OPERATIONS[(kind, potential)]
    assert ts.n_pars == len(ts.system.parameter_symbols) + len(ts.derived_parameters)


def test_ball_operations_drop_by_almost_half():
    """heyoka's own count: 85 operations for the literal transcription, 46 generated (44 by hand)."""
    ts = taylor_system(BALL)
    nv = len(ts.variables)
    literal = [hy.from_sympy(f, {**dict(zip(BALL.state_symbols, ts.variables)),
                                 **{s: hy.par[i] for i, s in enumerate(BALL.parameter_symbols)}})
               for f in list(BALL.rhs) + [BALL.reduced_time.density]]
    before = hy.taylor_adaptive(list(zip(ts.variables, literal)), np.zeros(nv), pars=np.zeros(4))
    after = hy.taylor_adaptive(ts.equations, np.zeros(nv), pars=np.zeros(ts.n_pars))
    assert len(before.decomposition) - 2 * nv == 85
    assert len(after.decomposition) - 2 * nv == ts.operations <= 48
    assert ts.strategy == "horner"


def test_runtime_parameters_batch_columns_are_the_single_vectors():
    ts = taylor_system(get_system("chaplygin_ball", "linear"))
    P = np.random.default_rng(2).uniform(0.5, 2.0, size=(7, 5))
    batch = ts.runtime_parameters(P)
    assert batch.shape == (ts.n_pars, 5)
    for j in range(5):
        assert np.array_equal(batch[:, j], ts.runtime_parameters(P[:, j]))
    assert np.array_equal(batch[:7], P)  # the system's own parameters come first: hy.par[i] is still the i-th
    with pytest.raises(ValueError, match="parameters"):
        ts.runtime_parameters(np.ones(3))


def test_expression_translates_through_the_hoisting():
    """An integral (parameter-only parts hoisted or not) and a plain surface, against numpy."""
    ts = taylor_system(BALL)
    energy = BALL.integrals[0].expression
    M1, gamma3, D = BALL.state_symbols[0], BALL.state_symbols[5], BALL.parameter_symbols[3]
    extra = D**3 * M1  # a parameter-only part the right-hand side lacks
    cf = hy.cfunc(ts.expressions([energy, extra, gamma3]), list(ts.variables[:6]))
    X = ball_states(20)
    pars = np.repeat(ts.runtime_parameters(P_BALL)[:cf.nparams, None], 20, axis=1)
    got = cf(np.ascontiguousarray(X.T), pars=pars)
    assert relative(got[0], numeric(BALL).integrals(X, P_BALL)[:, 0]) < 1e-14
    assert relative(got[1], P_BALL[3] ** 3 * X[:, 0]) < 1e-15
    assert np.array_equal(got[2], X[:, 5])
    with pytest.raises(ValueError, match="unknown symbols"):
        ts.expression(sp.Symbol("x") + M1)


# --- integrate: step states and segments ------------------------------------------------------------

def reference_run(system, p, y0, grid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The old way: propagate_grid with a Python callback recording (time, state) after every step."""
    ts = taylor_system(system)
    ta = hy.taylor_adaptive(ts.equations, ts.initial(y0), pars=ts.runtime_parameters(p), tol=integ.MACHINE_EPSILON)
    t, states = [0.0], [ta.state[:system.dimension].copy()]

    def record(integrator):
        t.append(integrator.time)
        states.append(integrator.state[:system.dimension].copy())
        return True

    out = ta.propagate_grid(grid, callback=record)[5]
    return out, np.array(t), np.array(states)


def test_integrate_records_every_step_state_exactly():
    grid = np.linspace(0.0, 60.0, 13)
    out, t, states = reference_run(BALL, P_BALL, Y_BALL, grid)
    traj = integrate(BALL, P_BALL, Y_BALL, 60.0, 13)
    assert np.array_equal(traj.step_t, t) and np.array_equal(traj.step_states, states)
    assert traj.steps == len(t) - 1
    assert relative(traj.states, out[:, :6]) < 1e-15 and relative(traj.tau, out[:, 6]) < 1e-15


def test_long_run_segments_give_the_same_steps_and_samples(monkeypatch):
    """After the first segment, continuous-output segments: the same steps exactly (the order-0
    Taylor coefficients are the integrator's states), samples to rounding, progress in between."""
    whole = integrate(BALL, P_BALL, Y_BALL, 300.0, 37)
    monkeypatch.setattr(integ, "FIRST_SEGMENT_STEPS", 20)
    monkeypatch.setattr(integ, "SEGMENT_WALL_TIME_S", 1e-5)  # tiny segments: many of them
    seen: list[float] = []
    cut = integrate(BALL, P_BALL, Y_BALL, 300.0, 37, progress=lambda f: seen.append(f) or True)
    assert cut.steps == whole.steps > 100
    assert np.array_equal(cut.step_t, whole.step_t) and np.array_equal(cut.step_states, whole.step_states)
    assert relative(cut.states, whole.states) < 1e-14 and relative(cut.tau, whole.tau) < 1e-14
    assert np.array_equal(cut.states[-1], whole.states[-1])
    assert len(seen) >= 3 and seen == sorted(seen) and 0 < seen[0] and seen[-1] < 1
    with pytest.raises(IntegrationCancelled):
        integrate(BALL, P_BALL, Y_BALL, 300.0, 37, progress=lambda f: f < 0.5)


def test_repeated_sample_times_are_allowed():
    traj = integrate(BALL, P_BALL, Y_BALL, 0.0, 0, times=np.array([0.0, 0.0, 1.0, 1.0, 2.5]))
    assert traj.states.shape == (5, 6) and np.array_equal(traj.states[0], traj.states[1])
    assert np.array_equal(traj.states[2], traj.states[3]) and np.array_equal(traj.states[0], Y_BALL)
    assert relative(traj.states[-1], integrate(BALL, P_BALL, Y_BALL, 2.5, 2).states[-1]) < 1e-15


def test_step_recorder_extend_is_adding_one_by_one():
    one, many = StepRecorder(capacity=8), StepRecorder(capacity=8)
    rng = np.random.default_rng(0)
    rows, start = rng.normal(size=(100, 2)), 0
    for i in range(100):
        one.add(float(i), rows[i])
    for size in [1, 3, 7, 20, 2, 40, 27]:
        many.extend(np.arange(start, start + size, dtype=float), rows[start:start + size])
        start += size
    assert start == 100 and one.stride == many.stride == 16
    assert np.array_equal(one.t, many.t) and np.array_equal(one.states, many.states)


# --- integrate_batch ------------------------------------------------------------------------------------

def sweep(count: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` members differing in D and in the initial state."""
    P = np.repeat(P_BALL[None], count, axis=0)
    P[:, 3] = np.linspace(0.2, 0.9, count)
    return P, ball_states(count)


def test_batch_members_agree_with_integrate():
    P, Y0 = sweep(7)  # two batches on 4 lanes, the second padded
    batch = integrate_batch(BALL, P, Y0, 40.0, 9)
    for p, y0, member in zip(P, Y0, batch):
        alone = integrate(BALL, p, y0, 40.0, 9)
        assert isinstance(member, Trajectory)
        assert relative(member.states, alone.states) < 1e-13 and relative(member.tau, alone.tau) < 1e-13
        assert member.steps == alone.steps and member.step_states.shape == alone.step_states.shape
        assert relative(member.step_states, alone.step_states) < 1e-13
        assert np.array_equal(member.t, alone.t) and np.array_equal(member.states[0], y0)


def test_batch_is_bit_for_bit_reproducible():
    P, Y0 = sweep(5)
    first, second = (integrate_batch(BALL, P, Y0, 25.0, 6) for _ in range(2))
    for a, b in zip(first, second):
        assert np.array_equal(a.states, b.states) and np.array_equal(a.tau, b.tau)
        assert np.array_equal(a.step_t, b.step_t) and np.array_equal(a.step_states, b.step_states)


def test_a_failing_member_fails_alone():
    """γ four times too long makes det I_Q negative: τ's density is not finite. Its neighbours in
    the batch get exactly what they get without it."""
    P, Y0 = sweep(4)
    bad = Y0.copy()
    bad[1, 3:] *= 4.0
    out = integrate_batch(BALL, P, bad, 20.0, 5)
    assert isinstance(out[1], IntegrationError) and "err_nf_state" in str(out[1])
    with pytest.raises(IntegrationError, match="err_nf_state"):
        integrate(BALL, P[1], bad[1], 20.0, 5)
    clean = integrate_batch(BALL, P, Y0, 20.0, 5)
    for i in (0, 2, 3):
        assert np.array_equal(out[i].states, clean[i].states)
        assert np.array_equal(out[i].step_states, clean[i].step_states)


def test_batch_long_runs_progress_and_cancel(monkeypatch):
    P, Y0 = sweep(5)
    whole = integrate_batch(BALL, P, Y0, 150.0, 16)
    monkeypatch.setattr(integ, "FIRST_SEGMENT_STEPS", 30)
    monkeypatch.setattr(integ, "SEGMENT_WALL_TIME_S", 1e-5)
    seen: list[float] = []
    cut = integrate_batch(BALL, P, Y0, 150.0, 16, progress=lambda f: seen.append(f) or True)
    for a, b in zip(cut, whole):
        assert a.steps == b.steps and np.array_equal(a.step_states, b.step_states)
        assert relative(a.states, b.states) < 1e-14
    assert len(seen) > 3 and seen == sorted(seen) and seen[-1] < 1
    with pytest.raises(IntegrationCancelled):
        integrate_batch(BALL, P, Y0, 150.0, 16, progress=lambda f: f < 0.3)


def test_batch_validates_shapes():
    with pytest.raises(ValueError, match="parameters"):
        integrate_batch(BALL, P_BALL, Y_BALL[None], 1.0, 2)
    with pytest.raises(ValueError, match="initial_states"):
        integrate_batch(BALL, P_BALL[None], Y_BALL[None, :5], 1.0, 2)
    assert integrate_batch(BALL, np.empty((0, 4)), np.empty((0, 6)), 1.0, 2) == []


def test_integral_evidence_batch_is_the_evidence_member_by_member():
    P, Y0 = sweep(6)
    trajectories = integrate_batch(BALL, P, Y0, 30.0, 7)
    for p, t, batch in zip(P, trajectories, integral_evidence_batch(BALL, P, trajectories)):
        for one, other in zip(integral_evidence(BALL, p, t), batch):
            assert (one.name, one.evaluated_at, one.tolerance, one.passed) == (
                other.name, other.evaluated_at, other.tolerance, other.passed)
            assert abs(one.initial - other.initial) <= 1e-15 * max(1.0, abs(one.initial))
            assert abs(one.final - other.final) <= 1e-15 * max(1.0, abs(one.final))
            assert abs(one.max_rel_drift - other.max_rel_drift) < 1e-15
            assert one.reference == pytest.approx(other.reference, rel=1e-15)


@pytest.mark.parametrize("kind,potential", KINDS)
def test_compiled_integrals_are_the_sympy_integrals(kind, potential):
    """Every kind's integrals and scales compile (|k|, |c|, |beta| in the scales included: heyoka has
    no Abs, sqrt(x**2) stands for it) and agree with the numpy kernels of the same expressions, also
    at negative parameters where |x| and x differ."""
    from nonholonomic.evidence.integrals import compiled_integrals

    system = get_system(kind, potential)
    cf, ts = compiled_integrals(system)
    rng = np.random.default_rng(5)
    n = 32
    X = 0.3 * rng.normal(size=(n, ts.n_state))
    P = rng.uniform(-2.0, 2.0, size=(n, len(system.parameter_symbols)))
    exprs = [c.expression for c in system.integrals] + [c.scale for c in system.integrals]
    fn = sp.lambdify([*system.state_symbols, *system.parameter_symbols], exprs, modules="numpy")
    with np.errstate(all="ignore"):
        ref = np.stack([np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in fn(*X.T, *P.T)])
        got = cf(np.ascontiguousarray(X.T), pars=np.ascontiguousarray(ts.runtime_parameters(P.T)[:cf.nparams]))
    finite = np.isfinite(ref)
    assert finite.mean() > 0.5
    scale = np.abs(ref) + 1e-3 * np.max(np.abs(ref[finite]))
    assert np.max(np.abs(got - ref)[finite] / scale[finite]) < 1e-12
