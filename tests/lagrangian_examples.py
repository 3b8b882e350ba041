"""Lagrangian systems with constraints that the tests of ``nonholonomic.lagrangian`` share, as the
API's ``system`` blocks (kind ``lagrangian``)."""

#: Chaplygin's sleigh: the contact point (x, y), the heading theta, the mass centre a ahead on the blade.
SLEIGH = {"kind": "lagrangian", "coordinates": ["x", "y", "theta"],
          "L": "m/2*((x_dot - a*sin(theta)*theta_dot)**2 + (y_dot + a*cos(theta)*theta_dot)**2) + J/2*theta_dot**2",
          "constraints": ["-sin(theta)*x_dot + cos(theta)*y_dot"],
          "parameters": {"m": 1.3, "a": 0.4, "J": 0.25}}
#: The nonholonomic particle (z_dot = y x_dot) in a harmonic and a uniform field.
PARTICLE = {"kind": "lagrangian", "coordinates": ["x", "y", "z"],
            "L": "(x_dot**2 + y_dot**2 + z_dot**2)/2 - k/2*(x**2 + y**2 + z**2) - g*z",
            "constraints": ["z_dot - y*x_dot"], "parameters": {"k": 0.8, "g": 0.3}}
#: A rigid body's kinetic energy in z-x-z Euler angles (phi, theta, psi), inertia diag(I1, I2, I3).
_RIGID_BODY = ("I1/2*(phi_dot*sin(theta)*sin(psi) + theta_dot*cos(psi))**2 + I2/2*(phi_dot*sin(theta)*cos(psi) "
               "- theta_dot*sin(psi))**2 + I3/2*(phi_dot*cos(theta) + psi_dot)**2")
#: Veselova's system: a rigid body about a fixed point whose angular velocity stays orthogonal to the space-fixed
#: vertical, (omega, gamma) = phi_dot + psi_dot cos(theta) = 0, in a field U = b cos(theta).
VESELOVA = {"kind": "lagrangian", "coordinates": ["phi", "theta", "psi"], "L": _RIGID_BODY + " - b*cos(theta)",
            "constraints": ["phi_dot + psi_dot*cos(theta)"],
            "parameters": {"I1": 1.0, "I2": 2.0, "I3": 3.0, "b": 0.5}}
#: Chaplygin's sphere (balanced, dynamically asymmetric) rolling without slipping on the plane: the centre (x, y),
#: Euler angles; the contact point's velocity x_dot - R Omega_y = y_dot + R Omega_x = 0 (Omega in space).
CHAPLYGIN_SPHERE = {"kind": "lagrangian", "coordinates": ["x", "y", "phi", "theta", "psi"],
                    "L": "m/2*(x_dot**2 + y_dot**2) + " + _RIGID_BODY,
                    "constraints": ["x_dot - R*(theta_dot*sin(phi) - psi_dot*cos(phi)*sin(theta))",
                                    "y_dot + R*(theta_dot*cos(phi) + psi_dot*sin(phi)*sin(theta))"],
                    "parameters": {"m": 1.0, "R": 1.0, "I1": 1.0, "I2": 1.5, "I3": 2.0}}
