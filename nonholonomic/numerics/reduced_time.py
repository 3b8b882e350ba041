"""The reduced time τ = ∫ N dt (eq. 2704-8) by quadrature along the integrator's dense output, where the
reducing multiplier N is not known to be analytic and positive on the orbit.

Why not integrate τ' = N beside the state, as for the paper's kinds: a Taylor step across a point where N
is not analytic continues N's Taylor polynomial, i.e. its analytic continuation. The Chaplygin skate's
N = √(1 − sin θ)·√(1 + sin θ) = |cos θ| was integrated as cos θ after each zero: τ(20) = 12.583977 where
∫|cos(0.4 + 1.7t)| dt = 12.619832 (issue 33).

Here, after each segment of the state's integration, its continuous output ``x(t)`` is integrated piece by
piece (the pieces between consecutive steps and sample times): Gauss–Legendre rules of :data:`NODES` and
2·:data:`NODES` points, a piece bisected while the two differ by more than :data:`PIECE_TOLERANCE` of its
parent piece's width times its largest |N| (at most :data:`MAX_BISECTIONS` times), so that a kink is
isolated in a piece about 1e-7 of a step wide. Everything is decided by the orbit's steps and samples,
never by the segment sizes or a clock: the same orbit gives the same τ.

Along the way the domain of the Hamiltonization is read off the nodes (the time change is one only where
N > 0): the times where N **vanishes** (a local minimum of |N| at most :data:`ZERO_FRACTION` of its parent
piece's largest |N|), where it **changes sign** (located by Brent's method) and where it stops being **real**
(a square root of a negative number; τ is NaN from there on).

The check: τ again at the sample times, by Romberg's method (:func:`scipy.integrate.romb`, 2^k + 1
equally spaced points, k raised until two levels agree) on the pieces between the samples, the segment ends
and the located zeros, independent of the Gauss–Legendre pieces and of the steps.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

#: Gauss–Legendre points of the coarse rule (the fine rule has twice as many).
NODES = 10
#: A piece is accepted when the two rules differ by at most this fraction of width × its parent's max |N|.
PIECE_TOLERANCE = 1e-14
#: Two halves whose differences sum to at least this fraction of their whole's are at N's rounding: accepted.
ROUNDOFF_RATIO = 0.7
#: Bisections of one step or sample interval at most (a kink needs about 25: a piece of 1e-7 of the step).
MAX_BISECTIONS = 40
#: An argument of |·|, √ ... at a local minimum at most this fraction of its max on the piece vanishes there.
KINK_FRACTION = 1e-9
#: |N| at a local minimum at most this fraction of its parent piece's max |N|: N vanishes there (N's own
#: rounding near a zero can be ~√ε: √(1 − sin θ) where sin θ is 1 to the last bit).
ZERO_FRACTION = 1e-6
#: Times listed per kind of event (the counts are complete).
MAX_LISTED = 50
#: Romberg levels of the check (2^k + 1 points per piece, k ≤ this).
ROMBERG_MAX_LEVEL = 14
#: The check passes when |τ − τ_Romberg| ≤ this × (1 + max |τ|).
CHECK_TOLERANCE = 1e-9

_X1, _W1 = np.polynomial.legendre.leggauss(NODES)
_X2, _W2 = np.polynomial.legendre.leggauss(2 * NODES)

#: ``states_at(times) -> (len(times), n)``: the dense output of one segment.
StatesAt = Callable[[np.ndarray], np.ndarray]
#: ``density(states) -> N`` at each row.
Density = Callable[[np.ndarray], np.ndarray]


@dataclass
class ReducedTimeReport:
    """How τ was integrated and where the Hamiltonization's domain ends (JSON-able fields).

    Attributes
    ----------
    zeros, sign_changes : list of float
        The first :data:`MAX_LISTED` times where N vanishes without changing sign, and where it changes sign.
    zero_count, sign_change_count : int
        All of them.
    not_real_from : float or None
        The time from which N is not real (τ is NaN after it).
    pieces, at_rounding, unconverged : int
        Gauss–Legendre pieces; those accepted because bisecting them no longer shrank the rules' difference
        (N's rounding); those still past the tolerance after :data:`MAX_BISECTIONS`.
    error_estimate : float
        Σ |fine − coarse| over the pieces (the coarse rule's error; the fine rule's is far smaller).
    check_residual, check_error_estimate : float
        max |τ − τ_Romberg| at the samples, and Romberg's own error estimate (its last two levels).
    """

    zeros: list[float] = field(default_factory=list)
    sign_changes: list[float] = field(default_factory=list)
    zero_count: int = 0
    sign_change_count: int = 0
    not_real_from: float | None = None
    pieces: int = 0
    at_rounding: int = 0
    unconverged: int = 0
    error_estimate: float = 0.0
    check_residual: float = 0.0
    check_error_estimate: float = 0.0
    method: str = ("adaptive Gauss-Legendre (10 and 20 points) on the pieces between steps and samples of the "
                   "dense output, bisected at kinks")

    def positive_until(self) -> float | None:
        """The first time N stops being positive (a zero, a sign change, not real), or None."""
        firsts = [t[0] for t in (self.zeros, self.sign_changes) if t]
        if self.not_real_from is not None:
            firsts.append(self.not_real_from)
        return min(firsts) if firsts else None


def _rules(density: Density, states_at: StatesAt, a: np.ndarray, b: np.ndarray,
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both rules on the pieces [a, b]: (coarse, fine, the fine rule's nodes, N there)."""
    mid, half = (a + b) / 2, (b - a) / 2
    nodes = np.concatenate([_X1, _X2])
    t = mid[:, None] + half[:, None] * nodes[None, :]
    values = density(states_at(t.ravel())).reshape(t.shape)
    coarse = half * (values[:, :NODES] @ _W1)
    fine = half * (values[:, NODES:] @ _W2)
    return coarse, fine, t[:, NODES:], values[:, NODES:]


class DensityQuadrature:
    """τ along an orbit, fed segment by segment (:meth:`add`); ``report`` says where N vanished.

    Parameters
    ----------
    density : N at rows of states (the system's ``time_density`` kernel at the job's parameters).
    """

    def __init__(self, density: Density, kinks: Density | None = None) -> None:
        self.density = density
        self.kinks = kinks
        self.report = ReducedTimeReport()
        self.tau = 0.0  # at the end of the segments added so far
        self.check_tau = 0.0
        empty = np.empty(0)
        #: the previous segment's dense output and its nodes (t, N, scale) from its last one that is not small
        self._carry: tuple[StatesAt | None, tuple[np.ndarray, np.ndarray, np.ndarray]] = (None, (empty, empty, empty))
        self._max_tau = 0.0

    def add(self, states_at: StatesAt, breaks: np.ndarray, grid: np.ndarray) -> np.ndarray:
        """Integrate one segment of the dense output and return τ at ``grid``.

        Parameters
        ----------
        states_at : the segment's dense output.
        breaks : increasing times: the segment's step boundaries (its first and last times included).
        grid : the sample times in [breaks[0], breaks[-1]], non-decreasing.
        """
        if self.report.not_real_from is not None:
            return np.full(len(grid), np.nan)
        cuts = np.unique(np.concatenate([breaks, grid]))
        start, stop = float(cuts[0]), float(cuts[-1])
        a, b = cuts[:-1], cuts[1:]
        end = self._real_until(states_at, a, b)
        if end is not None:
            keep = a < end
            a, b = a[keep], np.minimum(b[keep], end)
        kinks = self._kinks(states_at, a, b)
        points = np.unique(np.concatenate([a, b, kinks])) if len(a) else np.array([start])
        increments, nodes_t, nodes_n, nodes_ref, scale = self._adaptive(states_at, points[:-1], points[1:])
        at_points = self.tau + np.concatenate([[0.0], np.cumsum(increments)])
        if len(kinks):  # N at each kink, as a node whose scale is its neighbouring pieces'
            k = np.searchsorted(points, kinks)
            ref = np.maximum(scale[k - 1], scale[np.minimum(k, len(scale) - 1)])
            nodes_t, nodes_n, nodes_ref = (np.concatenate([x, y]) for x, y in zip(
                (nodes_t, nodes_n, nodes_ref), (kinks, self.density(states_at(kinks)), ref)))
            order = np.argsort(nodes_t, kind="stable")
            nodes_t, nodes_n, nodes_ref = nodes_t[order], nodes_n[order], nodes_ref[order]
        events = self._events(states_at, start, nodes_t, nodes_n, nodes_ref)
        tau_grid = np.interp(grid, points, at_points)
        check = self._check(states_at, start, grid, end if end is not None else stop, [*kinks, *events])
        if end is not None:
            tau_grid[grid > end] = np.nan
            check[grid > end] = np.nan
        self.tau = float(at_points[-1])
        finite = np.isfinite(tau_grid) & np.isfinite(check)
        if finite.any():
            self.report.check_residual = max(self.report.check_residual,
                                             float(np.max(np.abs(tau_grid[finite] - check[finite]))))
            self._max_tau = max(self._max_tau, float(np.max(np.abs(tau_grid[finite]))))
        return tau_grid

    def _kinks(self, states_at: StatesAt, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The times inside the pieces where an argument of a function that is not analytic at 0 (``kinks``)
        vanishes: a sign change between samples (the Gauss–Legendre nodes and both ends of each piece) located
        by Brent's method, or a local minimum of its |value| below a tenth of the piece's max refined by bounded
        Brent and kept when at most :data:`KINK_FRACTION` of it (√(1 − sin θ): 1 − sin θ touches 0). A touching
        point is located as the root of the argument's rate (∇g, f) (a simple root, to 1e-15), not as the
        minimum of |g| (flat to rounding over ~√ε of the time)."""
        from scipy.optimize import brentq, minimize_scalar

        if self.kinks is None or not len(a):
            return np.empty(0)
        mid, half = (a + b) / 2, (b - a) / 2
        t = np.concatenate([a[:, None], mid[:, None] + half[:, None] * _X2[None, :], b[:, None]], axis=1)
        values = self.kinks(states_at(t.ravel())).reshape(*t.shape, -1)
        found: list[float] = []
        m = values.shape[2] // 2  # the arguments, then their rates of change

        def at(time: float, k: int) -> float:
            return float(self.kinks(states_at(np.array([time])))[0, k])  # type: ignore[misc]

        for k in range(m):
            g, rate = values[:, :, k], values[:, :, m + k]
            size = np.abs(g)
            scale = np.max(size, axis=1)
            rows, cols = np.nonzero(g[:, :-1] * g[:, 1:] < 0)
            found += [float(brentq(at, t[r, c], t[r, c + 1], args=(k,), xtol=1e-15, rtol=1e-15))
                      for r, c in zip(rows, cols)]
            left = np.concatenate([size[:, :1] + 1, size[:, :-1]], axis=1)  # no neighbour outside the piece
            right = np.concatenate([size[:, 1:], size[:, -1:] + 1], axis=1)
            same = np.ones_like(g, dtype=bool)
            same[:, 1:-1] = g[:, :-2] * g[:, 2:] > 0
            candidate = (size <= left) & (size <= right) & same & (size <= 0.1 * scale[:, None]) & (size > 0)
            for r, c in zip(*np.nonzero(candidate)):
                lo, hi = max(c - 1, 0), min(c + 1, t.shape[1] - 1)
                if rate[r, lo] * rate[r, hi] < 0:  # the touching point: g's rate changes sign (a simple root)
                    where = float(brentq(at, t[r, lo], t[r, hi], args=(m + k,), xtol=1e-15, rtol=1e-15))
                else:
                    span = (float(t[r, lo]), float(t[r, hi]))
                    where = float(minimize_scalar(lambda s, k=k: abs(at(s, k)), bounds=span, method="bounded",
                                                  options={"xatol": 1e-15 * max(1.0, abs(span[1]))}).x)
                if abs(at(where, k)) <= KINK_FRACTION * scale[r]:
                    found.append(where)
            rows, cols = np.nonzero(g[:, 1:-1] == 0)
            found += [float(t[r, c + 1]) for r, c in zip(rows, cols)]
        inside = np.unique(found)
        return inside[(inside > a[0]) & (inside < b[-1]) & ~np.isin(inside, b)]

    def check_passed(self) -> bool:
        """Whether τ agrees with the Romberg check within :data:`CHECK_TOLERANCE` · (1 + max |τ|)."""
        return self.report.check_residual <= CHECK_TOLERANCE * (1 + self._max_tau)

    def check_tolerance(self) -> float:
        return CHECK_TOLERANCE * (1 + self._max_tau)

    def _real_until(self, states_at: StatesAt, a: np.ndarray, b: np.ndarray) -> float | None:
        """The first time in the segment where N is not finite (to 1e-15 relative), or None."""
        if not len(a):
            return None
        _, _, t, values = _rules(self.density, states_at, a, b)
        ends = self.density(states_at(np.concatenate([a, b[-1:]])))
        bad_piece = np.flatnonzero(~np.isfinite(values).all(axis=1) | ~np.isfinite(ends[:-1]))
        if not len(bad_piece) and np.isfinite(ends[-1]):
            return None
        i = int(bad_piece[0]) if len(bad_piece) else len(a) - 1
        lo, hi = float(a[i]), float(b[i])
        if not np.isfinite(ends[i]):  # not finite from the piece's start: at the segment's start or a cut
            lo = hi = float(a[i])
        for _ in range(200):
            mid = (lo + hi) / 2
            if hi - lo <= 1e-15 * max(1.0, abs(hi)) or mid in (lo, hi):
                break
            lo, hi = (mid, hi) if np.isfinite(self.density(states_at(np.array([mid])))[0]) else (lo, mid)
        self.report.not_real_from = lo
        return lo

    def _adaptive(self, states_at: StatesAt, a: np.ndarray, b: np.ndarray,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The integral over each piece [a_i, b_i]; the fine rule's nodes, N there and the parent piece's
        max |N| at each node, sorted by time; each piece's max |N| at its nodes.

        A sub-piece is accepted when the rules differ by at most :data:`PIECE_TOLERANCE` × its parent's width
        × its parent's max |N| (absolute, not relative to the sub-piece: near a kink N is evaluated with a
        rounding error of ~√ε, e.g. √(1 − sin θ) where sin θ ≈ 1, which no bisection removes), or when
        bisecting it did not shrink the difference (the two halves' sum at least :data:`ROUNDOFF_RATIO` of the
        whole's: N's own rounding, e.g. cos θ for θ ~ 3000 changes in steps of 1e-13, and no truncation error,
        which falls 4 times or more per bisection at a kink)."""
        report = self.report
        total = np.zeros(len(a))
        owner = np.arange(len(a))
        width = b - a
        scale = first_scale = np.zeros(len(a))
        kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        halves, whole_error = 0, np.empty(0)  # pieces i and i + halves are the halves of one with whole_error[i]
        for depth in range(MAX_BISECTIONS + 1):
            if not len(a):
                break
            coarse, fine, t, values = _rules(self.density, states_at, a, b)
            if depth == 0:
                scale = first_scale = np.max(np.abs(values), axis=1)
            error = np.abs(fine - coarse)
            ok = error <= PIECE_TOLERANCE * width[owner] * scale[owner]
            if halves:
                stalled = error[:halves] + error[halves:] >= ROUNDOFF_RATIO * whole_error
                report.at_rounding += 2 * int(np.count_nonzero(stalled & ~(ok[:halves] & ok[halves:])))
                ok |= np.concatenate([stalled, stalled])
            if depth == MAX_BISECTIONS:
                report.unconverged += int(np.count_nonzero(~ok))
                ok[:] = True
            np.add.at(total, owner[ok], fine[ok])
            report.error_estimate += float(np.sum(error[ok]))
            report.pieces += int(np.count_nonzero(ok))
            kept.append((t[ok].ravel(), values[ok].ravel(), np.repeat(scale[owner[ok]], t.shape[1])))
            mid = (a[~ok] + b[~ok]) / 2
            a, b = np.concatenate([a[~ok], mid]), np.concatenate([mid, b[~ok]])
            owner = np.concatenate([owner[~ok], owner[~ok]])
            halves, whole_error = len(mid), error[~ok]
        nodes_t, nodes_n, nodes_ref = (np.concatenate([k[i] for k in kept]) if kept else np.empty(0) for i in range(3))
        order = np.argsort(nodes_t, kind="stable")
        return total, nodes_t[order], nodes_n[order], nodes_ref[order], first_scale

    def _events(self, states_at: StatesAt, start: float, t: np.ndarray, n: np.ndarray, ref: np.ndarray,
                ) -> list[float]:
        """Where N vanishes or changes sign among the nodes (sorted by time) of the segment starting at
        ``start``; returns the segment's events (all of them, for the check's cuts).

        A node is *small* when |N| ≤ :data:`ZERO_FRACTION` × ``ref`` (its parent piece's max |N|); a run of
        consecutive small nodes is one event (at its smallest node), a sign change if the nodes on either side
        differ in sign. Between two nodes that are not small, a sign change is located by Brent's method, and a
        local minimum of |N| below a tenth of ``ref`` is refined (bounded Brent) and is a zero if the minimum
        is small. A run that reaches the segment's end waits for the next segment (the nodes from the last one
        that is not small are carried over, with the previous dense output)."""
        from scipy.optimize import brentq, minimize_scalar

        previous, carried = self._carry
        t, n, ref = (np.concatenate([old, new]) for old, new in zip(carried, (t, n, ref)))
        skip = len(carried[0]) - 1  # pairs and minima before this index were decided with the previous segment
        small = np.abs(n) <= ZERO_FRACTION * ref
        big = np.flatnonzero(~small)
        last = int(big[-1]) if len(big) else -1
        keep_from = max(0, last - 1) if last >= 0 else 0
        self._carry = (states_at, (t[keep_from:], n[keep_from:], ref[keep_from:]))
        report, events = self.report, []

        def at(time: float) -> float:
            where = states_at if time >= start or previous is None else previous
            return float(self.density(where(np.array([time])))[0])

        def emit(time: float, sign_change: bool) -> None:
            events.append(time)
            if sign_change:
                report.sign_change_count += 1
                if len(report.sign_changes) < MAX_LISTED:
                    report.sign_changes.append(time)
            else:
                report.zero_count += 1
                if len(report.zeros) < MAX_LISTED:
                    report.zeros.append(time)

        # runs of small nodes that end before the last node that is not small
        i = max(skip, 0)
        while i < last:
            if not small[i]:
                i += 1
                continue
            j = i
            while small[j + 1]:
                j += 1
            run = slice(i, j + 1)
            at_min = i + int(np.argmin(np.abs(n[run])))
            emit(float(t[at_min]), i > 0 and n[i - 1] * n[j + 1] < 0)
            i = j + 1
        # sign changes and near-zero minima between nodes that are not small
        pairs = big[:-1][(np.diff(big) == 1) & (big[:-1] >= max(skip, 0))]
        for i in pairs[n[pairs] * n[pairs + 1] < 0]:
            emit(float(brentq(at, t[i], t[i + 1], xtol=1e-15, rtol=1e-15)), True)
        size = np.abs(n)
        inner = big[(big >= max(skip, 1)) & (big < last)]
        inner = inner[~small[inner - 1] & ~small[inner + 1]]
        minima = inner[(size[inner] <= size[inner - 1]) & (size[inner] <= size[inner + 1])
                       & (n[inner - 1] * n[inner + 1] > 0) & (size[inner] <= 0.1 * ref[inner])]
        for i in minima:
            span = (float(t[i - 1]), float(t[i + 1]))
            best = minimize_scalar(lambda s: abs(at(s)), bounds=span, method="bounded",
                                   options={"xatol": 1e-15 * max(1.0, abs(span[1]))})
            if float(best.fun) <= ZERO_FRACTION * ref[i]:
                emit(float(best.x), False)
        for listed in (report.zeros, report.sign_changes):
            listed.sort()
        return sorted(events)

    def _check(self, states_at: StatesAt, start: float, grid: np.ndarray, end: float, events: list[float],
               ) -> np.ndarray:
        """τ at ``grid`` by Romberg's method on the pieces between the samples, the ends and the events found."""
        from scipy.integrate import romb

        known = [z for z in events if start < z < end]
        inside = grid[(grid > start) & (grid < end)]
        cuts = np.unique(np.concatenate([[start, end], inside, known]))
        a, b = cuts[:-1], cuts[1:]
        previous, spread = None, float("inf")
        estimate = np.zeros(len(a))
        for level in range(4, ROMBERG_MAX_LEVEL + 1):
            k = 2**level
            s = np.linspace(0.0, 1.0, k + 1)
            t = a[:, None] + (b - a)[:, None] * s[None, :]
            values = self.density(states_at(t.ravel())).reshape(t.shape)
            estimate = romb(values, dx=1.0 / k, axis=1) * (b - a)
            if previous is not None:
                spread = float(np.sum(np.abs(estimate - previous)))
                if spread <= 1e-13 * (1 + float(np.sum(np.abs(estimate)))):
                    break
            previous = estimate
        self.report.check_error_estimate += spread
        at_cuts = self.check_tau + np.concatenate([[0.0], np.cumsum(estimate)])
        self.check_tau = float(at_cuts[-1])
        return np.interp(grid, cuts, at_cuts)
