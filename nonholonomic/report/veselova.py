"""The report's claims of the section "Veselova system" (eq. 2504-1 … 2504-13, Theorem 2,
Proposition 1, the Neumann theorem)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
import sympy as sp

from nonholonomic import isomorphisms as iso
from nonholonomic.definition import dot
from nonholonomic.evidence.measure import measure_evidence
from nonholonomic.hamiltonization import local_forms as lf
from nonholonomic.hamiltonization.forms import (
    flow_residual,
    hamiltonian_form,
    symbolic_flow_identity,
)
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import parameter_vector, vectorize
from nonholonomic.report.common import (
    GAMMA0,
    INERTIA,
    OMEGA0,
    A,
    evidence_check,
    integrals_check,
    map_checks,
    proof,
    run,
    trig_identity,
)
from nonholonomic.report.verdict import Check, Claim, Row, RowBuilder, claim_id
from nonholonomic.systems import clebsch, get_system, veselova as ves

SECTION = "Veselova system"
LINEAR: dict[str, object] = {"inertia": INERTIA, "a": A}
STATE: dict[str, Sequence[float]] = {"omega": OMEGA0, "gamma": GAMMA0}


@claim_id("veselova.multiplier")
def multiplier() -> Row:
    claim = Claim(SECTION, "The multiplier mu keeps the constraint (omega, gamma) = 0",
                  "2504-2", printed="mu = +(I omega x omega + gamma x dU/dgamma, I^-1 gamma) / (gamma, I^-1 gamma)",
                  corrected="mu = -(I omega x omega + gamma x dU/dgamma, I^-1 gamma) / (gamma, I^-1 gamma)",
                  errata="ERRATA 1")
    right = get_system("veselova", "linear")
    U = dot(sp.Matrix(sp.symbols("a1:4", real=True)), ves.gamma)
    printed = dataclasses.replace(right, rhs=ves.equations_of_motion(U, -ves.constraint_multiplier(U)))
    p = parameter_vector(right, LINEAR)
    y0 = np.array(OMEGA0 + GAMMA0)
    drift = {}
    for name, system, engine in (("derived", right, "heyoka"), ("printed", printed, "scipy")):
        traj = integrate(system, p, y0, 5.0, 51, engine=engine)
        drift[name] = float(np.max(np.abs(np.einsum("ij,ij->i", traj.states[:, :3], traj.states[:, 3:]))))
    what = "max |(omega, gamma)| over t in [0, 5], U = (a, gamma)"
    return Row(claim, [Check.at_most(drift["derived"], 1e-12, "trajectory", f"{what}: {drift['derived']:.2g} "
                                     "(mu derived by sympy from d/dt (omega, gamma) = 0)")],
               printed_check=Check.at_most(drift["printed"], 1e-12, "trajectory", f"{what}: {drift['printed']:.2g}"))


@claim_id("veselova.integrals")
def integrals() -> Row:
    claim = Claim(SECTION, "Energy and the geometric integral are conserved for any U(gamma)",
                  "2504-3")
    return Row(claim, [integrals_check(run("veselova", "linear", LINEAR, STATE))])


@claim_id("veselova.measure")
def measure() -> Row:
    claim = Claim(SECTION, "rho_omega = (gamma, I^-1 gamma)^(1/2) is an invariant density",
                  "2504-4")
    result = run("veselova", "linear", LINEAR, STATE)
    items = measure_evidence(result.system, result.parameters, result.trajectory.states)
    return Row(claim, [evidence_check(i) for i in items])


@claim_id("veselova.F")
def integral_F() -> Row:
    claim = Claim(SECTION, "For U = 0, F = |I omega x gamma|^2 is conserved", "2504-5")
    return Row(claim, [integrals_check(run("veselova", "zero", {"inertia": INERTIA}, STATE), ["F"])])


def _chaplygin_form_residual(S: sp.Expr) -> float:
    """Max relative residual of eq. (2504-7) = (2704-7) with L = T − U and the given S, at the
    states of a Veselova trajectory (U linear); θ̈, φ̈ from the vector field."""
    result = run("veselova", "linear", LINEAR, STATE)
    system, p, X = result.system, result.parameters, result.trajectory.states
    rhs = vectorize(system.rhs, system.state_symbols + system.parameter_symbols)(X, p)
    omega, gamma, omega_dot = X[:, :3], X[:, 3:], rhs[:, :3]
    th, ph, thd, phd, _, s = lf.euler_angles_and_rates(omega, gamma)
    keep = s > 0.1
    e_N = np.stack([np.cos(ph), -np.sin(ph), np.zeros_like(ph)], axis=1)
    de_N = np.stack([-np.sin(ph), -np.cos(ph), np.zeros_like(ph)], axis=1)
    thdd = np.einsum("ij,ij->i", omega_dot, e_N) + np.einsum("ij,ij->i", omega, de_N) * phd
    phdd = omega_dot[:, 2] / s**2 - 2 * omega[:, 2] * np.cos(th) * thd / s**3
    a = sp.Matrix(sp.symbols("a1:4", real=True))
    L = lf.veselova_kinetic_energy() - dot(a, lf.euler_gamma())
    parts = []
    for i, sign in ((0, 1), (1, -1)):
        v = lf.QDOT[i]
        parts += [lf.time_derivative(sp.diff(L, v)), sp.diff(L, lf.Q[i]), sign * lf.QDOT[1 - i] * S]
    args = [*lf.Q, *lf.QDOT, *lf.QDDOT, lf.I1, lf.I2, lf.I3, *a]
    f = sp.lambdify(args, parts, "numpy")
    values = [np.broadcast_to(np.asarray(x, dtype=float), th.shape) for x in
              f(th, ph, thd, phd, thdd, phdd, *INERTIA, *A)]
    worst = 0.0
    for k in (0, 3):
        total = values[k] - values[k + 1] - values[k + 2]
        scale = np.abs(values[k]) + np.abs(values[k + 1]) + np.abs(values[k + 2])
        worst = max(worst, float(np.max(np.abs(total[keep]) / scale[keep])))
    return worst


@claim_id("veselova.S")
def gyroscopic_term() -> Row:
    claim = Claim(SECTION, "In Euler angles the Veselova flow is a Chaplygin system (2704-7) with "
                  "L = T - U and the gyroscopic term S", "2504-7",
                  printed="S = sin^2(theta) (thetadot (I2 - I1) sin(phi) cos(phi) - phidot (I1 cos^2(phi) + "
                          "I2 sin^2(phi) + I3))",
                  corrected="S = sin^2(theta) [thetadot (I2 - I1) sin(phi) cos(phi) + phidot sin(theta) cos(theta) "
                            "(I1 sin^2(phi) + I2 cos^2(phi) - I3)] = -sin(theta) dT0/dpsidot",
                  errata="ERRATA 2")
    what = ("max relative residual of eq. 2704-7 at 201 states of a trajectory (U = (a, gamma), t <= 100, "
            "sin(theta) > 0.1), accelerations from the vector field")
    right, printed = (_chaplygin_form_residual(S) for S in (lf.veselova_gyroscopic_term(),
                                                            lf.veselova_gyroscopic_term_printed()))
    return Row(claim, [Check.at_most(right, 1e-10, "trajectory", f"{what}: {right:.2g}")],
               printed_check=Check.at_most(printed, 1e-10, "trajectory", f"{what}: {printed:.2g}"))


@claim_id("veselova.theorem_2")
def theorem_2_multiplier() -> Row:
    claim = Claim(SECTION, "Theorem 2: the reducing multiplier N makes S_bar = 0 "
                  "(an ordinary Lagrangian system in the new time)", "Theorem 2, 2504-9",
                  printed="N = (gamma, I gamma)^(-1/2)", corrected="N = (gamma, I^-1 gamma)^(-1/2) = rho_omega^-1",
                  errata="ERRATA 3")
    g = lf.euler_gamma()
    T, S = lf.veselova_kinetic_energy(), lf.veselova_gyroscopic_term()
    values = {lf.I1: INERTIA[0], lf.I2: INERTIA[1], lf.I3: INERTIA[2], lf.thetadot: 0.3, lf.phidot: -0.7}
    right = lf.reduced_gyroscopic_term_over_multiplier(T, S, g.dot(ves.inertia_inv * g))
    printed = lf.reduced_gyroscopic_term_over_multiplier(T, S, g.dot(lf.inertia * g))
    return Row(claim, [trig_identity(right, (lf.theta, lf.phi),
                                     values, "S_bar / N with N = (gamma, I^-1 gamma)^(-1/2)")],
               printed_check=trig_identity(printed, (lf.theta, lf.phi), values,
                                           "S_bar / N with N = (gamma, I gamma)^(-1/2)"))


@claim_id("veselova.theorem_2_lagrangian")
def theorem_2_lagrangian() -> Row:
    claim = Claim(SECTION, "Theorem 2: the Lagrangian after the time substitution "
                  "equals 1/2 (gamma' x gamma, I (gamma' x gamma)) / (gamma, I^-1 gamma) - U", "Theorem 2")
    result = run("veselova", "linear", LINEAR, STATE)
    items = lf.local_form_evidence(result.system, result.parameters, result.trajectory.states)
    return Row(claim, [evidence_check(i) for i in items])


def _e3_form_rows() -> tuple[Check, Check]:
    system = get_system("veselova", "linear")
    form = hamiltonian_form(system)
    assert form is not None
    result = run("veselova", "linear", LINEAR, STATE)
    X, p = result.trajectory.states, result.parameters
    proven, detail = symbolic_flow_identity(form, system)
    res = flow_residual(form, system, X, p)
    return proof(proven, detail), Check.at_most(res, 1e-12, "pointwise",
                                                f"max |pushforward / N - {{H, x}}| / max |{{H, x}}| "
                                                f"along t <= 100: {res:.2g}")


@claim_id("veselova.e3")
def e3_form() -> Row:
    claim = Claim(SECTION, "After d tau = dt / (rho_omega sqrt(det I)), M = rho_omega I^(1/2) omega, "
                  "Gamma = rho_omega^-1 I^(-1/2) gamma, the flow is Hamiltonian on e(3) with "
                  "H = (Gamma, I Gamma) M^2 / 2 + U", "2504-10-2, 2504-11",
                  printed="dx/dtau = {x, H} read as the field of the printed bracket with k = -sqrt(det I)",
                  corrected="dx/dtau = {H, x} with the e(3) bracket as printed", errata="ERRATA 4")
    system = get_system("veselova", "linear")
    form = hamiltonian_form(system)
    assert form is not None
    flipped = dataclasses.replace(form, bracket=dataclasses.replace(form.bracket, matrix=-form.bracket.matrix))
    result = run("veselova", "linear", LINEAR, STATE)
    res = flow_residual(flipped, system, result.trajectory.states, result.parameters)
    return Row(claim, list(_e3_form_rows()),
               printed_check=Check.at_most(res, 1e-12, "pointwise", f"with dx/dtau = {{x, H}}: residual {res:.3g}"))


@claim_id("veselova.e3_map")
def e3_map() -> Row:
    claim = Claim(SECTION, "The map to e(3) and its inverse: the mapped trajectory is the e(3) system's own "
                  "trajectory in tau", "2504-10-2, inverse after 2504-11")
    m = iso.get_map("veselova_to_e3", "linear")
    p = parameter_vector(m.source, LINEAR)
    X = iso.sample_states(m, p, 50)
    inverse = iso.kernels(m).inverse
    assert inverse is not None  # this map has an inverse (after 2504-11)
    back = inverse(iso.apply(m, p, X)["states"], p)
    err = float(np.max(np.abs(back - X)))
    return Row(claim, map_checks("veselova_to_e3", LINEAR, "linear") + [
        Check.at_most(err, 1e-13, "pointwise", f"max |inverse(map(x)) - x| at 50 states: {err:.2g}")])


@claim_id("veselova.leaf")
def leaf() -> Row:
    claim = Claim(SECTION, "{H, F} = 0 on the symplectic leaf of the real motion", "after 2504-11",
                  printed="on (M, gamma) = 0", corrected="on (M, Gamma) = 0 (Gamma^2 = 1)",
                  errata="new (not in ERRATA)")
    from nonholonomic.systems import veselova_e3 as ve3

    H, F = ve3.hamiltonian_alpha(), 2 * ve3.hamiltonian_beta()
    f = sp.lambdify(ve3.BRACKET.variables + (ve3.I1, ve3.I2, ve3.I3), ve3.BRACKET.bracket(H, F), "numpy")
    rng = np.random.default_rng(1)
    on_leaf, on_printed = [], []
    sqrt_I = np.sqrt(INERTIA)
    for _ in range(20):
        M, G = rng.normal(size=3), rng.normal(size=3)
        G /= np.linalg.norm(G)
        scale = np.linalg.norm(M) ** 3 * np.max(INERTIA) ** 3
        on_leaf.append(abs(f(*(M - (M @ G) * G), *G, *INERTIA)) / scale)
        gamma = sqrt_I * G / np.sqrt(G @ (np.array(INERTIA) * G))  # gamma(Gamma), the inverse map
        M_p = M - (M @ gamma) / (gamma @ gamma) * gamma  # (M, gamma) = 0 as printed
        on_printed.append(abs(f(*M_p, *G, *INERTIA)) / scale)
    right, printed = max(on_leaf), min(on_printed)
    return Row(claim, [Check.at_most(right, 1e-14, "pointwise", f"max |{{H, F}}| / (|M|^3 max I^3) at 20 random "
                                     f"points with (M, Gamma) = 0: {right:.2g}")],
               printed_check=Check.at_most(printed, 1e-14, "pointwise", f"min of the same at 20 points with "
                                           f"(M, gamma(Gamma)) = 0: {printed:.2g}"))


@claim_id("veselova.proposition_1")
def proposition_1() -> Row:
    claim = Claim(SECTION, "Proposition 1: on M^2 (Gamma, I Gamma) / det I = c, "
                  "(M, Gamma) = 0, the field of H (2504-12) is the Clebsch field (2504-13)",
                  "Proposition 1, 2504-12, 2504-13", printed="k = -sqrt(det I)",
                  corrected="k = +sqrt(det I) with dx/dt = {H, x}; Gamma^2 = 1 needed", errata="ERRATA 4")
    m = iso.get_map("e3_to_clebsch")
    p = parameter_vector(m.source, {"inertia": INERTIA, "alpha": 0.7, "beta": -0.4})
    X = iso.sample_states(m, p, 50)
    right = iso.push_forward_residual(m, p, X)
    k_at = [str(s) for s in m.target.parameter_symbols].index("k")
    flipped = list(m.target_parameters)
    flipped[k_at] = -flipped[k_at]
    wrong = iso.push_forward_residual(dataclasses.replace(m, target_parameters=tuple(flipped)), p, X)
    what = "max relative push-forward residual at 50 random states of the level set (alpha = 0.7, beta = -0.4)"
    return Row(claim, [Check.at_most(right, iso.PUSH_FORWARD_TOLERANCE, "pointwise", f"{what}: {right:.2g}")],
               printed_check=Check.at_most(wrong, iso.PUSH_FORWARD_TOLERANCE, "pointwise",
                                           f"with k = -sqrt(det I): {wrong:.3g}"))


def _printed_2504_13() -> sp.Matrix:
    """Eq. (2504-13) transcribed as printed."""
    s, L, I = clebsch.s, clebsch.L, clebsch.inertia
    k, a, b, c = clebsch.k, clebsch.alpha, clebsch.beta, clebsch.c
    s_dot = k * (a * s.cross(L) + b * s.cross(I * L))
    L_dot = k * (a * c * s.cross(I * s)
                 + b * (L.cross(I * L) - c * clebsch.det_inertia * s.cross(clebsch.inertia_inv * s)))
    return sp.Matrix.vstack(s_dot, L_dot)


@claim_id("veselova.clebsch_hamiltonian")
def clebsch_hamiltonian() -> Row:
    claim = Claim(SECTION, "The Hamiltonian after Proposition 1 generates the field "
                  "(2504-13) on e(3)", "after Proposition 1",
                  printed="H = k alpha (M^2/2 + c/2 (Gamma, I Gamma)) "
                          "+ k beta ((M, I M)/2 - c/2 det I (Gamma, I Gamma))",
                  corrected="beta part -c/2 det I (Gamma, I^-1 Gamma)", errata="new (not in ERRATA)")
    target = _printed_2504_13()
    checks = []
    for label, beta_part in (("corrected", clebsch.hamiltonian_beta()),
                             ("printed", clebsch.printed_hamiltonian_beta())):
        H = clebsch.k * (clebsch.alpha * clebsch.hamiltonian_alpha() + clebsch.beta * beta_part)
        diff = (sp.Matrix(clebsch.kirchhoff_equations(H)) - target).expand()
        nonzero = sum(1 for e in diff if e != 0)
        checks.append(Check(nonzero == 0, float(nonzero), 0.0, "symbolic",
                            f"{label} H: field minus eq. 2504-13 expanded; {nonzero} of 6 components non-zero"))
    return Row(claim, [checks[0]], printed_check=checks[1])


@claim_id("veselova.neumann")
def neumann_theorem() -> Row:
    claim = Claim(SECTION, "For U = 0, after the time substitution, the Veselova flow on an energy "
                  "level is the Neumann problem", "theorem after Proposition 1",
                  corrected="s = gamma, L = rho_omega omega, c = 2h / det I, k = +sqrt(det I) in tau",
                  errata="ERRATA 3, 4")
    return Row(claim, map_checks("veselova_to_neumann", {"inertia": INERTIA}))


ROWS: list[RowBuilder] = [multiplier, integrals, measure, integral_F, gyroscopic_term, theorem_2_multiplier,
                                 theorem_2_lagrangian, e3_form, e3_map, leaf, proposition_1, clebsch_hamiltonian,
                                 neumann_theorem]
