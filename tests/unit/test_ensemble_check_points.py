"""An ensemble's members are checked at equally spaced check points (heyoka's dense output inside
``propagate_grid``) instead of at every step (a Python step callback): the same samples and steps, check
points that are the trajectory's own states at those times, the integrals' drift there as large as at
the steps to within a factor 2, and the step log back when a batch is not finished in its first segment.
The speed is measured in bench/bench_ensemble.py, not here."""

from __future__ import annotations

import numpy as np
import pytest

from nonholonomic import get_system
from nonholonomic.analysis.ensemble import CHECK_POINTS, Member, run_chunk
from nonholonomic.evidence.integrals import integral_evidence_batch
from nonholonomic.numerics import integration
from nonholonomic.numerics.integration import IntegrationError, Trajectory, integrate
from nonholonomic.numerics.integration_batch import integrate_batch
from nonholonomic.numerics.kernels import parameter_vector

BALL = get_system("chaplygin_ball", "zero")
P_BALL = parameter_vector(BALL, {"inertia": [2.0, 3.0, 4.5], "D": 0.7})
T_FINAL = 40.0


def _states(count: int, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(count, 3))
    return np.hstack([rng.normal(size=(count, 3)), g / np.linalg.norm(g, axis=1)[:, None]])


def test_check_points_are_the_trajectorys_states_and_change_no_sample():
    Y0 = _states(10)
    P = np.repeat(P_BALL[None], len(Y0), axis=0)
    steps = integrate_batch(BALL, P, Y0, T_FINAL, 5)
    checked = integrate_batch(BALL, P, Y0, T_FINAL, 5, check_points=17)
    grid = np.linspace(0.0, T_FINAL, 17)
    for i, (a, b) in enumerate(zip(steps, checked)):
        assert isinstance(b, Trajectory)
        # the same steps, the same samples (dense output at the same times), bit for bit
        assert b.steps == a.steps and np.array_equal(b.states, a.states) and np.array_equal(b.tau, a.tau)
        assert np.array_equal(b.step_t, grid) and b.step_states.shape == (17, BALL.dimension)
        # the check points are the orbit's states at those times: an independent one-orbit integration
        alone = integrate(BALL, P[i], Y0[i], T_FINAL, 17)
        assert np.max(np.abs(b.step_states - alone.states)) < 1e-12 * max(1.0, np.abs(alone.states).max())


def test_the_drift_at_the_check_points_is_the_drift_at_the_steps_within_a_factor_two():
    """The check points see the integrals' error growth the step log sees (bench_ensemble: the worst
    energy drift over 1000 members 5.6e-15 against 5.8e-15)."""
    Y0 = _states(64, seed=11)
    P = np.repeat(P_BALL[None], len(Y0), axis=0)
    at_steps = integral_evidence_batch(BALL, P, integrate_batch(BALL, P, Y0, 100.0, 2))
    at_checks = integral_evidence_batch(BALL, P, integrate_batch(BALL, P, Y0, 100.0, 2, check_points=CHECK_POINTS))
    for k, claim in enumerate(BALL.integrals):
        steps = np.array([member[k].max_rel_drift for member in at_steps])
        checks = np.array([member[k].max_rel_drift for member in at_checks])
        assert 0.5 * steps.max() <= checks.max() <= 2.0 * steps.max(), claim.name  # rounding of the dense output
        assert steps.max() < 1e-13 and all(member[k].passed for member in at_checks)


def test_a_batch_not_done_in_its_first_segment_goes_on_with_the_step_log(monkeypatch):
    Y0 = _states(4, seed=2)
    P = np.repeat(P_BALL[None], len(Y0), axis=0)
    monkeypatch.setattr(integration, "FIRST_SEGMENT_STEPS", 16)  # every run is long
    out = integrate_batch(BALL, P, Y0, T_FINAL, 5, check_points=9)
    for i, member in enumerate(out):
        alone = integrate(BALL, P[i], Y0[i], T_FINAL, 5)
        assert member.steps == alone.steps > 16
        assert len(member.step_t) == alone.steps + 1  # the steps themselves, as a single job keeps them
        assert np.max(np.abs(member.states - alone.states)) < 1e-13 * max(1.0, np.abs(alone.states).max())


def test_a_failing_member_fails_alone_with_check_points():
    Y0 = _states(6, seed=4)
    bad = Y0.copy()
    bad[2, 3:] *= 4.0  # |γ| = 4: τ's density is not finite along the orbit
    P = np.repeat(P_BALL[None], len(Y0), axis=0)
    out = integrate_batch(BALL, P, bad, T_FINAL, 3, check_points=8)
    clean = integrate_batch(BALL, P, Y0, T_FINAL, 3, check_points=8)
    assert isinstance(out[2], IntegrationError)
    for i in (0, 1, 3, 4, 5):
        assert np.array_equal(out[i].states, clean[i].states)
        assert np.array_equal(out[i].step_states, clean[i].step_states)


@pytest.mark.parametrize("count", [0, 1])
def test_fewer_than_two_check_points_are_refused(count):
    with pytest.raises(ValueError, match="check_points"):
        integrate_batch(BALL, P_BALL[None], _states(1), T_FINAL, 3, check_points=count)


def test_an_ensemble_chunk_checks_its_members_at_the_check_points():
    Y0 = _states(5, seed=8)
    members = [Member(i, P_BALL, y) for i, y in enumerate(Y0)]
    results = run_chunk(BALL, members, T_FINAL, 2)
    for member in results:
        trajectory = member.result.trajectory
        assert np.array_equal(trajectory.step_t, np.linspace(0.0, T_FINAL, CHECK_POINTS))
        assert all(i.passed and i.max_rel_drift < 1e-13 for i in member.result.integrals)
