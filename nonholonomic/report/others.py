"""The report's claims of the sections "Chaplygin's ball with the Veselova constraint" (and the
rubber ball), "Nonholonomic Jacobi problem" (the ball on a surface) and the Kirchhoff targets
(Neumann, Clebsch)."""

from __future__ import annotations

import dataclasses

import numpy as np
import sympy as sp

from nonholonomic.definition import FirstIntegral, dot
from nonholonomic.evidence.integrals import integral_evidence
from nonholonomic.evidence.measure import measure_evidence, symbolic_divergence_vanishes
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import parameter_vector, state_vector
from nonholonomic.report.common import (
    INERTIA,
    D,
    evidence_check,
    example,
    integrals_check,
    map_checks,
    proof,
    run,
)
from nonholonomic.report.verdict import Check, Claim, Row, RowBuilder, claim_id
from nonholonomic.systems import ball_on_quadric as bq, chaplygin_ball as cb, chaplygin_ball_veselova as bv, get_system

VESELOVA_BALL = "Chaplygin's ball with the Veselova constraint"
JACOBI = "Nonholonomic Jacobi problem"
KIRCHHOFF = "Kirchhoff equations: Neumann and Clebsch"


def _example_run(kind: str, t_final: float = 100.0):
    potential, parameters, state = example(kind)
    return run(kind, potential, parameters, state, t_final=t_final)


@claim_id("veselova_ball.multiplier")
def veselova_ball_multiplier() -> Row:
    claim = Claim(VESELOVA_BALL, "The multiplier mu keeps the Veselova constraint "
                  "(omega, E) = 0", "after 2704-4", printed="numerator with I^-1 E",
                  corrected="mu = -(I omega x omega + M_Q, I_Q^-1 E) / (E, I_Q^-1 E)", errata="ERRATA 9")
    potential, parameters, state = example("chaplygin_ball_veselova")
    right = bv.define(potential)
    U = sp.Integer(0) if potential == "zero" else right.integrals[0].expression.xreplace(
        {s: 0 for s in bv.omega})
    inertia_inv = sp.diag(1 / bv.I1, 1 / bv.I2, 1 / bv.I3)
    printed_mu = -dot(bv.free_torque(U), inertia_inv * bv.E) / dot(bv.E, cb.contact_inertia_inverse(bv.gamma) * bv.E)
    printed = dataclasses.replace(right, rhs=bv.equations_of_motion(U, printed_mu))
    p = parameter_vector(right, parameters)
    y0 = state_vector(right, dict(state), p)
    drift = {}
    for name, system, engine in (("derived", right, "heyoka"), ("printed", printed, "scipy")):
        traj = integrate(system, p, y0, 5.0, 51, engine=engine)
        drift[name] = float(np.max(np.abs(np.einsum("ij,ij->i", traj.states[:, :3], traj.states[:, 6:]))))
    what = "max |(omega, E)| over t in [0, 5] from the catalog example"
    return Row(claim, [Check.at_most(drift["derived"], 1e-12, "trajectory", f"{what}: {drift['derived']:.2g}")],
               printed_check=Check.at_most(drift["printed"], 1e-12, "trajectory", f"{what}: {drift['printed']:.2g}"))


@claim_id("veselova_ball.integrals")
def veselova_ball_integrals() -> Row:
    claim = Claim(VESELOVA_BALL, "Energy, F1 = (K, E x gamma), F2 = (K, E x (E x gamma)) "
                  "and the geometric relations are conserved", "2704-4, 2704-6")
    return Row(claim, [integrals_check(_example_run("chaplygin_ball_veselova"))])


@claim_id("veselova_ball.measure")
def veselova_ball_measure() -> Row:
    claim = Claim(VESELOVA_BALL, "The density (2704-5) is invariant", "2704-5")
    result = _example_run("chaplygin_ball_veselova")
    return Row(claim, [evidence_check(i) for i in measure_evidence(result.system, result.parameters,
                                                                   result.trajectory.states)])


@claim_id("rubber_ball.veselova")
def rubber_ball() -> Row:
    claim = Claim(VESELOVA_BALL, "The rubber ball (E = gamma) is Veselova's system with "
                  "I -> J = I + D 1", "rubber-ball paragraph", printed="I_Q omega' = J omega - D (omega', gamma) gamma",
                  corrected="I_Q omega' = J omega' - D (omega', gamma) gamma", errata="ERRATA 10 (a reading)")
    return Row(claim, map_checks("rubber_ball_to_veselova", {"inertia": INERTIA, "D": D}))


@claim_id("jacobi.energy")
def quadric_energy() -> Row:
    claim = Claim(JACOBI, "The ball on a surface conserves the energy H = 1/2 (D0 + D) omega^2 - "
                  "1/2 D (omega, n)^2 + U", "2804-1, 2804-2", printed="torque +R n x dU/dx",
                  corrected="(D0 + m R^2) omega' = m R^2 (omega, n) n' - R n x dU/dx", errata="ERRATA 11")
    _, parameters, state = example("ball_on_quadric")
    right = bq.define("linear")
    a = sp.Matrix(sp.symbols("a1:4", real=True))
    wrong = dataclasses.replace(right, rhs=bq.equations_of_motion(a.dot(bq.x), torque=bq.R ** 3))
    p = parameter_vector(right, {**parameters, "a": [0.3, -0.2, 0.5]})
    y0 = state_vector(right, dict(state), p)
    drift = {}
    for name, system, engine in (("derived", right, "heyoka"), ("printed", wrong, "scipy")):
        energy = {i.name: i for i in integral_evidence(system, p, integrate(system, p, y0, 20.0, 101, engine=engine))}
        drift[name] = energy["energy"]
    return Row(claim, [Check(drift["derived"].passed, drift["derived"].max_rel_drift, drift["derived"].tolerance,
                             "trajectory",
                             f"energy drift over t = 20, U = (a, x): {drift['derived'].max_rel_drift:.2g}")],
               printed_check=Check(drift["printed"].passed, drift["printed"].max_rel_drift, drift["printed"].tolerance,
                                   "trajectory", f"with the printed torque: {drift['printed'].max_rel_drift:.3g}"))


@claim_id("jacobi.energy_coefficient")
def quadric_energy_coefficient() -> Row:
    claim = Claim(JACOBI, "The energy's (omega, n)^2 term", "2804-2",
                  printed="1/2 mu (omega, n)^2 (mu = D0)", corrected="1/2 D (omega, n)^2, D = m R^2",
                  errata="ERRATA 12")
    result = _example_run("ball_on_quadric", 20.0)
    wrong = dataclasses.replace(result.system, integrals=(FirstIntegral(
        "energy", bq.energy(sp.Integer(0), coefficient=bq.D0), sp.Integer(1), "printed", "2804-2"),))
    (printed,) = integral_evidence(wrong, result.parameters, result.trajectory)
    return Row(claim, [integrals_check(result, ["energy"])],
               printed_check=Check(printed.passed, printed.max_rel_drift, printed.tolerance, "trajectory",
                                   f"energy with D0: drift {printed.max_rel_drift:.3g}"))


@claim_id("jacobi.measure")
def quadric_measure() -> Row:
    claim = Claim(JACOBI, "The flow has the invariant measure |grad Phi| d^3omega d^3x", "2804-3",
                  printed="the density read on the 4-dimensional phase space (rho = 1 there)",
                  corrected="|grad Phi| for d^3omega d^3x of the 6-dimensional ambient field", errata="ERRATA 13")
    result = _example_run("ball_on_quadric")
    right = [evidence_check(i) for i in measure_evidence(result.system, result.parameters, result.trajectory.states)]
    refuted, detail = symbolic_divergence_vanishes(result.system, sp.Integer(1))
    return Row(claim, right, printed_check=proof(refuted, f"rho = 1: {detail}"))


@claim_id("jacobi.K")
def quadric_K() -> Row:
    claim = Claim(JACOBI, "K = (omega x n, B^-1 omega x n) / (n, B n) is conserved, and extends to "
                  "U = k x^2 / 2", "2804-4")
    _, parameters, state = example("ball_on_quadric")
    checks = [integrals_check(_example_run("ball_on_quadric"), ["K"]),
              integrals_check(run("ball_on_quadric", "harmonic", {**parameters, "k": 0.8}, state), ["K"])]
    return Row(claim, checks, note="the c_i / x_i^2 terms of the extended potential are not implemented")


#: The quadric, level and states of the separatrix probe of bench/science.py (docs/science.md, study 1):
#: B = (1, 2, 3), (H, K) = (0.5, 2), section x2 = 0; the states lie on the symmetric line omega2 = 0,
#: 1e-4 on either side of the separatrix theta* = -0.3359 found by bisection there, and 1e-2 beside it.
CHAOS_PARAMETERS = {"D0": 0.036, "m": 1.0, "R": 0.3, "B": [1.0, 2.0, 3.0]}
CHAOS_LAYER_STATES = (
    {"x": [0.9440754845057774, 0.0, -0.5711080796710419], "omega": [3.9016463418908547, 0.0, 1.3317219904655078]},
    {"x": [0.9441414115064182, 0.0, -0.5707810309006467], "omega": [3.90164802480612, 0.0, 1.3320791681582551]},
)
CHAOS_REGULAR_STATE = {"x": [0.9407649526919554, 0.0, -0.5872681766957146],
                       "omega": [3.901389546771132, 0.0, 1.314121401481255]}
#: Tangent vectors grow like t^p: p = 1 on an invariant torus (linear shear), p >> 1 when they grow
#: exponentially; above this the orbit counts as chaotic.
CHAOS_GROWTH = 3.0
CHAOS_T_FINAL = 4000.0


def tangent_growth_power(system, p: np.ndarray, y0: np.ndarray, t_final: float) -> tuple[float, float]:
    """The largest Lyapunov exponent at ``t_final`` and the power p of |v(t)| ~ t^p of the tangent
    vector over [t_final/30, t_final] (the slope of λ(t)·t = ln|v| against ln t)."""
    from nonholonomic.analysis.lyapunov import spectrum

    s = spectrum(system, p, y0, t_final, count=1, interval=5.0)
    t, lam = s.convergence_t, s.convergence[:, 0]
    keep = t >= t_final / 30
    return float(s.exponents[0]), float(np.polyfit(np.log(t[keep]), lam[keep] * t[keep], 1)[0])


@claim_id("jacobi.chaos")
def jacobi_chaos() -> Row:
    claim = Claim(JACOBI, "Numerical experiments show the nonholonomic Jacobi problem behaves "
                  "chaotically", "text after 2804-4", errata="ERRATA 'Open'")
    system = get_system("ball_on_quadric", "zero")
    p = parameter_vector(system, CHAOS_PARAMETERS)
    regular = tangent_growth_power(system, p, state_vector(system, dict(CHAOS_REGULAR_STATE), p), CHAOS_T_FINAL)
    checks = []
    for side, state in zip(("-1e-4", "+1e-4"), CHAOS_LAYER_STATES):
        lam, growth = tangent_growth_power(system, p, state_vector(system, dict(state), p), CHAOS_T_FINAL)
        checks.append(Check(bool(growth > CHAOS_GROWTH), growth, CHAOS_GROWTH, "variational equations",
                            f"U = 0, B = (1, 2, 3), (H, K) = (0.5, 2): the orbit started {side} (in theta) from the "
                            f"separatrix of the section x2 = 0 has tangent vectors growing like t^{growth:.3g} "
                            f"(lambda = {lam:.3g} at t = {CHAOS_T_FINAL:g}), i.e. exponentially; chaotic if the power "
                            f"exceeds {CHAOS_GROWTH:g}. The orbit 1e-2 beside it: t^{regular[1]:.3g} (lambda = "
                            f"{regular[0]:.3g}), linear shear on an invariant torus"))
    return Row(claim, checks,
               note="chaotic in a thin layer at the separatrix (half-width 3e-4 .. 1e-3 in theta); 64 random states on "
                    "the same level all look regular (docs/science.md, study 1)")


@claim_id("kirchhoff.neumann")
def neumann_integrals() -> Row:
    claim = Claim(KIRCHHOFF, "The Neumann problem conserves H, (s, s), (s, L) and Uhlenbeck's "
                  "integrals", "2504-13 (alpha = 1, beta = 0)")
    return Row(claim, [integrals_check(_example_run("neumann"))])


@claim_id("kirchhoff.clebsch")
def clebsch_integrals() -> Row:
    claim = Claim(KIRCHHOFF, "The Clebsch case conserves H, (s, s), (s, L), H_alpha and H_beta",
                  "2504-13")
    return Row(claim, [integrals_check(_example_run("clebsch"))])


ROWS: list[RowBuilder] = [veselova_ball_multiplier, veselova_ball_integrals, veselova_ball_measure, rubber_ball,
                                 quadric_energy, quadric_energy_coefficient, quadric_measure, quadric_K, jacobi_chaos,
                                 neumann_integrals, clebsch_integrals]
