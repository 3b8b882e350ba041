"""The report's claims of the sections "Generalized Chaplygin systems" (Theorem 1, eq. 2704-9,
monopoles) and "Chaplygin's ball" (eq. 2604-1 … 2604-7, 001 … 007, Theorem 3)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
import sympy as sp

from nonholonomic import isomorphisms as iso
from nonholonomic.definition import dot
from nonholonomic.evidence.brackets import casimir_checks, jacobi_symbolic
from nonholonomic.evidence.measure import measure_evidence
from nonholonomic.hamiltonization import local_forms as lf
from nonholonomic.hamiltonization.forms import (
    flow_residual,
    hamiltonian_form,
    symbolic_flow_identity,
)
from nonholonomic.hamiltonization.poisson import chaplygin_ball_bracket, generalized_chaplygin_bracket
from nonholonomic.numerics.kernels import parameter_vector
from nonholonomic.report.common import (
    GAMMA0,
    INERTIA,
    A,
    D,
    evidence_check,
    integrals_check,
    map_checks,
    proof,
    run,
    trig_identity,
)
from nonholonomic.report.verdict import Check, Claim, Row, RowBuilder, claim_id
from nonholonomic.systems import chaplygin_ball as ball, get_system

GENERAL = "Generalized Chaplygin systems"
SECTION = "Chaplygin's ball"
LINEAR = {"inertia": INERTIA, "D": D, "a": A}
STATE: dict[str, Sequence[float]] = {"M": [0.5, -0.2, 0.1], "gamma": GAMMA0}
#: The ball's parameter symbols at the report's values.
BALL_VALUES = {ball.I1: INERTIA[0], ball.I2: INERTIA[1], ball.I3: INERTIA[2], ball.D: D}
#: Values for the ball's Euler-angle forms (c the constant of areas).
VALUES = {lf.I1: INERTIA[0], lf.I2: INERTIA[1], lf.I3: INERTIA[2], ball.D: D, lf.c: 0.35}


@claim_id("general.theorem_1")
def theorem_1() -> Row:
    claim = Claim(GENERAL, "Theorem 1: with N = rho (an invariant measure rho(q) dp dq), the "
                  "time-substituted system is Hamiltonian with the bracket (2704-9)", "Theorem 1, 2704-8, 2704-9",
                  printed="S_bar = B(q)", corrected="S_bar = N(q) B(q); the flow is dx/dtau = {x, H_bar}",
                  errata="ERRATA 6, 14")
    from nonholonomic.hamiltonization.theorem_1 import prove_theorem_1

    right, printed = prove_theorem_1("N*B"), prove_theorem_1("B")
    return Row(claim, [proof(*right)], printed_check=proof(*printed))


@claim_id("general.bracket")
def bracket_2704_9() -> Row:
    claim = Claim(GENERAL, "The bracket {q_i, p_j} = delta_ij, {p1, p2} = S_bar(q) satisfies "
                  "the Jacobi identity for any S_bar(q)", "2704-9")
    q, p = sp.symbols("q1 q2", real=True), sp.symbols("p1 p2", real=True)
    S_bar = sp.Function("S_bar")(*q)
    return Row(claim, [proof(*jacobi_symbolic(generalized_chaplygin_bracket(S_bar, q, p)))])


@lru_cache(maxsize=1)
def _ball_theorem_1():
    from nonholonomic.expressions import declare_symbols, parse_expression
    from nonholonomic.hamiltonization.local_forms import BALL_MONOPOLE_CHART
    from nonholonomic.hamiltonization.reducing_multiplier import hamiltonize

    spec = lf.chaplygin_ball_generalized_chaplygin()
    names = ["theta", "phi", "thetadot", "phidot", "I1", "I2", "I3", "D", "c", "N"]
    sym = declare_symbols(names)
    parsed = {k: parse_expression(spec[k], sym) for k in ("L", "a1", "a2", "b")}
    values = {sym["I1"]: INERTIA[0], sym["I2"]: INERTIA[1], sym["I3"]: INERTIA[2], sym["D"]: D, sym["c"]: 0.35}
    shift = tuple(parse_expression(w, sym) for w in BALL_MONOPOLE_CHART["shift"])
    result = hamiltonize(parsed["L"], (sym["theta"], sym["phi"]), (sym["thetadot"], sym["phidot"]),
                         parsed["a1"], parsed["a2"], parsed["b"], None, values,
                         domain=((0.0, np.pi), (0.0, 2 * np.pi)), shift=shift, multiplier_symbol=sym["N"])
    return result, sym, values


@claim_id("ball.multiplier")
def ball_multiplier() -> Row:
    claim = Claim(SECTION, "The ball in Euler angles (Routh form 003) is a generalized Chaplygin "
                  "system whose reducing multiplier is rho_mu", "003, 005, Theorem 1")
    result, sym, values = _ball_theorem_1()
    checks = [Check(result.measure_exists, None, None, "symbolic", f"integrability condition: "
                    f"{result.integrability_condition}"),
              Check(result.verification.get("passed"), result.verification.get("residual"), 1e-20,
                    result.verification.get("method", "pointwise"), str(result.verification.get("detail", ""))[:400])]
    if result.reducing_multiplier is not None:
        rho = ball.measure_density(lf.euler_gamma(sym["theta"], sym["phi"]))
        ratio = sp.lambdify((sym["theta"], sym["phi"]),
                            (result.reducing_multiplier / rho).subs({**values, **BALL_VALUES}), "numpy")
        r = np.array([ratio(t, f) for t, f in np.random.default_rng(0).uniform(0.2, 2.9, (20, 2))], dtype=float)
        spread = float(np.ptp(r) / np.mean(np.abs(r)))
        checks.append(Check.at_most(spread, 1e-12, "pointwise",
                                    f"N / rho_mu at 20 points: relative spread {spread:.2g}"))
    return Row(claim, checks)


@claim_id("general.monopole")
def monopole() -> Row:
    claim = Claim(GENERAL, "For the ball with c != 0 the gyroscopic 2-form S_bar dq1^dq2 is not "
                  "exact on the sphere (a monopole); for c = 0 it is", "text after 2704-9")
    from nonholonomic.hamiltonization.monopole import monopole_charge

    result, sym, values = _ball_theorem_1()
    if result.monopole is None or result.S_bar is None:
        return Row(claim, [Check(None, None, None, "numeric", f"Theorem 1 gave no S_bar: {result.reason}")])
    charge = result.monopole
    N = result.reducing_multiplier
    q = (sym["theta"], sym["phi"])
    zero = monopole_charge(result.S_bar, q, ((0.0, np.pi), (0.0, 2 * np.pi)), {**values, sym["c"]: 0.0},
                           symbolic=False)
    rho_pole = float(ball.measure_density(sp.Matrix([0, 0, 1])).subs(BALL_VALUES))
    k = float(N.subs(values).subs({sym["theta"]: 0, sym["phi"]: 0})) / rho_pole
    expected = -4 * np.pi * 0.35 * k / np.sqrt(np.prod(INERTIA))
    off = abs(charge["integral"] - expected) / abs(expected)
    return Row(claim, [
        Check.at_most(off, 1e-8, "numeric", f"charge = -4 pi c / sqrt(I1 I2 I3) to {off:.2g}"),
        Check(not charge["exact"], charge["integral"], None, "numeric",
              f"c = 0.35: integral of the smooth form (p~ = p - (0, c N cos theta)) = {charge['integral']:.10g}; "
              f"-4 pi c / sqrt(I1 I2 I3) = {expected:.10g} (relative difference {off:.2g}); the chart integral of "
              f"S_bar alone is {charge.get('integral_S_bar', float('nan')):.6g}"),
        Check(bool(zero["exact"]), zero["integral"], 1e-14, "numeric", f"c = 0: integral {zero['integral']:.3g}")])


@claim_id("ball.integrals")
def integrals() -> Row:
    claim = Claim(SECTION, "Energy, the geometric integral and the area integral (M, gamma) are "
                  "conserved for any U(gamma)", "2604-2")
    return Row(claim, [integrals_check(run("chaplygin_ball", "linear", LINEAR, STATE))])


@claim_id("ball.measure")
def measure() -> Row:
    claim = Claim(SECTION, "rho_mu = det(I_Q)^(-1/2) is an invariant density (Chaplygin)", "2604-3")
    result = run("chaplygin_ball", "linear", LINEAR, STATE)
    return Row(claim, [evidence_check(i) for i in measure_evidence(result.system, result.parameters,
                                                                   result.trajectory.states)])


@claim_id("ball.F")
def integral_F() -> Row:
    claim = Claim(SECTION, "For U = 0, F = (M, M) is conserved", "2604-4")
    return Row(claim, [integrals_check(run("chaplygin_ball", "zero", {"inertia": INERTIA, "D": D}, STATE), ["F"])])


@claim_id("ball.bracket")
def bracket() -> Row:
    claim = Claim(SECTION, "The bracket (2604-6) satisfies the Jacobi identity for any J, D; its "
                  "Casimirs are gamma^2 and (L, gamma) / rho_mu", "2604-6")
    ps = chaplygin_ball_bracket()
    checks = [proof(*jacobi_symbolic(ps))]
    checks += [proof(v, f"Casimir {name}: {detail}") for name, v, detail in casimir_checks(ps)]
    return Row(claim, checks)


@claim_id("ball.hamiltonian")
def hamiltonian_form_row() -> Row:
    claim = Claim(SECTION, "After rho_mu dt = d tau, L = rho_mu M, the flow is dx/dtau = {H, x} "
                  "with the bracket (2604-6) and H (2604-7), for any U(gamma)", "2604-5, 2604-6, 2604-7",
                  printed="'dM_k/dtau = {H, M_k}', 'the energy (2504-2)'",
                  corrected="dL_k/dtau = {H, L_k}; the energy (2604-2)", errata="ERRATA 5 (a reading)")
    system = get_system("chaplygin_ball", "linear")
    form = hamiltonian_form(system)
    assert form is not None
    result = run("chaplygin_ball", "linear", LINEAR, STATE)
    res = flow_residual(form, system, result.trajectory.states, result.parameters)
    control = flow_residual(form, system, result.trajectory.states, result.parameters, time="t")
    return Row(claim, [proof(*symbolic_flow_identity(form, system)),
                       Check.at_most(res, 1e-12, "pointwise", f"along t <= 100: {res:.2g}"),
                       Check(control > 1e-6, control, 1e-6, "pointwise",
                             f"control: in the original time t the same bracket misses the flow by {control:.3g}")])


@claim_id("ball.local_forms")
def local_forms() -> Row:
    claim = Claim(SECTION, "In Euler angles: the momenta L(p_theta, p_phi) give L = rho_mu M, and H(theta, phi, p) "
                  "is the energy, along a trajectory", "003, 004, theorem after 007")
    result = run("chaplygin_ball", "linear", LINEAR, STATE)
    return Row(claim, [evidence_check(i) for i in lf.local_form_evidence(result.system, result.parameters,
                                                                         result.trajectory.states)])


@claim_id("ball.S_bar")
def s_bar_007() -> Row:
    claim = Claim(SECTION, "With N = rho_mu the reduced gyroscopic term S_bar depends on q only and is "
                  "eq. 007", "003, 007", corrected="S_bar of eq. 2704-8 is -S_bar(007): eq. 003 and 007 write "
                  "-phidot S on the theta equation, the opposite sign of eq. 2704-7", errata="sign convention (new)")
    g = lf.euler_gamma()
    Delta = ball.contact_inertia_determinant(g)
    over_n = lf.reduced_gyroscopic_term_over_multiplier(lf.ball_routh_function(), lf.ball_gyroscopic_term(), Delta)
    B = over_n.subs({v: 0 for v in lf.QDOT})
    n = lf.ball_reducing_multiplier()
    S_007 = lf.ball_S_bar_printed(n) / n
    q = (lf.theta, lf.phi)
    values = {**VALUES, lf.thetadot: 0.3, lf.phidot: -0.7}
    return Row(claim, [trig_identity(sp.diff(over_n, v), q, values, f"d(S_bar/N)/d{v} (Theorem 1, statement 1)")
                       for v in lf.QDOT] + [trig_identity(B + S_007, q, values, "S_bar/N + S_bar(007)/N")])


@claim_id("ball.H_angles")
def hamiltonian_in_angles() -> Row:
    claim = Claim(SECTION, "The Hamiltonian in (theta, phi, p_theta, p_phi) equals the energy "
                  "1/2 (L, adj(I_Q) L) with L = L(p)", "theorem after 007",
                  printed="H with the printed coefficients of p_theta^2, p_phi^2, p_theta p_phi, c p_phi, c^2",
                  corrected=("H = 1/2 p_theta^2 (I3 I12 + D G) "
                             "+ 1/2 (p_phi^2 / sin^2) (I1 I2 sin^2 + I3 I21 cos^2 + D G)"
                             " + ... (ERRATA 7)"), errata="ERRATA 7")
    IQ = ball.contact_inertia(lf.euler_gamma())
    L = lf.ball_L_from_momenta()
    half_adj = (L.T * IQ.adjugate() * L)[0] / 2
    values = {**VALUES, lf.p_theta: 0.4, lf.p_phi: -0.3, lf.N: 0.8}
    q = (lf.theta, lf.phi)
    return Row(claim, [trig_identity(lf.ball_hamiltonian() - half_adj, q, values, "H - 1/2 (L, adj(I_Q) L)")],
               printed_check=trig_identity(lf.ball_hamiltonian_printed() - half_adj, q, values,
                                           "H(printed) - 1/2 (L, adj(I_Q) L)"))


@claim_id("ball.theorem_3")
def theorem_3() -> Row:
    claim = Claim(SECTION, "Theorem 3: for U = 0, (M, gamma) = 0, the ball after the time "
                  "substitution is the Clebsch case", "theorem after 2604-7",
                  printed="s = (gamma, B gamma)^(-1/2) B^(-1/2) gamma",
                  corrected=("s = (gamma, B gamma)^(-1/2) B^(1/2) gamma, L~ = B^(-1/2) L, B = I J^-1; Clebsch with "
                             "I -> B, alpha = -beta = det J / D, k = +sqrt(det B), c = L^2 (gamma, B gamma) / det B"),
                  errata="ERRATA 8")
    m = iso.get_map("chaplygin_ball_to_clebsch")
    p = parameter_vector(m.source, {"inertia": INERTIA, "D": D})
    Bd = [ball.I1 / (ball.I1 + ball.D), ball.I2 / (ball.I2 + ball.D), ball.I3 / (ball.I3 + ball.D)]
    g = ball.gamma
    s_printed = sp.diag(*[b ** sp.Rational(-1, 2) for b in Bd]) * g / sp.sqrt(dot(g, sp.diag(*Bd) * g))
    printed = dataclasses.replace(m, forward=tuple(s_printed) + m.forward[3:])
    wrong = iso.push_forward_residual(printed, p, iso.sample_states(m, p, 50))
    return Row(claim, map_checks("chaplygin_ball_to_clebsch", {"inertia": INERTIA, "D": D}),
               printed_check=Check.at_most(wrong, iso.PUSH_FORWARD_TOLERANCE, "pointwise",
                                           f"push-forward residual with the printed B^(-1/2): {wrong:.3g}"))


ROWS: list[RowBuilder] = [theorem_1, bracket_2704_9, monopole, integrals, measure, integral_F, bracket,
                                 hamiltonian_form_row, ball_multiplier, local_forms, s_bar_007, hamiltonian_in_angles,
                                 theorem_3]
