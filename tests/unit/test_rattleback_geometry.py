"""The rattleback classic's texts (nonholonomic/systems/lagrangian_classics.py) against its geometry, built
here independently: the rotation Rz(ψ) Rx(α) Ry(β), a paraboloid bottom with radii R1, R2 whose lowest point
is h below the mass centre, the contact point where the bottom's normal is vertical, and rolling without
slipping, v_cm = ω × (r_cm − r_contact). At random states: the body's ω, the mass centre's height, its vertical
velocity in L and both constraints agree with the geometry to 1e-14."""

from __future__ import annotations

import numpy as np
import sympy as sp

from nonholonomic.lagrangian import parse_system
from nonholonomic.systems.lagrangian_classics import CLASSICS

SPEC = CLASSICS["rattleback"]["job"]["system"]


def _rotation(axis: int, a: sp.Expr) -> sp.Matrix:
    c, s = sp.cos(a), sp.sin(a)
    return {0: sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]]), 1: sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            2: sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def test_the_rattleback_texts_are_its_geometry_and_rolling():
    data = parse_system(SPEC)
    sym = {str(s): s for s in (*data.q, *data.v, *data.parameters)}
    psi, alpha, beta = sym["psi"], sym["alpha"], sym["beta"]
    rates = {psi: sym["psi_dot"], alpha: sym["alpha_dot"], beta: sym["beta_dot"]}
    R = _rotation(2, psi) * _rotation(0, alpha) * _rotation(1, beta)
    R_dot = sum((R.diff(a) * rate for a, rate in rates.items()), sp.zeros(3, 3))
    skew = R.T * R_dot  # [ω]× in the body
    omega_body = sp.Matrix([skew[2, 1], skew[0, 2], skew[1, 0]])
    g = R.T * sp.Matrix([0, 0, 1])  # the vertical in the body
    R1, R2, h = sym["R1"], sym["R2"], sym["h"]
    rho = (-R1 * g[0] / g[2], -R2 * g[1] / g[2])  # the bottom's normal (K rho, -1) is -g there
    contact = sp.Matrix([rho[0], rho[1], -h + rho[0] ** 2 / (2 * R1) + rho[1] ** 2 / (2 * R2)])
    height = -(R * contact)[2]
    v_cm = (R * omega_body).cross(R * (-contact))  # rolling without slipping
    L = sp.sympify(SPEC["L"], locals=sym)
    z_dot_in_L = sp.sqrt(2 * (L.xreplace({sym["m"]: 1, sym["I1"]: 0, sym["I2"]: 0, sym["I3"]: 0, sym["g"]: 0})
                              - (sym["x_dot"] ** 2 + sym["y_dot"] ** 2) / 2))  # |z_dot| from m/2 (...)**2
    potential = -L.xreplace({v: 0 for v in data.v}) / (sym["m"] * sym["g"])
    constraints = [sp.sympify(c, locals=sym) for c in SPEC["constraints"]]
    body_texts = [sp.sympify(t, locals=sym) for t in ("alpha_dot*cos(beta) - psi_dot*sin(beta)*cos(alpha)",
                                                      "beta_dot + psi_dot*sin(alpha)",
                                                      "alpha_dot*sin(beta) + psi_dot*cos(alpha)*cos(beta)")]
    rng = np.random.default_rng(11)
    for _ in range(5):
        point = {s: float(x) for s, x in zip((*data.q, *data.v), rng.uniform(-0.3, 0.3, 2 * len(data.q)))}
        point.update(data.parameter_values)
        for exact, text in zip(omega_body, body_texts):
            assert abs(float((exact - text).xreplace(point))) < 1e-14
        assert abs(float((height - potential).xreplace(point))) < 1e-14
        assert abs(abs(float(v_cm[2].xreplace(point))) - float(z_dot_in_L.xreplace(point))) < 1e-13
        rolling = {sym["x_dot"]: v_cm[0], sym["y_dot"]: v_cm[1]}
        for c in constraints:
            assert abs(float(c.xreplace(rolling).xreplace(point))) < 1e-14
        # and a slipping velocity violates them
        assert abs(float(constraints[0].xreplace({**rolling, sym["x_dot"]: v_cm[0] + 0.1}).xreplace(point))) > 1e-3
