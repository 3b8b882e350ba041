"""Every long loop of the computation core asks ``progress`` within bounded work (issue 19, items 3, 11
and 13): a cancellation or a time limit acts inside heyoka's propagations, and a Poincaré surface that
is not smooth where the orbit meets it (heyoka's steps shrink to nothing there) ends with a clear error
instead of running forever."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from nonholonomic.analysis import lyapunov
from nonholonomic.analysis.lyapunov import spectrum
from nonholonomic.analysis.poincare import section, section_batch
from nonholonomic.numerics.integration import IntegrationCancelled, IntegrationError
from nonholonomic.systems import get_system

BALL = get_system("chaplygin_ball", "zero")
P = np.array([2.0, 3.0, 4.5, 0.7])
Y0 = np.array([0.5, -0.2, 0.1, 0.0, 0.6, 0.8])
#: Hang guard (seconds) of a call that never returned before the fix.
GUARD_S = 120.0


def _within_guard(call):
    """``call()`` in a daemon thread: its result or exception, or a failure if it runs past the guard."""
    out: dict[str, object] = {}

    def run() -> None:
        try:
            out["value"] = call()
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            out["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(GUARD_S)
    if thread.is_alive():
        pytest.fail(f"hang guard: still running after {GUARD_S:g} s")
    if "error" in out:
        raise out["error"]  # type: ignore[misc]
    return out["value"]


@pytest.mark.parametrize("surface, at", [("sqrt(gamma1)", "t = 0"), ("sqrt(gamma1 + 0.3)", "t = 29.48")])
def test_a_surface_not_smooth_where_the_orbit_meets_it_ends_with_a_clear_error(surface, at):
    with pytest.raises(IntegrationError, match="the surface is not finite or not smooth where the orbit meets it") as e:
        _within_guard(lambda: section(BALL, P, Y0, 100.0, surface))
    assert at in str(e.value)


def test_a_stalled_lane_of_a_batch_fails_alone():
    other = np.array([0.5, -0.2, 0.1, 0.6, 0.0, 0.8])  # gamma1 stays clear of 0 long enough
    out = _within_guard(lambda: section_batch(BALL, np.tile(P, (2, 1)), np.stack([Y0, other]), 5.0, "sqrt(gamma1)"))
    assert isinstance(out[0], IntegrationError) and "not smooth" in str(out[0])
    assert not isinstance(out[1], Exception)


def test_a_section_is_cancelled_inside_a_long_segment():
    calls: list[float] = []

    def cancel_at_once(fraction: float) -> bool:
        calls.append(fraction)
        return False

    # t_final 1e7: the first segment (1 % of t_final) alone is ~2e6 steps, minutes before the fix
    with pytest.raises(IntegrationCancelled):
        _within_guard(lambda: section(BALL, P, Y0, 1e7, "gamma3", max_points=100_000, progress=cancel_at_once))
    assert len(calls) == 1 and calls[0] < 0.01


def test_a_spectrum_asks_progress_inside_one_long_qr_interval():
    calls: list[float] = []

    def cancel_at_once(fraction: float) -> bool:
        calls.append(fraction)
        return False

    with pytest.raises(IntegrationCancelled):
        _within_guard(lambda: spectrum(BALL, P, Y0, 1e6, interval=1e6, progress=cancel_at_once))
    assert len(calls) == 1 and calls[0] < 0.01


def test_cutting_a_qr_interval_into_pieces_changes_no_number(monkeypatch):
    pieces = spectrum(BALL, P, Y0, 2000.0, interval=1000.0)
    monkeypatch.setattr(lyapunov, "PIECE_STEPS", 10**9)  # one propagation per interval
    whole = spectrum(BALL, P, Y0, 2000.0, interval=1000.0)
    assert np.array_equal(pieces.exponents, whole.exponents) and pieces.steps == whole.steps
