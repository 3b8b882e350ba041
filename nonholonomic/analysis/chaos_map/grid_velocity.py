"""A grid cell's velocity: the free velocity components that put a cell's position on the level set.

The relations a cell's velocity must satisfy are the constraints that involve it ((ω, γ) = 0) and the
level's integrals other than the energy, each read off the system's kernels at the cell's position:

- all linear in the velocity ((M, γ) = c): they leave a line ``v₀ + t n``, on which the energy is
  quadratic: two candidates (:func:`velocities`);
- one of them quadratic (the Jacobi problem's K, eq. 2804-4): the linear ones leave a plane
  ``v₀ + s n₁ + t n₂`` on which the energy and that integral are two conics; their common points are
  the roots of the resultant in t (a quartic) and each is polished by Newton's method on both: up to
  four candidates.

Every coefficient is read numerically from the kernels (a quadratic is fixed by its values at six
points and checked at a seventh), so any kind whose level is linear or quadratic in the velocity works.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
from numpy.polynomial import polynomial as poly

from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.kernels import NumericSystem

#: A relation is linear where its second difference is below this (relative to its first).
LINEAR_TOLERANCE = 1e-9
#: Newton steps polishing a common point of two conics.
NEWTON_STEPS = 6


class VelocityError(ValueError):
    """The level's relations do not fix the velocity up to finitely many points (the reason)."""


def quadratic_roots(c0: np.ndarray, c1: np.ndarray, c2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both real roots of c0 + c1 t + c2 t² (the larger first; NaN where none), stably."""
    disc = c1 * c1 - 4 * c2 * c0
    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
    q = -(c1 + np.where(c1 >= 0, 1.0, -1.0) * root) / 2
    with np.errstate(all="ignore"):
        r1 = np.where(c2 != 0, q / c2, np.where(c1 != 0, -c0 / c1, np.nan))
        r2 = np.where(q != 0, c0 / q, np.where(c2 != 0, r1, np.nan))
    return np.fmax(r1, r2), np.fmin(r1, r2)


def velocities(kern: NumericSystem, p: np.ndarray, system: MechanicalSystem, relations: Sequence[tuple[str, int]],
               free: Sequence[int], states: np.ndarray, targets: Mapping[str, float]) -> list[np.ndarray]:
    """Candidates for the free velocity components (each of shape ``(cells, len(free))``, NaN where a
    cell has fewer), from the relations ``("constraint" | "integral", index)`` and the energy.

    Raises
    ------
    VelocityError
        More than one relation not linear in the velocity, or one of degree above 2.
    """
    free = list(free)
    zero = states.copy()
    zero[:, free] = 0.0

    def values(x: np.ndarray) -> np.ndarray:
        cols, cons, ints = [], None, None
        for kind, i in relations:
            if kind == "constraint":
                cons = kern.constraints(x, p) if cons is None else cons
                cols.append(cons[:, i] - system.constraints[i].value)
            else:
                ints = kern.integrals(x, p) if ints is None else ints
                cols.append(ints[:, i] - targets[system.integrals[i].name])
        return np.column_stack(cols) if cols else np.zeros((len(x), 0))

    r0 = values(zero)
    G = np.empty((len(states), r0.shape[1], len(free)))
    curved = np.zeros(r0.shape[1], bool)
    for j, k in enumerate(free):
        trial = zero.copy()
        trial[:, k] = 1.0
        G[:, :, j] = values(trial) - r0
        trial[:, k] = 2.0
        bent = values(trial) - r0 - 2 * G[:, :, j]
        with np.errstate(invalid="ignore"):
            curved |= np.any(np.abs(bent) > LINEAR_TOLERANCE * np.maximum(1.0, np.abs(G[:, :, j])), axis=0)
    linear = np.flatnonzero(~curved)
    finite = np.all(np.isfinite(G), axis=(1, 2))
    if finite.any() and np.any(np.all(np.abs(G[finite]) == 0, axis=(0, 2))):
        raise VelocityError("a relation of the level does not involve the velocity (it fixes positions only): "
                            "a map's level fixes the energy and integrals of the velocity")
    bad = ~(np.all(np.isfinite(G), axis=(1, 2)) & np.all(np.isfinite(r0), axis=1))
    G[bad], r0[bad] = 1.0, 0.0  # cells whose position has no root: any finite stand-in, NaN again below
    basis, particular = _affine(G[:, linear, :], r0[:, linear], len(free))
    energy = [i.name for i in system.integrals].index("energy")

    def at(point: np.ndarray) -> np.ndarray:
        """Energy − h and the curved relations at ``particular + basis @ point`` (point: (cells, dim))."""
        trial = zero.copy()
        trial[:, free] = particular + np.einsum("cjd,cd->cj", basis, point)
        out = [kern.integrals(trial, p)[:, energy] - targets["energy"]]
        if curved.any():
            out += list(values(trial)[:, curved].T)
        return np.column_stack(out)

    dim = basis.shape[2]
    if curved.sum() == 0 and dim == 1:
        c0, plus, minus = (at(np.zeros((len(G), 1)))[:, 0], at(np.ones((len(G), 1)))[:, 0],
                           at(-np.ones((len(G), 1)))[:, 0])
        t1, t2 = quadratic_roots(c0, (plus - minus) / 2, (plus + minus) / 2 - c0)
        points = [t1[:, None], t2[:, None]]
    elif curved.sum() == 1 and dim == 2:
        points = _conic_points(at, len(G))
    else:
        raise VelocityError(f"{int(curved.sum())} relations of the level are not linear in the velocity and "
                            f"{dim} velocity directions remain: a map fixes the energy, integrals linear in the "
                            "velocity and at most one quadratic one, one direction per quadratic")
    out = []
    for point in points:
        v = particular + np.einsum("cjd,cd->cj", basis, point)
        v[bad] = np.nan
        out.append(v)
    return out


def _affine(G: np.ndarray, r0: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The solutions of ``G v + r0 = 0`` as ``particular + basis @ u`` (basis: (cells, n, n − rank))."""
    if G.shape[1] == 0:
        return np.broadcast_to(np.eye(n), (len(G), n, n)).copy(), np.zeros((len(G), n))
    _, _, vt = np.linalg.svd(G)
    rows = G.shape[1]
    basis = np.transpose(vt[:, rows:, :], (0, 2, 1))
    particular = -np.einsum("cij,cj->ci", np.linalg.pinv(G), r0)
    return basis, particular


#: Points fixing a quadratic in (s, t): (0, 0), (±1, 0), (0, ±1), (1, 1); (1, −1) checks it.
_PROBES = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1]], dtype=float)


def _conic_points(at: Callable[[np.ndarray], np.ndarray], cells: int) -> list[np.ndarray]:
    """The common points of two conics F_k(s, t) = a s² + b st + c t² + d s + e t + f = 0 (the energy and
    one curved relation), per cell: up to four, NaN-padded, ordered by s then t."""
    values = np.stack([at(np.broadcast_to(q, (cells, 2)).copy()) for q in _PROBES])  # (probe, cell, 2)
    f = values[0]
    a = (values[1] + values[2]) / 2 - f
    d = (values[1] - values[2]) / 2
    c = (values[3] + values[4]) / 2 - f
    e = (values[3] - values[4]) / 2
    b = values[5] - a - c - d - e - f
    check = a + c - b + d - e + f  # at (1, -1)
    scale = np.maximum(np.max(np.abs(values), axis=0), 1e-300)
    with np.errstate(invalid="ignore"):
        if np.any(np.abs(check - values[6]) > 1e-8 * scale):
            raise VelocityError("a relation of the level is of degree above 2 in the velocity")
    out = np.full((4, cells, 2), np.nan)
    for cell in range(cells):
        coef = [(a[cell, k], b[cell, k], c[cell, k], d[cell, k], e[cell, k], f[cell, k]) for k in range(2)]
        if not all(np.isfinite(x) for row in coef for x in row):
            continue
        found = sorted(_intersect(coef[0], coef[1]))
        for i, point in enumerate(found[:4]):
            out[i, cell] = point
    return [out[i] for i in range(4)]


def _intersect(p: tuple[float, ...], q: tuple[float, ...]) -> list[tuple[float, float]]:
    """Real common points of two conics (a, b, c, d, e, f) in (s, t), by the resultant in s."""
    def parts(k: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b, c, d, e, f = k
        return np.array([a]), np.array([d, b]), np.array([f, e, c])  # s², s¹, s⁰ coefficients as polys in t

    A1, B1, C1 = parts(p)
    A2, B2, C2 = parts(q)
    X = poly.polysub(poly.polymul(A1, C2), poly.polymul(A2, C1))
    Y = poly.polysub(poly.polymul(A1, B2), poly.polymul(A2, B1))
    Z = poly.polysub(poly.polymul(B1, C2), poly.polymul(B2, C1))
    R = poly.polysub(poly.polymul(X, X), poly.polymul(Y, Z))
    size = np.max(np.abs(R)) if len(R) else 0.0
    if not size:
        return []
    R = np.trim_zeros(R / size, "b")
    while len(R) > 1 and abs(R[-1]) < 1e-14:
        R = R[:-1]
    roots = poly.polyroots(R) if len(R) > 1 else np.array([])
    out: list[tuple[float, float]] = []
    for t in roots[np.abs(roots.imag) <= 1e-6 * (1 + np.abs(roots.real))].real:
        y, x = poly.polyval(t, Y), poly.polyval(t, X)
        if abs(y) > 1e-12 * (1 + abs(x)):
            candidates = [-x / y]
        else:  # the s-quadratics are proportional here: the roots of the first
            candidates = list(np.roots([p[0], p[1] * t + p[3], p[2] * t * t + p[4] * t + p[5]]).real)
        for s in candidates:
            point = _newton(p, q, s, t)
            if point is not None and all(np.hypot(point[0] - u, point[1] - v) > 1e-9 * (1 + abs(u) + abs(v))
                                         for u, v in out):
                out.append(point)
    return out


def _newton(p: tuple[float, ...], q: tuple[float, ...], s: float, t: float) -> tuple[float, float] | None:
    """Newton's method on both conics from (s, t); None if it does not land on both."""
    def value(k: tuple[float, ...], s: float, t: float) -> tuple[float, float, float]:
        a, b, c, d, e, f = k
        return (a * s * s + b * s * t + c * t * t + d * s + e * t + f, 2 * a * s + b * t + d, b * s + 2 * c * t + e)

    for _ in range(NEWTON_STEPS):
        f1, f1s, f1t = value(p, s, t)
        f2, f2s, f2t = value(q, s, t)
        det = f1s * f2t - f1t * f2s
        if det == 0 or not np.isfinite(det):
            break
        s, t = s - (f1 * f2t - f2 * f1t) / det, t - (f2 * f1s - f1 * f2s) / det
    f1, _, _ = value(p, s, t)
    f2, _, _ = value(q, s, t)
    size = 1 + abs(s) + abs(t)
    scale1 = max(abs(x) for x in p) * size * size
    scale2 = max(abs(x) for x in q) * size * size
    if np.isfinite(s) and np.isfinite(t) and abs(f1) <= 1e-10 * scale1 and abs(f2) <= 1e-10 * scale2:
        return float(s), float(t)
    return None
