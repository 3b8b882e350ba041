"""Hamiltonization: Theorem 1, the time substitutions and the Poisson structures of the paper.

- :mod:`.reducing_multiplier`: Theorem 1 for a user's 2-DOF system (the front door) over
  :mod:`.reducing_multiplier_density` (ρ: ansatz, sympy integrate, line integral), :mod:`.monopole` (the
  charge of S̄ dq₁∧dq₂) and :mod:`.theorem_1` (Theorem 1 proved for arbitrary G, w, V, a, b and N).
- :mod:`.forms`: the Hamiltonian forms after a time substitution (Veselova → e(3), the ball → (L, γ)).
- :mod:`.poisson`: the Poisson structures: e(3), the ball's eq. 2604-6, generalized Chaplygin eq. 2704-9.
- :mod:`.local_forms`: the Euler-angle forms (eq. 2504-7/8, 003, 007) and Theorem 1's worked examples.
- :mod:`.structure`: a job's ``bracket`` and ``euler_angles`` checks.
"""
