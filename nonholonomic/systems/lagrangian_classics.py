"""Classic nonholonomic systems written as the kind ``lagrangian`` (a Lagrangian in coordinates and
constraints linear in the velocities): the catalog's worked examples, each with the fact it is tested
against (``tests/api/test_lagrangian_classics.py``).

* **Chaplygin's sleigh** (Chaplygin 1911; Neimark & Fufaev ch. III §5): a knife edge at the contact point
  (x, y), heading θ, the mass centre a ahead on the blade. Reduced: v̇ = a ω², ω̇ = −m a v ω/(J + m a²)
  (v = ẋ cos θ + ẏ sin θ, ω = θ̇); ω → 0, v → √(2E/m): the heading tends to a straight motion, an
  asymptotically stable one, so no invariant measure (verdict ``none``).
* **The nonholonomic particle** (Bloch, *Nonholonomic mechanics and control*, §1.3; Rosenberg):
  ż = y ẋ, here in U = k(x² + y²)/2; measure √(1 + y²) dx dy dz dẋ dẏ; z cyclic, so a Chaplygin system
  and Theorem 1 gives N = 1/√(1 + y²) and a Hamiltonian form.
* **The Suslov problem** (Suslov 1902; Kozlov 1985): a rigid body about a fixed point with (ω, e) = 0 for a
  body-fixed e, Euler angles (φ, θ, ψ) z-x-z, inertia diag(I₁, I₂, I₃). A measure exists exactly when e is an
  eigenvector of the inertia tensor: for e = e₃ (ω₃ = 0) Euler's equations give I₁ω̇₁ = I₂ω̇₂ = 0, the body's
  ω is constant; for e = (sin α, 0, cos α) not an eigenvector, ω tends to the steady rotation about e₂ with
  |ω| = √(2E/I₂) (asymptotically stable: no measure). φ is cyclic, so both are Chaplygin systems in (θ, ψ):
  Theorem 1 gives N = |cos θ| for the first and no multiplier for the second.
* **The rolling disk** (Appell 1900, Korteweg 1899; Neimark & Fufaev ch. III §8): a thin disk of radius R
  rolling without slipping, mass centre (x, y, R sin θ), z-x-z Euler angles (φ precession, θ the axis' angle
  to the vertical, ψ spin). Its integrals besides the energy (Appell–Korteweg, hypergeometric in cos θ) make
  φ̇ and ψ̇ functions of θ along a motion: at every crossing of θ = θ₀ in the same direction the reduced
  state (θ̇, φ̇, ψ̇) is the same. Measure sin²θ dq du.
* **The rattleback** (Walker 1896; Garcia & Hubbard 1988; Borisov & Mamaev, *Strange attractors in
  rattleback dynamics*, 2003): a body with a paraboloid bottom (principal radii of curvature R1, R2 at
  the contact point, the mass centre h above it when upright) whose principal axes of inertia are turned by δ
  about the vertical body axis against the curvature directions; coordinates (x, y) of the mass centre, yaw ψ,
  tilts α, β (ω's vertical component ψ̇ + β̇ sin α). Spun one way it rocks and turns to spin the other way
  within 10 s; spun the other way it keeps its sense over the same time (without dissipation it too turns,
  about ten times slower, near t = 22 s). Published: no invariant measure (the reversal is an attraction).
  Here its equations are too large for the exact elimination: they are eliminated without cancellation
  (correct, compiled from a small DAG), so the searches fit an ansatz on sampled states
  (:mod:`nonholonomic.lagrangian.sampled_search`): no density and no integral linear in the velocities in it,
  so the measure is ``undecided`` (not ``none``: absence from an ansatz proves nothing).
"""

from __future__ import annotations

import math
from typing import Any

from nonholonomic.lagrangian.parse import KIND

#: The rattleback's inertia in the curvature frame, (A, B, C, D) [kg m^2] (Garcia & Hubbard's kind of body):
#: principal moments I1, I2 in the horizontal plane at the angle δ, I3 about the vertical axis.
_A, _B, _C, _D = 2e-4, 1.6e-3, 1.7e-3, 2e-5
_HALF = math.hypot((_B - _A) / 2, _D)
_RATTLEBACK_PARAMETERS = {"m": 1.0, "g": 9.81, "h": 0.01, "R1": 2.0, "R2": 0.045, "I1": (_A + _B) / 2 - _HALF,
                          "I2": (_A + _B) / 2 + _HALF, "I3": _C, "delta": -0.5 * math.atan2(2 * _D, _B - _A)}
#: Its mass centre's height over the plane, and Z's derivatives by α and β.
_Z = "(h*cos(alpha)*cos(beta) + (R1*sin(beta)**2*cos(alpha)**2 + R2*sin(alpha)**2)/(2*cos(alpha)*cos(beta)))"
_ZA = ("sin(alpha)*(R2 + (R2 - R1)*cos(alpha)**2 + (R1 - 2*h)*cos(alpha)**2*cos(beta)**2)"
       "/(2*cos(alpha)**2*cos(beta))")
_ZB = "sin(beta)*(R1 - 2*h + (R1 - R2)/cos(beta)**2 + R2/(cos(alpha)*cos(beta))**2)/2"
#: The body's angular velocity in the curvature frame, and its vertical component.
_W1 = "(alpha_dot*cos(beta) - psi_dot*sin(beta)*cos(alpha))"
_W2 = "(beta_dot + psi_dot*sin(alpha))"
_W3 = "(alpha_dot*sin(beta) + psi_dot*cos(alpha)*cos(beta))"
_SPIN = "(psi_dot + beta_dot*sin(alpha))"

__all__ = ["CLASSICS"]

_SUSLOV_L = ("I1/2*(phi_dot*sin(theta)*sin(psi) + theta_dot*cos(psi))**2 + I2/2*(phi_dot*sin(theta)*cos(psi) "
             "- theta_dot*sin(psi))**2 + I3/2*(phi_dot*cos(theta) + psi_dot)**2")


def _suslov_tilted_state() -> dict[str, list[float]]:
    phi, theta, psi, phi_dot, theta_dot = 0.1, 1.0, 0.2, 0.3, 0.5
    omega1 = phi_dot * math.sin(theta) * math.sin(psi) + theta_dot * math.cos(psi)
    psi_dot = -0.6 * omega1 / 0.8 - phi_dot * math.cos(theta)  # ca ω₃ + sa ω₁ = 0, ca = 0.8, sa = 0.6
    return {"q": [phi, theta, psi], "q_dot": [phi_dot, theta_dot, psi_dot]}


def _disk_state() -> dict[str, list[float]]:
    phi, theta, psi, phi_dot, theta_dot, psi_dot, R = 0.0, 1.2, 0.0, 0.5, 0.1, 3.0, 1.0
    x_dot = -R * (phi_dot * math.cos(phi) * math.cos(theta) + psi_dot * math.cos(phi)
                  - theta_dot * math.sin(phi) * math.sin(theta))
    y_dot = -R * (phi_dot * math.sin(phi) * math.cos(theta) + psi_dot * math.sin(phi)
                  + theta_dot * math.sin(theta) * math.cos(phi))
    return {"q": [0.0, 0.0, phi, theta, psi], "q_dot": [x_dot, y_dot, phi_dot, theta_dot, psi_dot]}


#: name → {"title", "job" (a POST /v1/jobs body), "facts", "measure" (the verdict the search reaches),
#: "hamiltonization" (Theorem 1's verdict), "references"}.
CLASSICS: dict[str, dict[str, Any]] = {
    "chaplygin_sleigh": {
        "title": "Chaplygin's sleigh",
        "job": {"system": {"kind": KIND, "coordinates": ["x", "y", "theta"],
                           "L": "m/2*((x_dot - a*sin(theta)*theta_dot)**2 + (y_dot + a*cos(theta)*theta_dot)**2) "
                                "+ J/2*theta_dot**2",
                           "constraints": ["-sin(theta)*x_dot + cos(theta)*y_dot"],
                           "parameters": {"m": 1.3, "a": 0.4, "J": 0.25}},
                "initial_state": {"q": [0.2, -0.1, 0.0], "q_dot": [0.9, 0.0, 0.7]}, "t_final": 40.0,
                "samples": 401, "checks": ["integrals", "measure"]},
        "facts": ["reduced: v' = a w^2, w' = -m a v w/(J + m a^2), v = x_dot cos(theta) + y_dot sin(theta), "
                  "w = theta_dot",
                  "w -> 0 and v -> sqrt(2E/m): the heading tends to a straight motion (asymptotically stable)",
                  "no invariant measure rho(q) dq du"],
        "measure": "none", "hamiltonization": "none",
        "references": ["S. A. Chaplygin, On the theory of motion of nonholonomic systems (1911)",
                       "Ju. I. Neimark, N. A. Fufaev, Dynamics of Nonholonomic Systems, ch. III"]},
    "nonholonomic_particle": {
        "title": "The nonholonomic particle (z_dot = y x_dot) in a harmonic potential",
        "job": {"system": {"kind": KIND, "coordinates": ["x", "y", "z"],
                           "L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - k*(x**2 + y**2)/2",
                           "constraints": ["z_dot - y*x_dot"], "parameters": {"k": 1.0}},
                "initial_state": {"q": [0.3, -0.2, 0.1], "q_dot": [0.5, 0.4, -0.1]}, "t_final": 20.0,
                "samples": 201, "checks": ["integrals", "measure", "bracket"]},
        "facts": ["invariant measure sqrt(1 + y^2) dx dy dz dx_dot dy_dot",
                  "z cyclic: a Chaplygin system (2704-7) with S = y x_dot; Theorem 1: N = 1/sqrt(1 + y^2), "
                  "Hamiltonian in tau"],
        "measure": "found", "hamiltonization": "found",
        "references": ["A. M. Bloch, Nonholonomic Mechanics and Control, section 1.3",
                       "R. M. Rosenberg, Analytical Dynamics of Discrete Systems (1977)"]},
    "suslov": {
        "title": "The Suslov problem, the constraint along a principal axis (omega_3 = 0)",
        "job": {"system": {"kind": KIND, "coordinates": ["phi", "theta", "psi"], "L": _SUSLOV_L,
                           "constraints": ["phi_dot*cos(theta) + psi_dot"],
                           "parameters": {"I1": 1.0, "I2": 2.0, "I3": 3.0}},
                "initial_state": {"q": [0.1, 1.0, 0.2], "q_dot": [0.3, 0.5, -0.3 * math.cos(1.0)]},
                "t_final": 50.0, "samples": 201, "checks": ["integrals", "measure"]},
        "facts": ["omega_3 = 0 and Euler's equations give I1 omega_1' = I2 omega_2' = 0: the body's angular "
                  "velocity is constant",
                  "the constraint vector e3 is an eigenvector of the inertia tensor: an invariant measure "
                  "(here sin(theta)^2 dq du)",
                  "phi is cyclic: a Chaplygin system in (theta, psi) (2704-7), and Theorem 1 gives N = |cos(theta)|"],
        "measure": "found", "hamiltonization": "found",
        "references": ["G. K. Suslov, Theoretical Mechanics (1902)",
                       "V. V. Kozlov, On the theory of integration of the equations of nonholonomic mechanics, "
                       "Adv. Mech. 8 (1985)"]},
    "suslov_tilted": {
        "title": "The Suslov problem, the constraint vector not an eigenvector of the inertia tensor",
        "job": {"system": {"kind": KIND, "coordinates": ["phi", "theta", "psi"], "L": _SUSLOV_L,
                           "constraints": ["ca*(phi_dot*cos(theta) + psi_dot) + sa*(phi_dot*sin(theta)*sin(psi) "
                                           "+ theta_dot*cos(psi))"],
                           "parameters": {"I1": 1.0, "I2": 2.0, "I3": 3.0, "ca": 0.8, "sa": 0.6}},
                "initial_state": _suslov_tilted_state(), "t_final": 100.0, "samples": 201,
                "checks": ["integrals", "measure"]},
        "facts": ["e = (sa, 0, ca) is not an eigenvector of diag(I1, I2, I3): no invariant measure",
                  "omega tends to the steady rotation about e2 with |omega| = sqrt(2E/I2) (asymptotically stable)",
                  "phi is cyclic: a Chaplygin system in (theta, psi), and Theorem 1's integrability condition fails"],
        "measure": "none", "hamiltonization": "none",
        "references": ["V. V. Kozlov, Adv. Mech. 8 (1985)",
                       "A. V. Borisov, A. A. Kilin, I. S. Mamaev, Hamiltonicity and integrability of the Suslov "
                       "problem, Regul. Chaotic Dyn. 16 (2011)"]},
    "rolling_disk": {
        "title": "A thin disk rolling without slipping on a plane",
        "job": {"system": {"kind": KIND, "coordinates": ["x", "y", "phi", "theta", "psi"],
                           "L": "m/2*(x_dot**2 + y_dot**2 + R**2*cos(theta)**2*theta_dot**2) + A/2*(theta_dot**2 "
                                "+ phi_dot**2*sin(theta)**2) + C/2*(psi_dot + phi_dot*cos(theta))**2 "
                                "- m*g*R*sin(theta)",
                           "constraints": ["x_dot + R*(phi_dot*cos(phi)*cos(theta) + psi_dot*cos(phi) "
                                           "- theta_dot*sin(phi)*sin(theta))",
                                           "y_dot + R*(phi_dot*sin(phi)*cos(theta) + psi_dot*sin(phi) "
                                           "+ theta_dot*sin(theta)*cos(phi))"],
                           "parameters": {"m": 1.0, "R": 1.0, "A": 0.25, "C": 0.5, "g": 9.81}},
                "initial_state": _disk_state(), "t_final": 50.0, "samples": 501, "checks": ["integrals", "measure"],
                "poincare": {"surface": "theta", "value": 1.2, "direction": "increasing",
                             "coordinates": ["phi_dot", "psi_dot"]}},
        "facts": ["Appell-Korteweg integrals: phi_dot and psi_dot are functions of theta along a motion, so every "
                  "crossing of theta = theta_0 upwards has the same (theta_dot, phi_dot, psi_dot)",
                  "invariant measure sin(theta)^2 dq du"],
        "measure": "found", "hamiltonization": "not applicable",
        "references": ["P. Appell, Sur l'integration des equations du mouvement d'un corps pesant de revolution "
                       "roulant... (1900)", "D. J. Korteweg (1899)",
                       "Ju. I. Neimark, N. A. Fufaev, Dynamics of Nonholonomic Systems, ch. III"]},
    "rattleback": {
        "title": "The rattleback: a body with a paraboloid bottom, its inertia turned against its curvature",
        "job": {"system": {"kind": KIND, "coordinates": ["x", "y", "psi", "alpha", "beta"],
                           "L": (f"m/2*(x_dot**2 + y_dot**2 + (alpha_dot*{_ZA} + beta_dot*cos(alpha)*{_ZB})**2)"
                                 f" + I1/2*(cos(delta)*{_W1} + sin(delta)*{_W2})**2"
                                 f" + I2/2*(cos(delta)*{_W2} - sin(delta)*{_W1})**2 + I3/2*{_W3}**2 - m*g*{_Z}"),
                           "constraints": [f"cos(psi)*x_dot + sin(psi)*y_dot - beta_dot*cos(alpha)*{_Z} "
                                           f"+ {_SPIN}*{_ZA}",
                                           f"-sin(psi)*x_dot + cos(psi)*y_dot + alpha_dot*{_Z} + {_SPIN}*{_ZB}"],
                           "parameters": _RATTLEBACK_PARAMETERS},
                "initial_state": {"q": [0.0, 0.0, 0.0, 0.0, 0.0], "q_dot": [0.0, -0.01 * 0.01, 5.0, 0.01, 0.0]},
                "t_final": 12.0, "samples": 121, "checks": ["integrals"]},
        "facts": ["spun at psi_dot = +5 rad/s with a small rocking (alpha_dot = 0.01), the vertical spin "
                  "psi_dot + beta_dot sin(alpha) turns to about -5 rad/s within 10 s (below -4 at t = 12); "
                  "spun at -5 rad/s it "
                  "keeps its sense over these 12 s (without dissipation it too turns, about ten times slower: its "
                  "instability grows at 0.04 |omega| against 0.42 omega, the turn comes near t = 22 s)",
                  "energy and both rolling constraints conserved",
                  "no invariant measure (published); here the search is not run: the equations are eliminated "
                  "without cancellation"],
        "measure": "undecided", "hamiltonization": "not applicable",
        "references": ["G. T. Walker, On a dynamical top, Q. J. Pure Appl. Math. 28 (1896)",
                       "A. Garcia, M. Hubbard, Spin reversal of the rattleback: theory and experiment, Proc. R. "
                       "Soc. A 418 (1988)",
                       "A. V. Borisov, I. S. Mamaev, Strange attractors in rattleback dynamics, Phys. Usp. 46 (2003)"]},
}
