"""Numerics derived from a system's one symbolic definition.

- :mod:`.kernels`: numpy kernels generated from a definition (the right-hand side, integrals, checks).
- :mod:`.numpy_function`: lambdify to numpy, picklable as its source (so kernels can be remembered).
- :mod:`.taylor`: the heyoka form of a definition (shared subexpressions, parameter-only terms hoisted).
- :mod:`.integration`: one orbit with heyoka's Taylor integrator (compiled once per process) or scipy's
  DOP853 (the cross-check engine).
- :mod:`.integration_batch`: many members at once in heyoka's batch mode (SIMD lanes).
- :mod:`.precision`: mpmath's working precision kept per thread (threads of one process do not interfere).
"""
