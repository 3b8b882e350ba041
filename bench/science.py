"""Three open questions of the paper, settled through the API (embedded mode, in-process).

Run from the repository root::

    .venv/bin/python bench/science.py --quick            # ~1 min: every study, small and short
    .venv/bin/python bench/science.py                    # ~10 min on 2 cores: the numbers of bench/SCIENCE.md
    .venv/bin/python bench/science.py --out /tmp/science # also the section CSVs (the API's export), the
                                                         # requests, the numbers as JSON and, if matplotlib
                                                         # is importable, PNG plots of the sections

Every computation is a request to ``POST /v1/ensembles`` or ``POST /v1/jobs`` of
``service.main.create_app()`` through FastAPI's TestClient; each ensemble request is printed as the
JSON it posts (``REQUEST name: POST /v1/ensembles`` and the body on the next line), so it can be
posted to a running service with curl. The analysis of the answers (below) is plain numpy.

1. The nonholonomic Jacobi problem on a triaxial ellipsoid, U = 0 (paper, section "Nonholonomic
   Jacobi problem"; ERRATA "Open"): chaotic or not? An ensemble on one (H, K) level, the section
   x2 = 0 (increasing) and every member's largest exponent, beside the integrable Chaplygin ball
   (U = 0), the quadric in a linear field (chaotic), and a separatrix probe: orbits started next to
   the separatrices found by bisection on a symmetric line of the section, where a non-integrable
   system has its chaotic layers and an integrable one has none (the same probe on the integrable
   ball and on the integrable ellipsoid of revolution is the control).
2. [b008]: on a resonant torus of Chaplygin's ball (U = 0) the closed orbits have equal periods in
   τ (dτ = ρ_μ dt, eq. 2604-5) and different periods in t. The torus is found by root-finding the
   q-th return of the section on the line φ = 0; the periods of several orbits on it, and on a
   non-resonant torus as the control.
3. Chaplygin's ball in a linear field beside U = 0 on the same (H, c) level: the fraction of
   members with a chaotic signature.

Measures (per member; validated on the integrable ball and the ball in a linear field):

* ``growth``: the power p of the tangent vector's growth, |v(t)| ~ t^p, the slope of
  ln|v(t)| = λ(t)·t against ln t over [t_final/30, t_final] from the running exponent the API
  reports. A regular orbit (a torus) shears tangent vectors linearly: p ≈ 1 and λ(t) ≈ (ln t + c)/t;
  on a chaotic orbit ln|v| ≈ λt, so p ≈ λt ≫ 1. Chaotic if p > 3. Also shown: λ at t_final/10 and at
  t_final and their ratio (ln t/t predicts 0.13 for a decade at 1e3 → 1e4; a plateau gives ~1).
* ``order``: the fraction of section points that have, among their 3 nearest neighbours (in the state
  vector at the crossings, each component scaled by its spread over the ensemble), one at an index
  offset |j − i| that is among the three most frequent offsets of the orbit. On an invariant curve
  the return map is a rotation in a smooth angle, and by the three-distance theorem the neighbours
  along the curve sit at no more than three index offsets: order ≈ 1 (3 neighbours, not 1, so that
  a thin island loop whose other side is as near as the next point along it still counts). In a
  chaotic sea or layer the nearest points in space come from random times. Calibrated on the
  controls: ≥ 0.79 for every regular orbit, ≤ 0.51 for every chaotic one of the ball in a linear
  field; not on a curve if order < 0.65.
* ``rough``: the median over the points of s2/s1, the singular values of each point's 12 nearest
  neighbours (a local dimension): ~0.005 on a resolved curve, ~0.7 in a 2-D sea. It misses thin
  chaotic layers (a band thinner than the point spacing looks like a curve) and flags thin regular
  island loops (both sides within the 12 neighbours), so it is shown, not used to classify.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import csv  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import os  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import brentq  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

# --------------------------------------------------------------------------------------------------
# The systems, levels and analysis blocks (request fragments)
# --------------------------------------------------------------------------------------------------

#: The catalog's Jacobi problem: a solid ball (D0 = 2/5 m R^2) on the ellipsoid with semi-axes 1, √2, √3.
JACOBI = {"kind": "ball_on_quadric", "D0": 0.036, "m": 1.0, "R": 0.3, "B": [1.0, 2.0, 3.0],
          "potential": {"kind": "zero"}}
#: The same ball on an ellipsoid of revolution (b1 = b2): integrable (Routh), the same-system control.
JACOBI_ROUND = {**JACOBI, "B": [1.0, 1.0, 3.0]}
#: The quadric in a linear field: no K, chaotic (tests/unit/test_lyapunov.py).
JACOBI_LINEAR = {**JACOBI, "potential": {"kind": "linear", "a": [0.1, -0.2, 0.3]}}
BALL = {"kind": "chaplygin_ball", "inertia": [2.0, 3.0, 4.5], "D": 0.7, "potential": {"kind": "zero"}}
BALL_LINEAR = {**BALL, "potential": {"kind": "linear", "a": [0.3, -0.2, 0.5]}}

JACOBI_LEVEL = {"energy": 0.5, "K": 2.0}
ROUND_LEVEL = {"energy": 0.5, "K": 3.0}
BALL_LEVEL = {"energy": 2.0, "area": 0.0}
#: Study 2's level of the ball (U = 0): H = 0.5, c = 0.
TORUS_ENERGY, TORUS_AREA = 0.5, 0.0

#: x2 = 0 (the plane of the longest and the shortest axis), x2 increasing: crossed by every orbit
#: seen (x3 = 0 misses orbits that circle one pole). Chart: θ = atan2(x3/√b3, x1/√b1) and ω2, one
#: sheet per sign of a = (ω, n) (never seen to change on an orbit).
JACOBI_SECTION = {"surface": "x2", "value": 0.0, "direction": "increasing", "coordinates": ["x3", "omega2"],
                  "max_points": 100000}
#: γ3 = 0 increasing. Chart: φ = atan2(γ2, γ1) and M3 (the increasing branch is single-valued in them).
BALL_SECTION = {"surface": "gamma3", "value": 0.0, "direction": "increasing", "coordinates": ["gamma1", "M3"],
                "max_points": 100000}
LYAPUNOV = {"count": 1, "interval": 5.0}

GROWTH_CHAOTIC = 3.0
ORDER_REGULAR = 0.65
MIN_POINTS = 30


@dataclass(frozen=True)
class Config:
    members: int            # sampled members per main ensemble
    t_final: float          # main ensembles
    controls: int           # members of the small control ensembles (quadric in a field, round quadric)
    line_points: int        # separatrix probe: states on the symmetric line
    t_line: float           # ... their sections, and each bisection step
    separatrices: int       # ... how many separatrices per system are probed
    offsets: tuple[float, ...]  # ... distances of the probe orbits from the separatrix (both sides)
    t_probe: float          # ... their sections and exponents
    bisection_tol: float    # ... width of the final bracket (in the line parameter)
    resonances: tuple[tuple[int, int], ...]
    orbits: tuple[float, ...]   # study 2: φ of the orbits' starting points on each torus
    scan_points: int
    scan_returns: int


FULL = Config(members=64, t_final=1e4, controls=8, line_points=64, t_line=3000.0, separatrices=1,
              offsets=(1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 1e-6, 1e-9), t_probe=2e4, bisection_tol=1e-11,
              resonances=((1, 3), (1, 4)),
              orbits=(0.0, 0.7, 1.5, 2.5, -1.0), scan_points=24, scan_returns=200)
QUICK = Config(members=8, t_final=2e3, controls=4, line_points=32, t_line=1500.0, separatrices=1,
               offsets=(1e-4,), t_probe=5e3, bisection_tol=1e-9, resonances=((1, 3),),
               orbits=(0.0, 1.5, -1.0), scan_points=12, scan_returns=60)


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


# --------------------------------------------------------------------------------------------------
# The API
# --------------------------------------------------------------------------------------------------

@dataclass
class Ensemble:
    """One finished ensemble: the request, the view, the members and the section export."""

    name: str
    body: dict
    id: str
    view: dict
    members: list[dict]
    csv_text: str
    sections: dict[int, dict[str, np.ndarray]] = field(default_factory=dict)
    wall_s: float = 0.0

    @property
    def t_final(self) -> float:
        return float(self.body["t_final"])


def _parse_csv(text: str) -> dict[int, dict[str, np.ndarray]]:
    rows = list(csv.reader(io.StringIO(text)))
    if len(rows) < 2:
        return {}
    header, data = rows[0], np.array(rows[1:], dtype=float)
    out: dict[int, dict[str, np.ndarray]] = {}
    member = data[:, 0].astype(int)
    for m in np.unique(member):
        block = data[member == m]
        out[int(m)] = {name.split(" [")[0]: block[:, j] for j, name in enumerate(header) if j > 0}  # "M1 [unit]"
    return out


class Api:
    """The service in embedded mode (TestClient on create_app()); every request it posts is logged."""

    def __init__(self, workers: int = 2) -> None:
        for key in ("REDIS_URL", "NONHOLONOMIC_REDIS_URL"):
            os.environ.pop(key, None)
        os.environ.setdefault("NONHOLONOMIC_WARM_UP", "false")
        os.environ.setdefault("NONHOLONOMIC_MAX_T_FINAL", "1e9")
        os.environ.setdefault("NONHOLONOMIC_EMBEDDED_WORKERS", str(workers))
        from fastapi.testclient import TestClient

        from schemas.settings import get_settings
        from service.main import create_app

        get_settings.cache_clear()
        self._context = TestClient(create_app())
        self.client = self._context.__enter__()
        self.requests: dict[str, dict] = {}
        self.cache: dict[str, Ensemble] = {}
        self.jobs = 0

    def close(self) -> None:
        self._context.__exit__(None, None, None)

    def _wait(self, location: str, timeout: float = 1800.0) -> dict:
        deadline = time.monotonic() + timeout
        pause = 0.02
        while time.monotonic() < deadline:
            view = self.client.get(location).json()
            if view["status"] in ("succeeded", "failed", "cancelled"):
                return view
            time.sleep(pause)
            pause = min(pause * 1.5, 0.5)
        raise TimeoutError(location)

    def ensemble(self, name: str, body: dict, *, show: bool = True, retries: int = 2) -> Ensemble:
        """Post an ensemble (printing its request), wait, fetch the members and the section CSV.

        Members failing in the integrator (another developer is changing integration.py) are retried
        after a pause; if they still fail the ensemble is used without them (reported)."""
        if name in self.cache:
            return self.cache[name]
        self.requests[name] = body
        if show:
            print(f"\nREQUEST {name}: POST /v1/ensembles\n{json.dumps(body)}", flush=True)
        for attempt in range(retries + 1):
            start = time.perf_counter()
            r = self.client.post("/v1/ensembles", json=body)
            if r.status_code != 202:
                raise RuntimeError(f"{name}: {r.status_code} {r.text}")
            location = r.headers["location"]
            view = self._wait(location)
            wall = time.perf_counter() - start
            failed = view.get("summary", {}).get("failed", 0)
            if view["status"] == "succeeded" and not failed:
                break
            reasons = view.get("summary", {}).get("failures", []) or view.get("error")
            print(f"  ! {name}: status {view['status']}, {failed} failed members: {str(reasons)[:300]}", flush=True)
            if attempt < retries:
                print("  ! retrying in 60 s", flush=True)
                time.sleep(60)
        members: list[dict] = []
        offset = 0
        while True:
            page = self.client.get(f"{location}/members", params={"offset": offset, "limit": 1000}).json()
            members += page["members"]
            offset += 1000
            if offset >= page["total"]:
                break
        csv_text = ""
        if body.get("poincare"):
            csv_text = self.client.get(f"{location}/poincare", params={"format": "csv"}).text
        ens = Ensemble(name, body, r.json()["id"], view, members, csv_text, _parse_csv(csv_text), wall)
        if show:
            s = view.get("summary", {})
            drift = max(s.get("worst_integral_drift", {}).values(), default=math.nan)
            print(f"  done in {wall:.1f} s: {s.get('succeeded')} members succeeded, {s.get('failed')} failed, "
                  f"worst integral drift {drift:.1e}", flush=True)
        self.cache[name] = ens
        return ens

    def job(self, body: dict) -> dict:
        """Post one job, wait, return its result."""
        self.jobs += 1
        r = self.client.post("/v1/jobs", json=body)
        if r.status_code != 202:
            raise RuntimeError(f"job: {r.status_code} {r.text}")
        view = self._wait(r.headers["location"])
        if view["status"] != "succeeded":
            raise RuntimeError(f"job failed: {view.get('error')}")
        return view["result"]


# --------------------------------------------------------------------------------------------------
# Per-member analysis
# --------------------------------------------------------------------------------------------------

STATE_COLUMNS = {"ball_on_quadric": ("x1", "x2", "x3", "omega1", "omega2", "omega3"),
                 "chaplygin_ball": ("M1", "M2", "M3", "gamma1", "gamma2", "gamma3")}


def section_matrix(section: dict[str, np.ndarray], kind: str) -> np.ndarray:
    return np.column_stack([section[c] for c in STATE_COLUMNS[kind]])


def analyse(ens: Ensemble) -> list[dict[str, Any]]:
    """One row per member: section points, order, roughness, exponent measures, classification."""
    kind = ens.body["system"]["kind"]
    mats = {i: section_matrix(s, kind) for i, s in ens.sections.items()}
    stacked = np.concatenate(list(mats.values())) if mats else np.zeros((0, 6))
    scale = np.std(stacked, axis=0) if len(stacked) else None
    rows = []
    for m in ens.members:
        row: dict[str, Any] = {"index": m["index"], "status": m["status"]}
        if m["status"] != "succeeded":
            row["error"] = m.get("error")
            rows.append(row)
            continue
        P = mats.get(m["index"], np.zeros((0, 6)))
        row.update(points=len(P), order=neighbour_order(P, scale), rough=roughness(P, scale))
        ly = m.get("lyapunov")
        if ly:
            conv = np.asarray(ly["convergence"], dtype=float)[:, 0]
            row.update(exponent_measures(ly["convergence_t"], conv, ens.t_final))
            row["chaotic_exponent"] = row["growth"] > GROWTH_CHAOTIC
        if not math.isnan(row["order"]):
            row["chaotic_section"] = row["order"] < ORDER_REGULAR
        rows.append(row)
    return rows


def _fmt(v: float, spec: str = ".3g") -> str:
    return "nan" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def summarize(name: str, rows: list[dict]) -> dict[str, Any]:
    """Print and return the ensemble's statistics: medians and ranges, chaotic fractions."""
    ok = [r for r in rows if r["status"] == "succeeded"]
    out: dict[str, Any] = {"members": len(rows), "succeeded": len(ok)}

    def rng(key: str) -> tuple[float, float, float] | None:
        v = np.array([r[key] for r in ok if key in r and not math.isnan(r[key])])
        return (float(np.min(v)), float(np.median(v)), float(np.max(v))) if len(v) else None

    parts = [f"{name}: {len(ok)}/{len(rows)} members"]
    for key, spec in (("points", ".0f"), ("order", ".3f"), ("rough", ".3f"), ("lambda_early", ".2e"),
                      ("lambda_final", ".2e"), ("ratio", ".3f"), ("lambda_t_over_ln_t", ".2f"), ("growth", ".2f")):
        r = rng(key)
        if r is not None:
            out[key] = {"min": r[0], "median": r[1], "max": r[2]}
            parts.append(f"{key} {_fmt(r[0], spec)} / {_fmt(r[1], spec)} / {_fmt(r[2], spec)}")
    for key in ("chaotic_exponent", "chaotic_section"):
        flagged = [r for r in ok if key in r]
        if flagged:
            out[key] = {"count": sum(r[key] for r in flagged), "of": len(flagged)}
    both = [r for r in ok if "chaotic_exponent" in r and "chaotic_section" in r]
    if both:
        out["disagree"] = [r["index"] for r in both if r["chaotic_exponent"] != r["chaotic_section"]]
        out["agree"] = len(both) - len(out["disagree"])
        out["both_chaotic"] = sum(r["chaotic_exponent"] and r["chaotic_section"] for r in both)
        out["of"] = len(both)
    no_section = [r["index"] for r in ok if r.get("points", 0) < MIN_POINTS]
    out["no_section"] = no_section
    print("  " + "\n    ".join(parts) + "   (min / median / max)")
    line = "    chaotic: "
    if "chaotic_exponent" in out:
        c = out["chaotic_exponent"]
        line += f"by exponent (growth > {GROWTH_CHAOTIC:g}) {c['count']}/{c['of']}"
    if "chaotic_section" in out:
        c = out["chaotic_section"]
        line += f", by section (order < {ORDER_REGULAR:g}) {c['count']}/{c['of']}"
    if both:
        line += f", both {out['both_chaotic']}/{out['of']}, the two criteria agree on {out['agree']}/{out['of']}"
        if out["disagree"]:
            line += f" (not on members {out['disagree']})"
    if no_section:
        line += f"; members with < {MIN_POINTS} section points: {no_section}"
    print(line, flush=True)
    return out


# --------------------------------------------------------------------------------------------------
# Separatrix probe
# --------------------------------------------------------------------------------------------------

@dataclass
class Line:
    """A symmetric line of a section: ``state(s)`` on the level for the line parameter s (or None),
    ``chart(section) -> (angle, y)`` of the section points, the system and section request."""

    name: str
    system: dict
    section: dict
    grid: np.ndarray
    state: Callable[[float], dict | None]
    chart: Callable[[dict[str, np.ndarray]], tuple[np.ndarray, np.ndarray]]


def _features(line: Line, sec: dict[str, np.ndarray], y_scale: float) -> np.ndarray:
    """Time averages of the chart over the orbit's section: (⟨cos u⟩, ⟨sin u⟩, ⟨y⟩/scale). They are
    constant on a family of tori and jump across a separatrix."""
    u, y = line.chart(sec)
    if len(u) == 0:
        return np.full(3, np.nan)
    return np.array([np.mean(np.cos(u)), np.mean(np.sin(u)), np.mean(y) / y_scale])


def _job_section(api: Api, system: dict, section: dict, state: dict, t_final: float) -> dict[str, np.ndarray]:
    """One job's section as columns (t, tau, x1 ... as in the ensemble export)."""
    body = {"system": system, "initial_state": state, "t_final": t_final, "samples": 2, "poincare": section}
    sec = api.job(body)["poincare"]
    out = {"t": np.asarray(sec["t"], dtype=float)}
    if sec.get("tau") is not None:
        out["tau"] = np.asarray(sec["tau"], dtype=float)
    for name, values in sec["points"].items():
        arr = np.asarray(values, dtype=float).reshape(-1, 3)
        for k in range(3):
            out[f"{name}{k + 1}"] = arr[:, k]
    return out


def separatrix_probe(api: Api, line: Line, cfg: Config) -> dict[str, Any]:
    """Scan the line (one ensemble, sections only), find the largest jumps of the time averages
    between neighbours (separatrices), bisect each with single jobs, then integrate orbits at
    ``cfg.offsets`` on both sides with section and exponent (one ensemble). ``halves``: the distance
    between the time averages over the first and the second half of an orbit's section points, ~0 on
    an invariant curve, O(0.1 to 1) for an orbit that moves between the lobes of the separatrix."""
    states = [(s, line.state(float(s))) for s in line.grid]
    states = [(s, st) for s, st in states if st is not None]
    scan = api.ensemble(f"{line.name}-line", {
        "system": line.system, "members": {"initial_states": [st for _, st in states]}, "t_final": cfg.t_line,
        "samples": 2, "poincare": line.section, "chunk_size": 8})
    ys = np.concatenate([line.chart(sec)[1] for sec in scan.sections.values()])
    y_scale = float(np.std(ys)) or 1.0
    feats = [_features(line, scan.sections[i], y_scale) if i in scan.sections else np.full(3, np.nan)
             for i in range(len(states))]
    step = float(line.grid[1] - line.grid[0])
    jumps = []
    for i in range(len(states) - 1):
        if abs(states[i + 1][0] - states[i][0] - step) > 1e-9 * abs(step):
            continue        # states missing between them (the level is not reached there)
        d = float(np.linalg.norm(feats[i + 1] - feats[i]))
        if np.isfinite(d) and d > 0.3:
            jumps.append((d, i))
    jumps.sort(reverse=True)
    found = []
    for d, i in jumps[: cfg.separatrices]:
        lo, hi = float(states[i][0]), float(states[i + 1][0])
        f_lo, f_hi = feats[i], feats[i + 1]
        steps = 0
        while hi - lo > cfg.bisection_tol:
            mid = 0.5 * (lo + hi)
            st = line.state(mid)
            if st is None:
                break
            f = _features(line, _job_section(api, line.system, line.section, st, cfg.t_line), y_scale)
            if np.linalg.norm(f - f_lo) < np.linalg.norm(f - f_hi):
                lo = mid
            else:
                hi = mid
            steps += 1
        found.append({"bracket": [lo, hi], "jump": d, "bisection_jobs": steps})
        print(f"  separatrix of {line.name} at s in [{lo:.15f}, {hi:.15f}] ({steps} bisection jobs, "
              f"jump of the time averages {d:.2f})", flush=True)
    if not found:
        print(f"  no separatrix found on the line of {line.name}")
        return {"separatrices": []}
    probes, labels = [], []
    for j, sep in enumerate(found):
        lo, hi = sep["bracket"]
        for d in cfg.offsets:
            for side, s in (("-", lo - d), ("+", hi + d)):
                st = line.state(s)
                if st is not None:
                    probes.append(st)
                    labels.append({"separatrix": j, "offset": d, "side": side, "s": s})
    body = {"system": line.system, "members": {"initial_states": probes}, "t_final": cfg.t_probe, "samples": 2,
            "poincare": line.section, "lyapunov": LYAPUNOV, "chunk_size": 4}
    ens = api.ensemble(f"{line.name}-probe", body)
    rows = analyse(ens)
    for row, label in zip(rows, labels):
        row.update(label)
        sec = ens.sections.get(row["index"])
        if sec is not None and len(sec["t"]) >= 2 * MIN_POINTS:
            half = len(sec["t"]) // 2
            first = _features(line, {k: v[:half] for k, v in sec.items()}, y_scale)
            second = _features(line, {k: v[half:] for k, v in sec.items()}, y_scale)
            row["halves"] = float(np.linalg.norm(first - second))
        print(f"    sep {label['separatrix']} offset {label['side']}{label['offset']:.0e}: "
              f"lambda({ens.t_final / 10:g}) = {_fmt(row.get('lambda_early'), '.2e')}, "
              f"lambda({ens.t_final:g}) = {_fmt(row.get('lambda_final'), '.2e')}, "
              f"growth {_fmt(row.get('growth'), '.1f')}, "
              f"order {_fmt(row.get('order'), '.2f')}, rough {_fmt(row.get('rough'), '.3f')}, "
              f"{row.get('points')} points, halves {_fmt(row.get('halves'), '.3f')}", flush=True)
    summary = summarize(f"{line.name} separatrix probe", rows)
    return {"separatrices": found, "probes": rows, "summary": summary, "ensemble": ens.name}


def jacobi_line(name: str, system: dict, level: dict, cfg: Config) -> Line:
    """ω2 = 0, a > 0 on the section x2 = 0: θ ∈ [−π, π) (the symmetric line through the islands' centres)."""
    grid = np.linspace(-math.pi, math.pi, cfg.line_points, endpoint=False)

    def chart(sec: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        x = np.column_stack([sec["x1"], sec["x2"], sec["x3"]])
        w = np.column_stack([sec["omega1"], sec["omega2"], sec["omega3"]])
        theta, w2, _ = jacobi_chart(x, w, system["B"])
        return theta, w2

    return Line(name, system, JACOBI_SECTION, grid,
                lambda s: jacobi_state(s, 0.0, level["energy"], level["K"], system), chart)


def ball_line(name: str, system: dict, level: dict, cfg: Config) -> Line:
    """φ = π/2 on the section γ3 = 0: M3 across the island around (π/2, 0) and the rotating curves."""
    grid = np.linspace(-3.2, 3.2, cfg.line_points, endpoint=False) + 0.5 * 6.4 / cfg.line_points

    def chart(sec: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        return np.arctan2(sec["gamma2"], sec["gamma1"]), sec["M3"]

    return Line(name, system, BALL_SECTION, grid,
                lambda s: ball_state(math.pi / 2, s, level["energy"], level["area"], system), chart)


# --------------------------------------------------------------------------------------------------
# The studies
# --------------------------------------------------------------------------------------------------

def sampled(system: dict, level: dict, count: int, t_final: float, section: dict, seed: int = 1,
            lyapunov: bool = True) -> dict:
    body = {"system": system, "members": {"sample": {"count": count, "seed": seed, "level": level}},
            "t_final": t_final, "samples": 2, "poincare": section, "chunk_size": 4}
    if lyapunov:
        body["lyapunov"] = LYAPUNOV
    return body


def study_jacobi(api: Api, cfg: Config, results: dict) -> None:
    print("\n" + "=" * 100 + "\nSTUDY 1: the nonholonomic Jacobi problem on a triaxial ellipsoid, U = 0\n" + "=" * 100)
    out: dict[str, Any] = {}
    ens = {
        "jacobi": api.ensemble("jacobi", sampled(JACOBI, JACOBI_LEVEL, cfg.members, cfg.t_final, JACOBI_SECTION)),
        "ball": api.ensemble("ball", sampled(BALL, BALL_LEVEL, cfg.members, cfg.t_final, BALL_SECTION, seed=5)),
        "jacobi-round": api.ensemble("jacobi-round", sampled(JACOBI_ROUND, ROUND_LEVEL, cfg.controls, cfg.t_final,
                                                             JACOBI_SECTION)),
        "jacobi-linear": api.ensemble("jacobi-linear", sampled(JACOBI_LINEAR, {"energy": 0.5}, cfg.controls,
                                                               cfg.t_final, JACOBI_SECTION)),
    }
    print("\nMembers on one level, section and largest exponent to t = %g:" % cfg.t_final)
    labels = {"jacobi": "Jacobi problem, B = (1, 2, 3), U = 0, (H, K) = (0.5, 2)",
              "ball": "control: Chaplygin ball, U = 0, (H, c) = (2, 0) (integrable)",
              "jacobi-round": "control: the same ball on an ellipsoid of revolution, B = (1, 1, 3) (integrable)",
              "jacobi-linear": "control: the quadric B = (1, 2, 3) in a linear field, H = 0.5 (no K: 3-D section)"}
    for key, e in ens.items():
        rows = analyse(e)
        out[key] = {"summary": summarize(labels[key], rows), "rows": rows, "ensemble": e.name}
    print("\nSeparatrix probe (the chaotic layers of a non-integrable system sit at its separatrices):")
    out["probe"] = {
        "jacobi": separatrix_probe(api, jacobi_line("jacobi", JACOBI, JACOBI_LEVEL, cfg), cfg),
        "ball": separatrix_probe(api, ball_line("ball", BALL, BALL_LEVEL, cfg), cfg),
    }
    results["study1"] = out
    # verdict: the exponent decides per orbit (it needs no resolved curve); the section corroborates
    main = out["jacobi"]["summary"]
    probe = {k: v.get("summary", {}) for k, v in out["probe"].items()}

    def count(s: dict, key: str) -> int:
        return int(s.get(key, {}).get("count", 0))

    layer_exp, layer_sec = count(probe["jacobi"], "chaotic_exponent"), count(probe["jacobi"], "chaotic_section")
    prows = out["probe"]["jacobi"].get("probes", [])
    halves_c = [r["halves"] for r in prows if r.get("chaotic_exponent") and "halves" in r]
    halves_r = [r["halves"] for r in prows if not r.get("chaotic_exponent") and "halves" in r]
    halves = (f"; the time averages of their section points over the two halves of the run differ by "
              f"{_fmt(float(np.median(halves_c)), '.2f')} (median; regular probe orbits "
              f"{_fmt(float(np.median(halves_r)) if halves_r else math.nan, '.3f')}): they move between the lobes of "
              "the separatrix" if halves_c else "")
    n_probe = probe["jacobi"].get("succeeded", 0)
    main_exp, main_sec = count(main, "chaotic_exponent"), count(main, "chaotic_section")
    false_alarms = (count(probe["ball"], "chaotic_exponent") + count(out["ball"]["summary"], "chaotic_exponent")
                    + count(out["jacobi-round"]["summary"], "chaotic_exponent"))
    control_n = (probe["ball"].get("succeeded", 0) + out["ball"]["summary"].get("succeeded", 0)
                 + out["jacobi-round"]["summary"].get("succeeded", 0))
    print("\nVERDICT 1:", end=" ")
    if layer_exp > 0 and false_alarms == 0:
        verdict = (f"CHAOTIC, weakly. {layer_exp}/{n_probe} orbits started next to a separatrix of the Jacobi problem "
                   f"have a positive exponent (tangent vectors grow like t^p with p > {GROWTH_CHAOTIC:g}; "
                   f"{layer_sec} of "
                   f"them also leave every curve in the section, order < {ORDER_REGULAR:g}){halves}; "
                   f"none of {control_n} orbits of the integrable controls (ball U = 0 with the same separatrix probe, "
                   f"ellipsoid of revolution) does. Random members on the level: {main_exp}/{main.get('succeeded', 0)} "
                   f"chaotic by the exponent ({main_sec} flagged by the section alone: thin island chains), all others "
                   "on invariant curves, with island chains (Poincare-Birkhoff chains, themselves a mark of "
                   "non-integrability). The chaos is confined to thin layers at the separatrices, which is why short "
                   "or random-orbit tests looked integrable.")
    elif layer_exp == 0 and main_exp == 0:
        verdict = ("REGULAR on this level: every orbit, also next to the separatrices, has an exponent falling like "
                   "ln t / t as in the integrable controls and its section points on a curve; the data point to a "
                   "further integral.")
    else:
        verdict = (f"INCONCLUSIVE: Jacobi probe chaotic {layer_exp}/{n_probe}, random members chaotic {main_exp}, "
                   f"chaotic-looking orbits in the integrable controls {false_alarms}/{control_n}.")
    print(verdict)
    out["verdict"] = verdict


def study_periods(api: Api, cfg: Config, results: dict) -> None:
    print("\n" + "=" * 100
          + "\nSTUDY 2 [b008]: periods in t and in tau on a resonant torus of Chaplygin's ball, U = 0\n"
          + "=" * 100)
    system, h, c = BALL, TORUS_ENERGY, TORUS_AREA
    out: dict[str, Any] = {"energy": h, "area": c}
    # 1. rotation number of the section's return map along the line phi = 0 (one ensemble)
    grid = np.linspace(0.05, 1.80, cfg.scan_points)
    starts = [ball_state(0.0, float(M3), h, c, system) for M3 in grid]
    body = {"system": system, "members": {"initial_states": starts}, "t_final": 14.0 * (cfg.scan_returns + 2),
            "samples": 2, "poincare": {**BALL_SECTION, "max_points": cfg.scan_returns + 1}, "chunk_size": 4}
    scan = api.ensemble("torus-scan", body)
    nu = []
    for i in range(len(grid)):
        sec = scan.sections[i]
        phi = np.arctan2(sec["gamma2"], sec["gamma1"])
        nu.append(float(np.mean(wrap(np.diff(phi))) / (2 * math.pi)))
    nu = np.array(nu)
    print("  rotation number nu(M3) of the return map on the curve through (phi, M3) = (0, M3):")
    print("   " + ", ".join(f"{m:.2f}:{v:.4f}" for m, v in zip(grid, nu)))
    out["scan"] = {"M3": grid.tolist(), "nu": nu.tolist()}

    def closing(M3: float, q: int, p: int) -> tuple[float, dict]:
        state = ball_state(0.0, M3, h, c, system)
        sec = _job_section(api, system, {**BALL_SECTION, "max_points": q + 1}, state, 16.0 * (q + 1))
        phi = np.arctan2(sec["gamma2"], sec["gamma1"])
        if sec["t"][0] > 1e-9:          # the start (on the section) was not reported as a crossing
            phi = np.concatenate([[0.0], phi])
        return float(wrap(phi[q] - phi[0] - 2 * math.pi * p)), state

    # 2. each resonance p/q: Brent on the closing angle after q returns, orbits on the torus, periods
    out["tori"] = []
    orbit_bodies = []
    plans = []
    for p, q in cfg.resonances:
        k = np.nonzero(np.sign(nu[:-1] - p / q) != np.sign(nu[1:] - p / q))[0]
        if not len(k):
            print(f"  no bracket for nu = {p}/{q} in the scan")
            continue
        lo, hi = float(grid[k[0]]), float(grid[k[0] + 1])
        before = api.jobs
        M3_res = brentq(lambda v: closing(v, q, p)[0], lo, hi, xtol=1e-15, rtol=1e-15)
        residual, state = closing(M3_res, q, p)
        F = float(np.dot(state["M"], state["M"]))
        print(f"  resonant torus nu = {p}/{q}: M3(phi = 0) = {M3_res:.15f}, F = (M, M) = {F:.15f}, closing angle "
              f"after {q} returns {residual:.1e} ({api.jobs - before} Brent jobs)")
        M3_ctrl = M3_res - 0.2
        ctrl_state = ball_state(0.0, M3_ctrl, h, c, system)
        F_ctrl = float(np.dot(ctrl_state["M"], ctrl_state["M"]))
        nu_ctrl = float(np.interp(M3_ctrl, grid, nu))
        for torus, FF, M3_guess in (("resonant", F, M3_res), ("control", F_ctrl, M3_ctrl)):
            for phi0 in cfg.orbits:
                st = ball_on_torus(phi0, h, c, FF, M3_guess + 0.1 * (abs(phi0) > 0), system)
                orbit_bodies.append(st)
                plans.append({"p": p, "q": q, "torus": torus, "F": FF, "phi0": phi0})
        out["tori"].append({"p": p, "q": q, "M3": M3_res, "F": F, "closing": residual, "F_control": F_ctrl,
                            "M3_control": M3_ctrl, "nu_control": nu_ctrl})
    if not plans:
        return
    q_max = max(pl["q"] for pl in plans)
    body = {"system": system, "members": {"initial_states": orbit_bodies}, "t_final": 16.0 * (q_max + 1),
            "samples": 2, "poincare": {**BALL_SECTION, "max_points": q_max + 1}, "chunk_size": 4}
    ens = api.ensemble("torus-orbits", body)
    for i, pl in enumerate(plans):
        sec = ens.sections[i]
        t, tau = sec["t"], sec["tau"]
        phi = np.arctan2(sec["gamma2"], sec["gamma1"])
        M = np.column_stack([sec["M1"], sec["M2"], sec["M3"]])
        start = np.asarray(orbit_bodies[i]["M"])
        if t[0] > 1e-9:
            t, tau = np.concatenate([[0.0], t]), np.concatenate([[0.0], tau])
            phi = np.concatenate([[pl["phi0"]], phi])
            M = np.vstack([start, M])
        q = pl["q"]
        pl.update(T_t=float(t[q] - t[0]), T_tau=float(tau[q] - tau[0]),
                  closing=float(abs(wrap(phi[q] - phi[0]))), closing_M=float(np.linalg.norm(M[q] - M[0])))
    print("\n  Time of q returns to the section (the period, on the resonant torus) of orbits started at phi0:")
    for torus_info in out["tori"]:
        p, q = torus_info["p"], torus_info["q"]
        for torus in ("resonant", "control"):
            sel = [pl for pl in plans if pl["p"] == p and pl["q"] == q and pl["torus"] == torus]
            Tt = np.array([pl["T_t"] for pl in sel])
            Ttau = np.array([pl["T_tau"] for pl in sel])
            label = (f"nu = {p}/{q}, F = {torus_info['F']:.12f}" if torus == "resonant"
                     else f"control nu ~ {torus_info['nu_control']:.4f}, F = {torus_info['F_control']:.12f}")
            print(f"   {torus} torus ({label}):")
            for pl in sel:
                print(f"     phi0 = {pl['phi0']:+.2f}: T_t = {pl['T_t']:.15f}  T_tau = {pl['T_tau']:.15f}  "
                      f"closing |dphi| = {pl['closing']:.1e}, |dM| = {pl['closing_M']:.1e}")
            spread_t = float(np.ptp(Tt) / np.mean(Tt))
            spread_tau = float(np.ptp(Ttau) / np.mean(Ttau))
            print(f"     relative spread (max - min)/mean: in t {spread_t:.2e}, in tau {spread_tau:.2e}")
            torus_info[f"{torus}_orbits"] = sel
            torus_info[f"{torus}_spread_t"] = spread_t
            torus_info[f"{torus}_spread_tau"] = spread_tau
    res = out["tori"][0]
    verdict = (f"CONFIRMED: on the resonant torus nu = {res['p']}/{res['q']} the orbits' tau-periods agree to "
               f"{res['resonant_spread_tau']:.1e} (relative) while their t-periods differ by "
               f"{res['resonant_spread_t']:.1e}; on a non-resonant torus the q-return times differ in both "
               f"({res['control_spread_t']:.1e} in t, {res['control_spread_tau']:.1e} in tau)."
               if res["resonant_spread_tau"] < 1e-9 and res["resonant_spread_t"] > 1e3 * res["resonant_spread_tau"]
               else "NOT CONFIRMED: see the numbers above.")
    print("\nVERDICT 2:", verdict)
    out["verdict"] = verdict
    results["study2"] = out


def study_linear(api: Api, cfg: Config, results: dict) -> None:
    print("\n" + "=" * 100 + "\nSTUDY 3: Chaplygin's ball in a linear field beside U = 0, one (H, c) level\n"
          + "=" * 100)
    out: dict[str, Any] = {}
    for key, system, seed in (("ball-linear", BALL_LINEAR, 5), ("ball", BALL, 5)):
        e = api.ensemble(key, sampled(system, BALL_LEVEL, cfg.members, cfg.t_final, BALL_SECTION, seed=seed))
        rows = analyse(e)
        label = ("Chaplygin ball, linear field a = (0.3, -0.2, 0.5)" if key == "ball-linear"
                 else "Chaplygin ball, U = 0") + ", (H, c) = (2, 0)"
        out[key] = {"summary": summarize(label, rows), "rows": rows, "ensemble": e.name}
    lin, zero = out["ball-linear"]["summary"], out["ball"]["summary"]
    verdict = (f"linear field: {lin.get('chaotic_exponent', {}).get('count')}/{lin.get('succeeded')} members "
               "chaotic by "
               f"the exponent, {lin.get('chaotic_section', {}).get('count')}/{lin.get('succeeded')} by the section "
               f"(criteria agree on {lin.get('agree')}/{lin.get('of')}); U = 0: "
               f"{zero.get('chaotic_exponent', {}).get('count')}/{zero.get('succeeded')} and "
               f"{zero.get('chaotic_section', {}).get('count')}/{zero.get('succeeded')}.")
    print("\nVERDICT 3:", verdict)
    out["verdict"] = verdict
    results["study3"] = out


# --------------------------------------------------------------------------------------------------
# Output: CSV, requests, numbers, plots
# --------------------------------------------------------------------------------------------------

def write_outputs(api: Api, results: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for name, ens in api.cache.items():
        if ens.csv_text:
            (out / f"{name}-poincare.csv").write_text(ens.csv_text)
    (out / "requests.json").write_text(json.dumps(api.requests, indent=1))

    def plain(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [plain(x) for x in v]
        if isinstance(v, (np.floating, np.integer, np.bool_)):
            return v.item()
        return v

    (out / "results.json").write_text(json.dumps(plain(results), indent=1))
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print(f"\nwrote CSV, requests.json and results.json to {out} (matplotlib not importable: no plots)")
        return
    _plots(api, results, out, plt)
    print(f"\nwrote CSV, requests.json, results.json and PNG plots to {out}")


def _rows_by_index(results: dict, study: str, key: str) -> dict[int, dict]:
    return {r["index"]: r for r in results.get(study, {}).get(key, {}).get("rows", [])}


def _plots(api: Api, results: dict, out: Path, plt: Any) -> None:
    cache = api.cache
    if "jacobi" in cache:
        rows = _rows_by_index(results, "study1", "jacobi")
        fig, axes = plt.subplots(1, 2, figsize=(15, 6), sharey=True)
        for i, sec in cache["jacobi"].sections.items():
            x = np.column_stack([sec["x1"], sec["x2"], sec["x3"]])
            w = np.column_stack([sec["omega1"], sec["omega2"], sec["omega3"]])
            th, w2, a = jacobi_chart(x, w, JACOBI["B"])
            chaotic = rows.get(i, {}).get("chaotic_exponent", False)
            for ax, sel in ((axes[0], a > 0), (axes[1], a < 0)):
                ax.plot(th[sel], w2[sel], ".", ms=1.5 if chaotic else 0.6, color="k" if chaotic else None)
        probe = cache.get("jacobi-probe")
        if probe is not None:
            prow = results["study1"]["probe"]["jacobi"]["probes"]
            for i, sec in probe.sections.items():
                if prow[i].get("chaotic_exponent"):
                    x = np.column_stack([sec["x1"], sec["x2"], sec["x3"]])
                    w = np.column_stack([sec["omega1"], sec["omega2"], sec["omega3"]])
                    th, w2, a = jacobi_chart(x, w, JACOBI["B"])
                    axes[0].plot(th[a > 0], w2[a > 0], ".", ms=1.2, color="red")
        for ax, title in zip(axes, ("a = (omega, n) > 0", "a < 0")):
            ax.set_xlabel("theta = atan2(x3/sqrt(b3), x1/sqrt(b1))")
            ax.set_title(f"Jacobi problem, U = 0, (H, K) = (0.5, 2), section x2 = 0 ({title})")
        axes[0].set_ylabel("omega2")
        fig.text(0.5, 0.005, "colours: members (regular); black: members with a positive exponent; red: separatrix "
                 "probe orbits with a positive exponent", ha="center")
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        fig.savefig(out / "study1-jacobi-section.png", dpi=110)
        plt.close(fig)
    if "jacobi-probe" in cache:
        probe = results["study1"]["probe"]["jacobi"]
        prow = probe["probes"]
        centre = 0.5 * sum(probe["separatrices"][0]["bracket"])
        fig, axes = plt.subplots(1, 3, figsize=(19, 6))
        for i, sec in cache["jacobi-probe"].sections.items():
            x = np.column_stack([sec["x1"], sec["x2"], sec["x3"]])
            w = np.column_stack([sec["omega1"], sec["omega2"], sec["omega3"]])
            th, w2, a = jacobi_chart(x, w, JACOBI["B"])
            r = prow[i]
            label = f"{r['side']}{r['offset']:.0e}"
            ax = axes[0] if r.get("chaotic_exponent") else axes[1]
            ax.plot(th[a > 0], w2[a > 0], ".", ms=1.0, label=label)
            near = (a > 0) & (np.abs(wrap(th - centre)) < 0.01) & (np.abs(w2) < 0.6)
            axes[2].plot(th[near], w2[near], "o" if r.get("chaotic_exponent") else ".", ms=2.5 if r.get(
                "chaotic_exponent") else 1.5, label=label + (" (chaotic)" if r.get("chaotic_exponent") else ""))
        for ax, title in zip(axes, ("probe orbits with a positive exponent", "probe orbits without",
                                    "zoom at the line omega2 = 0 next to the separatrix")):
            ax.set_title(f"Jacobi problem, a > 0: {title}", fontsize=10)
            ax.set_xlabel("theta")
            ax.set_ylabel("omega2")
            if ax.lines:
                ax.legend(markerscale=5, fontsize=7)
        fig.tight_layout()
        fig.savefig(out / "study1-jacobi-separatrix.png", dpi=110)
        plt.close(fig)
    # exponents against t
    fig, ax = plt.subplots(figsize=(9, 6))
    colours = {"jacobi": "C0", "ball": "C2", "jacobi-round": "C4", "ball-linear": "C3", "jacobi-linear": "C1",
               "jacobi-probe": "k"}
    for name, colour in colours.items():
        ens = cache.get(name)
        if ens is None:
            continue
        for k, m in enumerate(ens.members):
            ly = m.get("lyapunov")
            if ly:
                ax.loglog(ly["convergence_t"], np.abs(np.asarray(ly["convergence"])[:, 0]), color=colour, lw=0.5,
                          alpha=0.6, label=name if k == 0 else None)
    t = np.logspace(2, 4.5, 50)
    ax.loglog(t, np.log(t) / t, "k--", lw=1.5, label="ln t / t")
    ax.set_xlabel("t")
    ax.set_ylabel("running largest exponent lambda(t)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "exponents.png", dpi=110)
    plt.close(fig)
    # study 3
    if "ball-linear" in cache and "ball" in cache:
        fig, axes = plt.subplots(1, 2, figsize=(15, 6), sharey=True)
        for ax, name in zip(axes, ("ball-linear", "ball")):
            study = "study3" if "study3" in results else "study1"
            rows = _rows_by_index(results, study, name)
            for i, sec in cache[name].sections.items():
                phi, M3 = np.arctan2(sec["gamma2"], sec["gamma1"]), sec["M3"]
                chaotic = rows.get(i, {}).get("chaotic_exponent", False)
                ax.plot(phi, M3, ".", ms=0.5 if chaotic else 0.8, color="0.55" if chaotic else None)
            ax.set_title(f"Chaplygin ball, {'linear field' if name == 'ball-linear' else 'U = 0'}, (H, c) = (2, 0)")
            ax.set_xlabel("phi = atan2(gamma2, gamma1) at gamma3 = 0")
        axes[0].set_ylabel("M3")
        fig.text(0.5, 0.005, "grey: members with a positive exponent; colours: regular members", ha="center")
        fig.tight_layout(rect=(0, 0.03, 1, 1))
        fig.savefig(out / "study3-ball-sections.png", dpi=110)
        plt.close(fig)
    if "torus-orbits" in cache and "study2" in results:
        fig, axes = plt.subplots(1, 2, figsize=(16, 6))
        scan = cache.get("torus-scan")
        if scan is not None:
            for sec in scan.sections.values():
                axes[0].plot(np.arctan2(sec["gamma2"], sec["gamma1"]), sec["M3"], ".", color="0.8", ms=0.6)
        tori = results["study2"]["tori"]
        plans = [pl for t in tori for torus in ("resonant", "control") for pl in t.get(f"{torus}_orbits", [])]
        first = (tori[0]["p"], tori[0]["q"])
        starts = sorted({pl["phi0"] for pl in plans})
        for i, sec in cache["torus-orbits"].sections.items():
            pl = plans[i]
            if (pl["p"], pl["q"]) != first:
                continue
            resonant = pl["torus"] == "resonant"
            axes[0].plot(np.arctan2(sec["gamma2"], sec["gamma1"]), sec["M3"], "o" if resonant else "x", ms=6,
                         color=f"C{starts.index(pl['phi0']) % 10}", mfc="none" if not resonant else None,
                         label=f"{pl['torus']}, phi0 = {pl['phi0']:+.1f}")
        axes[0].set_xlabel("phi")
        axes[0].set_ylabel("M3")
        axes[0].set_title(f"q = {first[1]} returns of orbits on the resonant torus {first[0]}/{first[1]} (o) and on "
                          "a non-resonant one (x)", fontsize=10)
        axes[0].legend(fontsize=7, ncol=2)
        for k, t in enumerate(tori):
            for torus, marker in (("resonant", "o"), ("control", "x")):
                sel = t.get(f"{torus}_orbits", [])
                if not sel:
                    continue
                for key, colour, label in (("T_t", "C0", "t"), ("T_tau", "C3", "tau")):
                    values = np.array([pl[key] for pl in sel])
                    dev = np.abs(values / values.mean() - 1) + 1e-17
                    where = np.full(len(dev), 2 * k + (torus == "control")) + (0.1 if label == "tau" else -0.1)
                    legend = f"period in {label}" if (k, torus) == (0, "resonant") else None
                    axes[1].semilogy(where, dev, marker, color=colour, label=legend)
        axes[1].set_xticks(range(2 * len(tori)))
        axes[1].set_xticklabels([f"{t['p']}/{t['q']} {torus}" for t in tori for torus in ("resonant", "control")])
        axes[1].set_ylabel("|T / mean(T) - 1| over the orbits of a torus")
        axes[1].set_title("time of q returns: in t (blue) and in tau (red)", fontsize=10)
        axes[1].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "study2-tori.png", dpi=110)
        plt.close(fig)


# --------------------------------------------------------------------------------------------------

def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small and short (~1 min)")
    parser.add_argument("--out", type=Path, help="write section CSVs, requests, numbers and plots here")
    parser.add_argument("--study", default="1,2,3", help="which studies, e.g. '2' or '1,3'")
    args = parser.parse_args()
    cfg = QUICK if args.quick else FULL
    studies = {s.strip() for s in args.study.split(",")}
    start = time.perf_counter()
    api = Api()
    results: dict[str, Any] = {"mode": "quick" if args.quick else "full"}
    try:
        if "2" in studies:
            study_periods(api, cfg, results)
        if "3" in studies:
            study_linear(api, cfg, results)
        if "1" in studies:
            study_jacobi(api, cfg, results)
        results["wall_s"] = time.perf_counter() - start
        print(f"\nSUMMARY ({results['mode']} run, {results['wall_s']:.0f} s, {len(api.cache)} ensembles, "
              f"{api.jobs} jobs)")
        for key in ("study1", "study2", "study3"):
            if key in results:
                print(f"  {key}: {results[key]['verdict']}")
        if args.out:
            write_outputs(api, results, args.out)
    finally:
        api.close()


if __name__ == "__main__":
    main()
