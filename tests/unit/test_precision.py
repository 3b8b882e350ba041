"""mpmath's precision is one global of the process (nonholonomic/numerics/precision.py): a thread that asks for
50 digits keeps them while another thread asks for 15, because :func:`working_digits` makes them take turns.
With ``mpmath.workdps`` alone the second thread's entry set 15 digits for both, and a 50-digit identity test in
the first (Theorem 1's field comparison) failed: the same request answered "undecided" under load."""

from __future__ import annotations

import threading

import mpmath

from nonholonomic.numerics.precision import working_digits

#: Hang guard (seconds) of the waits between the two threads; never a result.
GUARD_S = 30.0


def test_a_thread_keeps_its_digits_while_another_asks_for_fewer():
    other_trying, other_inside = threading.Event(), threading.Event()
    seen: dict[str, object] = {}

    def fewer_digits() -> None:
        other_trying.set()
        with working_digits(15):
            other_inside.set()
            seen["other"] = mpmath.mp.dps

    with working_digits(50):
        thread = threading.Thread(target=fewer_digits)
        thread.start()
        assert other_trying.wait(GUARD_S)
        # the other thread now waits for its turn: given time, it still has not changed the precision
        assert not other_inside.wait(0.3)
        assert mpmath.mp.dps == 50
        tiny = (mpmath.mpf(1) + mpmath.mpf(10) ** -30) - 1
        assert abs(tiny - mpmath.mpf(10) ** -30) < mpmath.mpf(10) ** -45  # 30 digits below 1 are still there
    thread.join(GUARD_S)
    assert seen["other"] == 15 and mpmath.mp.dps == 15
