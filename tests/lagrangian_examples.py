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
