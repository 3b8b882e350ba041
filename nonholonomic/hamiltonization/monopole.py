"""Monopoles (text after eq. 2704-9): the chart integral of the gyroscopic 2-form S̄ dq₁∧dq₂.

A smooth closed 2-form on a compact surface is exact iff its integral vanishes; :func:`monopole_charge`
integrates it over an angle chart (scipy's ``dblquad``, and sympy's exact integral for forms of at most
:data:`SYMBOLIC_INTEGRAL_MAX_OPS` operations, run to its end). Part of Theorem 1's result
(:func:`nonholonomic.hamiltonization.reducing_multiplier.hamiltonize`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import sympy as sp

from nonholonomic import bounded
from nonholonomic.numerics.precision import working_digits
from nonholonomic.work_limits import operations, over

#: Largest 2-form (sympy operation count) for which monopole_charge tries sympy's exact integral: sympy's
#: ``integrate`` does not return on larger ones such as the ball's S_bar (a deterministic gate, decided
#: before the integral starts).
SYMBOLIC_INTEGRAL_MAX_OPS = 40


def _symbolic_area_integral(S_bar: sp.Expr, q: tuple[sp.Symbol, sp.Symbol],
                            domain: tuple[tuple[sp.Expr, sp.Expr], tuple[sp.Expr, sp.Expr]]) -> sp.Expr | None:
    (a, b), (c, d) = domain
    value = sp.integrate(S_bar, (q[1], c, d), (q[0], a, b))
    return None if value.has(sp.Integral) else value


def monopole_charge(S_bar: sp.Expr, q: tuple[sp.Symbol, sp.Symbol],
                    domain: tuple[tuple[float, float], tuple[float, float]],
                    parameters: Mapping[sp.Symbol, float] | None = None, symbolic: bool = True,
                    shift: tuple[sp.Expr, sp.Expr] | None = None) -> dict[str, Any]:
    """∫ S̄ dq₁∧dq₂ over the chart ``domain`` (text after eq. 2704-9).

    If the chart covers a compact surface up to a set of measure zero (Euler angles θ ∈ (0, π),
    φ ∈ (0, 2π) on S²) and S̄ dq₁∧dq₂ is a smooth 2-form there, it is exact iff its integral is 0;
    if not, the generalized potential W (dW = Ω) has singularities (monopoles) and no global
    canonical form exists.

    Smoothness is the catch in angle charts: if the momenta p are not smooth fibre coordinates of
    T*M (e.g. after a Routh reduction they differ from them by a potential W(q) singular at the
    poles, a Dirac string), the smooth gyroscopic form belongs to p̃ = p − W, for which eq. (2704-9)
    gives {p̃₁, p̃₂} = S̄ + ∂W₂/∂q₁ − ∂W₁/∂q₂. Pass ``shift=(W₁, W₂)`` to integrate that form instead;
    the chart integral of S̄ alone is then reported as ``"integral_S_bar"``.

    Parameters
    ----------
    S_bar : S̄(q) of the bracket (2704-9).
    q : (q₁, q₂).
    domain : ((q₁ min, q₁ max), (q₂ min, q₂ max)); multiples of π are recognised for sympy.
    parameters : values of every other symbol.
    symbolic : try sympy's exact integral too (run to its end; only for a form of at most
        :data:`SYMBOLIC_INTEGRAL_MAX_OPS` operations, else the detail says it was not tried).
    shift : (W₁, W₂) with p̃ = p − W smooth fibre coordinates, or None.

    Returns
    -------
    dict
        ``{"integral": float, "exact": bool, "detail": str}`` plus ``"absolute_integral"`` (of
        |form|, the scale of "zero"), ``"error_estimate"``, ``"form"`` (the integrand), and
        ``"symbolic"`` if sympy found the integral.

    Raises
    ------
    ValueError
        If a symbol other than q has no value.
    nonholonomic.bounded.SafetyCapExceeded
        If sympy's integral outlives the service's safety cap (a failure, not a verdict).
    """
    from scipy.integrate import dblquad

    par = {sp.sympify(k): float(val) for k, val in (parameters or {}).items()}
    S_bar = sp.sympify(S_bar)
    form = S_bar
    if shift is not None:
        W1, W2 = (sp.sympify(x) for x in shift)
        form = S_bar + sp.diff(W2, q[0]) - sp.diff(W1, q[1])
    missing = form.free_symbols - set(q) - set(par)
    if missing:
        raise ValueError(f"S_bar has symbols without a value: {', '.join(sorted(map(str, missing)))}")
    (a, b), (c, d) = [(float(lo), float(hi)) for lo, hi in domain]

    def integrate(expr: sp.Expr) -> tuple[float, float, float]:
        names = sorted(expr.free_symbols - set(q), key=str)
        f = sp.lambdify(list(q) + names, expr, modules="numpy")
        values = [par[s] for s in names]
        # dblquad integrates func(y, x) with x outer: outer q₁, inner q₂
        value, err = dblquad(lambda y, x: float(f(x, y, *values)), a, b, c, d, epsabs=1e-13, epsrel=1e-11)
        absolute, _ = dblquad(lambda y, x: abs(float(f(x, y, *values))), a, b, c, d, epsabs=1e-13, epsrel=1e-9)
        return value, absolute, err

    value, absolute, err = integrate(form)
    exact = bool(abs(value) <= 1e-9 * absolute + 1e-14)
    what = "S_bar" if shift is None else "S_bar + dW2/dq1 - dW1/dq2"
    out: dict[str, Any] = {
        "integral": float(value), "exact": exact, "absolute_integral": float(absolute), "error_estimate": float(err),
        "form": sp.sstr(form),
        "detail": (f"integral of ({what}) d{q[0]} d{q[1]} over {q[0]} in ({a:g}, {b:g}), {q[1]} in ({c:g}, {d:g}) "
                   f"by scipy dblquad = {value:.12g} (its absolute value integrates to {absolute:.6g}); if the chart "
                   "covers a compact surface (e.g. Euler angles on S^2) and the form is smooth there, the closed "
                   "2-form is exact iff the integral is 0: "
                   + ("exact, a global generalized potential W exists" if exact else
                      "not exact: W has singularities (monopoles), no global canonical Hamiltonian form")),
    }
    if shift is not None:
        out["integral_S_bar"] = float(integrate(S_bar)[0])
        out["detail"] += (f"; the chart integral of S_bar alone is {out['integral_S_bar']:.12g} (the momenta p differ "
                          "from smooth fibre coordinates by W)")
    if not symbolic:
        return out
    skipped = over(operations(form), SYMBOLIC_INTEGRAL_MAX_OPS, "SYMBOLIC_INTEGRAL_MAX_OPS", "sympy's exact integral")
    if skipped is not None:
        # sympy's integrate does not return on large forms (the ball's S_bar): decided by size, not started
        out["detail"] += f"; {skipped}"
        return out
    with working_digits(15):  # nsimplify sets mpmath's global precision: take turns with other threads
        exact_domain = tuple(tuple(sp.nsimplify(x, [sp.pi]) for x in pair) for pair in domain)
    # identical calls share one computation, cached per process (nonholonomic.bounded)
    outcome = bounded.run(("monopole", "symbolic_area_integral", (form, q, exact_domain)), _symbolic_area_integral,
                          (form, q, exact_domain))
    if outcome.status == "done" and outcome.value is not None:
        out["symbolic"] = sp.sstr(outcome.value)
        out["detail"] += f"; sympy: {sp.sstr(outcome.value)}"
    return out

