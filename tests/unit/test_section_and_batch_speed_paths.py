"""The fast paths of issue 20 (bench/bench_poincare.py, bench/bench_ensemble.py) compute what the slow
ones did: a section's compiled post-processing is the symbolic expressions, its segments cut no step,
and the batch path's short runs finished all together are the members' own trajectories, in order,
next to a failing member's batch. No wall-clock bound here: the speed is measured in bench/."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from nonholonomic import get_system
from nonholonomic.analysis.poincare import section
from nonholonomic.analysis.poincare.surface import _surface_kernels, parse_surface
from nonholonomic.numerics.integration import IntegrationError, Trajectory, integrate
from nonholonomic.numerics.integration_batch import integrate_batch
from nonholonomic.numerics.kernels import parameter_vector
from nonholonomic.numerics.taylor import taylor_system
from nonholonomic.systems import SUPPORTED_POTENTIALS

BALL = get_system("chaplygin_ball", "zero")
P_BALL = parameter_vector(BALL, {"inertia": [2.0, 3.0, 4.5], "D": 0.7})
Y_BALL = np.array([0.5, -0.2, 0.1, 0.0, 0.6, 0.8])


def _surface_of(system) -> str:
    """A derived component when the system has one (its expression is the longest), else the last state one."""
    if system.derived:
        return f"{system.derived[0].name}1"
    return str(system.state_symbols[-1])


@pytest.mark.parametrize("kind", sorted(SUPPORTED_POTENTIALS))
def test_compiled_surface_rows_are_the_symbolic_expressions(kind):
    """δ = (value − S)/(∇S·f), f, ρ, S − value, the derived vectors, the integrals, their scales and
    Σ|∂S/∂x_i|·|v(i)|, from the heyoka compiled function, against sympy's own evaluation (numpy)."""
    system = get_system(kind, "zero")
    text = _surface_of(system)
    expr = parse_surface(system, text)
    kernels = _surface_kernels(system, expr)
    rng = np.random.default_rng(11)
    X = 0.4 * rng.normal(size=(24, system.dimension))
    p = rng.uniform(0.5, 2.0, size=len(system.parameter_symbols))
    value = 0.05
    runtime = taylor_system(system).runtime_parameters(p)
    got = kernels.evaluate(X, runtime, value)

    gradient = [sp.diff(expr, s) for s in system.state_symbols]
    norms = []
    for vec in system.state:
        norms += [sp.sqrt(sum(s**2 for s in vec.symbols))] * len(vec.symbols)
    exprs = [(value - expr) / sum(d * f for d, f in zip(gradient, system.rhs)), *system.rhs]
    exprs += [system.reduced_time.density] if system.reduced_time is not None else []
    exprs += [expr - value] + [e for vec in system.derived for e in vec.expression]
    exprs += [i.expression for i in system.integrals] + [i.scale for i in system.integrals]
    exprs.append(sum(sp.Abs(d) * norm for d, norm in zip(gradient, norms)))
    fn = sp.lambdify([*system.state_symbols, *system.parameter_symbols], exprs, modules="numpy")
    with np.errstate(all="ignore"):
        ref = np.stack([np.broadcast_to(np.asarray(v, dtype=float), (len(X),)) for v in fn(*X.T, *p)])
    assert got.shape == ref.shape
    finite = np.isfinite(ref)
    assert finite.mean() > 0.9
    scale = np.abs(ref) + 1e-6 * np.max(np.abs(ref[finite]))
    assert np.max(np.abs(got - ref)[finite] / scale[finite]) < 1e-11


def test_section_segments_cut_no_step():
    """With a progress to call, a section runs in segments of whole steps (a short first one, then about
    1 % of t_final); without, in one: the same steps, so the same crossings bit for bit."""
    calls: list[float] = []
    cut = section(BALL, P_BALL, Y_BALL, 1000.0, "gamma3", progress=lambda f: calls.append(f) or True)
    whole = section(BALL, P_BALL, Y_BALL, 1000.0, "gamma3")
    assert len(calls) >= 3 and cut.steps == whole.steps and cut.count == whole.count == 31
    assert np.array_equal(cut.t, whole.t) and np.array_equal(cut.tau, whole.tau)
    for name in ("M", "gamma", "omega"):
        assert np.array_equal(cut.points[name], whole.points[name])
    assert cut.integral_drift_max == whole.integral_drift_max


def test_short_runs_finished_together_keep_their_order_next_to_a_failure():
    """Twelve members on 4 lanes, one of them failing (γ four times too long: τ's density is not
    finite): the failing batch is finished on its own, the short runs together, every member in its
    place and equal to its own integration."""
    rng = np.random.default_rng(5)
    g = rng.normal(size=(12, 3))
    Y0 = np.hstack([0.5 * rng.normal(size=(12, 3)), g / np.linalg.norm(g, axis=1)[:, None]])
    P = np.repeat(P_BALL[None], 12, axis=0)
    P[:, 3] = np.linspace(0.3, 0.9, 12)
    bad = Y0.copy()
    bad[5, 3:] *= 4.0
    out = integrate_batch(BALL, P, bad, 30.0, 7)
    clean = integrate_batch(BALL, P, Y0, 30.0, 7)
    assert isinstance(out[5], IntegrationError)
    for i in (0, 1, 2, 3, 4, 6, 7, 8, 9, 10, 11):
        member, alone = out[i], integrate(BALL, P[i], bad[i], 30.0, 7)
        assert isinstance(member, Trajectory) and member.wall_time_s > 0
        assert (np.array_equal(member.states, clean[i].states)
                and np.array_equal(member.step_states, clean[i].step_states))
        assert np.array_equal(member.step_t, clean[i].step_t) and np.array_equal(member.tau, clean[i].tau)
        assert member.steps == alone.steps and member.step_states.shape == alone.step_states.shape
        assert np.max(np.abs(member.step_states - alone.step_states)) < 1e-13
        assert member.step_t[0] == 0.0 and member.step_t[-1] == 30.0 and np.all(np.diff(member.step_t) > 0)
