"""A nonholonomic system given by a Lagrangian in the user's coordinates and constraints linear and
homogeneous in the velocities: parsing (safe parser, never eval), the checks, and the Lagrange–d'Alembert
equations of motion with the multipliers eliminated.

>>> from nonholonomic.lagrangian import parse_system, derive
>>> data = parse_system({"kind": "lagrangian", "coordinates": ["x", "y", "z"],
...                      "L": "(x_dot**2 + y_dot**2 + z_dot**2)/2", "constraints": ["z_dot - y*x_dot"]})
>>> eqs = derive(data)
>>> eqs.qddot[0]
-x_dot*y*y_dot/(y**2 + 1)
"""

from nonholonomic.lagrangian.equations import DerivationError, EquationsOfMotion, derive
from nonholonomic.lagrangian.parse import DataError, LagrangianData, lagrangian_data, parse_system

__all__ = ["DataError", "DerivationError", "EquationsOfMotion", "LagrangianData", "derive", "lagrangian_data",
           "parse_system"]
