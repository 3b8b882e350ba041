"""mpmath's precision per thread (nonholonomic/numerics/precision.py).

sympy 1.14 sets mpmath's global precision in places (``nsimplify`` sets ``mp.dps = 15`` and restores what it
found). With one global precision, a thread's ``nsimplify`` dropped another thread to 15 digits in the middle of
its 50-digit identity test (Theorem 1's field comparison, compared at 1e-40), and a proven Hamiltonization came
out ``undecided`` in embedded mode with several jobs running (issue 31's same-answer test, failed in CI). Here
the two threads interleave step by step (events, no timing) and each must keep the precision it set.
"""

from __future__ import annotations

import subprocess
import sys
import threading

import mpmath
import sympy as sp

from nonholonomic.numerics.precision import installed, working_digits

#: Hang guard (seconds) of the waits between the two threads; never a result.
GUARD_S = 30.0


def _thirty_digits_below_one_survive() -> bool:
    tiny = (mpmath.mpf(1) + mpmath.mpf(10) ** -30) - 1
    return bool(abs(tiny - mpmath.mpf(10) ** -30) < mpmath.mpf(10) ** -45)


def test_importing_the_core_makes_the_precision_per_thread():
    assert installed()
    out = subprocess.run([sys.executable, "-c", "import nonholonomic, mpmath; "
                          "from nonholonomic.numerics.precision import installed; print(installed(), mpmath.mp.dps)"],
                         capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split() == ["True", "15"]


def test_another_threads_precision_change_does_not_reach_this_thread():
    # what sympy's nsimplify does in the other thread: remember, set 15 digits, compute, restore
    entered, changed, restored = threading.Event(), threading.Event(), threading.Event()
    seen: dict[str, object] = {}

    def other() -> None:
        assert entered.wait(GUARD_S)
        seen["start"] = mpmath.mp.dps  # a new thread starts at mpmath's default, whatever this one set
        orig = mpmath.mp.dps
        mpmath.mp.dps = 15
        seen["third"] = mpmath.mpf(1) / 3
        changed.set()
        assert restored.wait(GUARD_S)
        mpmath.mp.dps = orig

    thread = threading.Thread(target=other)
    thread.start()
    with working_digits(50):
        entered.set()
        assert changed.wait(GUARD_S)
        assert mpmath.mp.dps == 50 and mpmath.mp.prec == 169
        assert _thirty_digits_below_one_survive()
        third = mpmath.mpf(1) / 3
        restored.set()
    thread.join(GUARD_S)
    assert seen["start"] == 15
    assert abs(third - mpmath.mpf(1) / 3) == 0 or abs(third * 3 - 1) < mpmath.mpf(10) ** -49
    with working_digits(50):
        assert abs(seen["third"] * 3 - 1) > mpmath.mpf(10) ** -20  # the other computed at 15 digits
    # nothing leaked: the other thread restored 15 in itself, this thread left its block at 15
    assert mpmath.mp.dps == 15 and not _thirty_digits_below_one_survive()


def test_sympys_evalf_in_another_thread_leaves_a_50_digit_identity_test_alone():
    # sympy evaluates a function under mpmath.workprec (Function._eval_evalf): the other thread pauses there
    inside, checked = threading.Event(), threading.Event()
    seen: dict[str, object] = {}

    def pause(x: mpmath.mpf) -> mpmath.mpf:
        seen["other"] = mpmath.mp.prec  # the precision sympy set for this evaluation
        inside.set()
        assert checked.wait(GUARD_S)
        return x

    class Pausing(sp.Function):
        def _eval_mpmath(self):  # type: ignore[no-untyped-def]  # sympy's hook: mpmath's function and arguments
            return pause, self.args

    thread = threading.Thread(target=lambda: seen.setdefault("value", Pausing(sp.Rational(1, 3)).evalf(15)))
    results: list[object] = []
    with working_digits(50):
        thread.start()
        assert inside.wait(GUARD_S)
        results += [mpmath.mp.dps, _thirty_digits_below_one_survive()]
        checked.set()
    thread.join(GUARD_S)
    assert 53 <= seen["other"] < 64 and results == [50, True]  # 15 digits and sympy's guard bits; 50 here
    assert abs(seen["value"] - sp.Rational(1, 3)) < 1e-15
    assert mpmath.mp.dps == 15


def test_mpmath_functions_and_lambdified_expressions_use_the_calling_threads_precision():
    x = sp.Symbol("x")
    f = sp.lambdify(x, sp.sin(x) ** 2 + sp.cos(x) ** 2 - 1 + sp.exp(-x) * sp.Rational(1, 10**30), modules="mpmath")
    values: dict[int, object] = {}

    def at(digits: int) -> None:
        with working_digits(digits):
            values[digits] = f(mpmath.mpf(1) / 7)

    threads = [threading.Thread(target=at, args=(d,)) for d in (15, 60)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(GUARD_S)
    with working_digits(60):
        expected = mpmath.exp(-mpmath.mpf(1) / 7) * mpmath.mpf(10) ** -30
        assert abs(values[60] - expected) < mpmath.mpf(10) ** -55  # sin^2 + cos^2 - 1 cancelled to 60 digits
    assert values[60]._mpf_[1].bit_length() > 150  # the mantissa of a 60-digit number: 200 bits
    assert values[15]._mpf_[1].bit_length() <= 53  # the other thread's: a double's
