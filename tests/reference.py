"""Independent references for Chaplygin's ball, written from the paper's equations (2604-1) with
plain numpy (ω by a linear solve, not the core's Sherman–Morrison form)."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def ball_rhs(inertia: np.ndarray, D: float, a: np.ndarray | None = None, k: float = 0.0):
    """f(t, y) for y = (M, γ): dM/dt = M×ω + γ×∂U/∂γ, dγ/dt = γ×ω, I_Q ω = M."""
    inertia = np.asarray(inertia, dtype=float)
    a = np.zeros(3) if a is None else np.asarray(a, dtype=float)

    def f(t: float, y: np.ndarray) -> np.ndarray:
        M, g = y[:3], y[3:]
        IQ = np.diag(inertia + D) - D * np.outer(g, g)
        w = np.linalg.solve(IQ, M)
        dU = a + k * inertia * g
        return np.concatenate([np.cross(M, w) + np.cross(g, dU), np.cross(g, w)])

    return f


def ball_reference(inertia, D, y0, t_final, a=None, k=0.0, rtol=1e-13):
    """scipy DOP853 solution of the ball at ``t_final`` (rtol = atol)."""
    sol = solve_ivp(ball_rhs(inertia, D, a, k), (0.0, t_final), np.asarray(y0, dtype=float), method="DOP853",
                    rtol=rtol, atol=rtol)
    assert sol.success, sol.message
    return sol.y[:, -1]
