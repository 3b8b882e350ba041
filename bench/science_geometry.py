"""The measures (neighbour order, roughness, exponent growth) and the charts and states of the
section (Jacobi problem and Chaplygin's ball), plain numpy and scipy, independent of the service's
code; tests/unit/test_science.py uses them through bench/science.py. Part of bench/science.py.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from science_config import MIN_POINTS
from scipy.optimize import brentq
from scipy.spatial import cKDTree

# --------------------------------------------------------------------------------------------------
# Measures (pure numpy; tests/unit/test_science.py uses them)
# --------------------------------------------------------------------------------------------------

def neighbour_order(points: np.ndarray, scale: np.ndarray | None = None, k: int = 3, top: int = 3) -> float:
    """Fraction of the points (rows, in time order) with one of their ``k`` nearest neighbours at one of
    the ``top`` most frequent index offsets |j − i| (over all the points' k neighbours): ≈ 1 on an
    invariant curve (three-distance theorem), small in a chaotic sea or layer. NaN below
    :data:`MIN_POINTS` points."""
    P = np.asarray(points, dtype=float)
    if len(P) < MIN_POINTS:
        return math.nan
    s = np.std(P, axis=0) if scale is None else np.asarray(scale, dtype=float)
    s = np.where(s > 0, s, 1.0)
    Z = P / s
    _, idx = cKDTree(Z).query(Z, k=k + 1)
    offsets = np.abs(idx[:, 1:] - np.arange(len(Z))[:, None])
    values, counts = np.unique(offsets, return_counts=True)
    frequent = values[np.argsort(counts, kind="stable")[::-1][:top]]
    return float(np.mean(np.isin(offsets, frequent).any(axis=1)))


def roughness(points: np.ndarray, scale: np.ndarray | None = None, k: int = 12) -> float:
    """Median over the points of s2/s1 of the centred k nearest neighbours: ~0 on a curve, O(1) on an area."""
    P = np.asarray(points, dtype=float)
    if len(P) < max(MIN_POINTS, k + 2):
        return math.nan
    s = np.std(P, axis=0) if scale is None else np.asarray(scale, dtype=float)
    Z = P / np.where(s > 0, s, 1.0)
    _, idx = cKDTree(Z).query(Z, k=k + 1)
    nb = Z[idx] - Z[idx].mean(axis=1, keepdims=True)
    sv = np.linalg.svd(nb, compute_uv=False)
    return float(np.median(sv[:, 1] / sv[:, 0]))


def exponent_measures(t: Sequence[float], lam: Sequence[float], t_final: float) -> dict[str, float]:
    """From the running largest exponent λ(t): λ at t_final/10 and at t_final, their ratio, λ·T/ln T and
    the growth power p of |v| = exp(λ(t) t) ~ t^p over [t_final/30, t_final]."""
    t, lam = np.asarray(t, dtype=float), np.asarray(lam, dtype=float)
    early = float(np.interp(t_final / 10, t, lam))
    final = float(lam[-1])
    keep = t >= t_final / 30
    growth = float(np.polyfit(np.log(t[keep]), lam[keep] * t[keep], 1)[0])
    return {"lambda_early": early, "lambda_final": final, "ratio": final / early if early else math.nan,
            "lambda_t_over_ln_t": final * t_final / math.log(t_final), "growth": growth}


# --------------------------------------------------------------------------------------------------
# Charts and states (plain numpy, independent of the service's code)
# --------------------------------------------------------------------------------------------------

def wrap(angle: np.ndarray | float) -> np.ndarray | float:
    """Angle to (−π, π]."""
    return np.angle(np.exp(1j * np.asarray(angle)))


def jacobi_chart(x: np.ndarray, omega: np.ndarray, B: Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ = atan2(x3/√b3, x1/√b1) on the ellipse x2 = 0, ω2, and a = (ω, n), n = B⁻¹x/|B⁻¹x|."""
    b = np.asarray(B, dtype=float)
    n = x / b
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.arctan2(x[:, 2] / math.sqrt(b[2]), x[:, 0] / math.sqrt(b[0])), omega[:, 1], np.sum(omega * n, axis=1)


def ball_chart(M: np.ndarray, gamma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """φ = atan2(γ2, γ1) on the equator γ3 = 0, and M3."""
    return np.arctan2(gamma[:, 1], gamma[:, 0]), M[:, 2]


def jacobi_state(theta: float, w2: float, energy: float, K: float, system: dict, a_sign: float = 1.0) -> dict | None:
    """The state on the level (H, K) at x = (√b1 cos θ, 0, √b3 sin θ) with ω2 = w2, x2 increasing and
    sign(a) = a_sign, or None if the level is not reached there. ω = w + a n, w ⊥ n; K depends on w
    only (eq. 2804-4), H = D0 a²/2 + (D0 + D) w²/2 (eq. 2804-2, ERRATA 12)."""
    b = np.asarray(system["B"], dtype=float)
    D0, D, R = system["D0"], system["m"] * system["R"] ** 2, system["R"]
    x = np.array([math.sqrt(b[0]) * math.cos(theta), 0.0, math.sqrt(b[2]) * math.sin(theta)])
    n = x / b
    n /= np.linalg.norm(n)
    e2 = np.array([0.0, 1.0, 0.0])
    t = np.cross(e2, n)

    def K_of(w: np.ndarray) -> float:
        wn = np.cross(w, n)
        return float(wn @ (wn / b) / (n @ (b * n)))

    k0, kp, km = K_of(w2 * e2), K_of(w2 * e2 + t), K_of(w2 * e2 - t)
    k2, k1 = (kp + km) / 2 - k0, (kp - km) / 2
    disc = k1 * k1 - 4 * k2 * (k0 - K)
    if disc < 0:
        return None
    for wt in ((-k1 + math.sqrt(disc)) / (2 * k2), (-k1 - math.sqrt(disc)) / (2 * k2)):
        w = w2 * e2 + wt * t
        if R * np.cross(w, n)[1] > 0:      # dx2/dt = R (ω × n)_2 > 0
            break
    else:
        return None
    a2 = 2 * (energy - (D0 + D) * (w @ w) / 2) / D0
    if a2 < 0:
        return None
    return {"x": x.tolist(), "omega": (w + a_sign * math.sqrt(a2) * n).tolist()}


def ball_omega(M: np.ndarray, gamma: np.ndarray, inertia: Sequence[float], D: float) -> np.ndarray:
    """ω = I_Q⁻¹ M, I_Q = diag(I + D) − D γ⊗γ (eq. 2604-1), by a linear solve."""
    IQ = np.diag(np.asarray(inertia, dtype=float) + D) - D * np.outer(gamma, gamma)
    return np.linalg.solve(IQ, M)


def ball_energy(M: np.ndarray, gamma: np.ndarray, inertia: Sequence[float], D: float) -> float:
    return float(M @ ball_omega(M, gamma, inertia, D)) / 2


def ball_state(phi: float, M3: float, energy: float, area: float, system: dict) -> dict | None:
    """The ball's (U = 0) state on the level (H, c) at γ = (cos φ, sin φ, 0) with this M3 and γ3
    increasing, or None. M = c γ + M3 e3 + m e_φ, H quadratic in m; (γ × ω)_3 > 0 picks the root."""
    inertia, D = system["inertia"], system["D"]
    g = np.array([math.cos(phi), math.sin(phi), 0.0])
    e = np.array([-math.sin(phi), math.cos(phi), 0.0])
    base = area * g + np.array([0.0, 0.0, M3])
    e0, ep, em = (ball_energy(base + s * e, g, inertia, D) for s in (0.0, 1.0, -1.0))
    c2, c1 = (ep + em) / 2 - e0, (ep - em) / 2
    disc = c1 * c1 - 4 * c2 * (e0 - energy)
    if disc < 0:
        return None
    for m in ((-c1 + math.sqrt(disc)) / (2 * c2), (-c1 - math.sqrt(disc)) / (2 * c2)):
        M = base + m * e
        if np.cross(g, ball_omega(M, g, inertia, D))[2] > 0:
            return {"M": M.tolist(), "gamma": g.tolist()}
    return None


def ball_on_torus(phi: float, energy: float, area: float, F: float, M3_guess: float, system: dict) -> dict:
    """The state at γ = (cos φ, sin φ, 0), γ3 increasing, on the torus H = energy, (M, γ) = area,
    (M, M) = F (eq. 2604-2, 2604-4) whose M3 is nearest ``M3_guess`` (the same connected component).
    M = c γ + M3 e3 + m e_φ with m² = F − c² − M3²; H(M3) = energy is solved by bracketing and Brent."""
    inertia, D = system["inertia"], system["D"]
    g = np.array([math.cos(phi), math.sin(phi), 0.0])
    e = np.array([-math.sin(phi), math.cos(phi), 0.0])
    rest = F - area * area
    best: tuple[float, np.ndarray] | None = None
    for sign in (1.0, -1.0):
        def M_of(M3: float, sign: float = sign) -> np.ndarray:
            return area * g + np.array([0.0, 0.0, M3]) + sign * math.sqrt(max(rest - M3 * M3, 0.0)) * e

        def residual(M3: float) -> float:
            return ball_energy(M_of(M3), g, inertia, D) - energy

        grid = np.linspace(-math.sqrt(rest), math.sqrt(rest), 2001)
        values = np.array([residual(v) for v in grid])
        for i in np.nonzero(np.sign(values[:-1]) != np.sign(values[1:]))[0]:
            root = brentq(residual, grid[i], grid[i + 1], xtol=1e-16, rtol=1e-15)
            M = M_of(root)
            if np.cross(g, ball_omega(M, g, inertia, D))[2] > 0 and (
                    best is None or abs(root - M3_guess) < abs(best[0] - M3_guess)):
                best = (root, M)
    if best is None:
        raise ValueError(f"no state on the torus F = {F} at phi = {phi}")
    return {"M": best[1].tolist(), "gamma": g.tolist()}
