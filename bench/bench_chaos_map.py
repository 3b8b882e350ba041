"""Benchmark: chaos maps (cells per second against heyoka written by hand, and a 128 x 128 map over the
real queue on 1 and 2 worker processes).

Run from the repository root (part B needs Redis on 127.0.0.1:6379)::

    .venv/bin/python bench/bench_chaos_map.py            # ~6 min on 2 cores
    .venv/bin/python bench/bench_chaos_map.py --quick    # ~1 min: 64 x 64, t = 200

Chaplygin's ball in a linear field (I = (2, 3, 4.5), D = 0.7, a = (0.3, -0.2, 0.5)), level H = 2,
(M, γ) = 0, section γ3 = 0 (increasing) in (γ1, M3), t = 500.

A. **Cells per second, one process.** The core's map path (:func:`nonholonomic.analysis.chaos_map.run_cells`:
   the cells' indicators in heyoka's batch mode, classification, the integrals' drift, the 1 % recomputed
   by Benettin's method) and its integration alone (:func:`nonholonomic.analysis.chaos_map.indicators.run_batch`)
   against the same variational system written by hand in heyoka: ω = I_Q⁻¹ M by Sherman–Morrison,
   Ṁ = M × ω + γ × a, γ̇ = γ × ω (eq. 2604-1), J w by ``hy.diff`` of those, the unit tangent vector and
   the three quadratures of the indicators, the same batch size, tolerance and output grid. Target:
   core / hand ≥ 0.8. The two give the same MEGNO on the regular cells (printed).
B. **The map over the queue.** ``POST /v1/ensembles`` with ``members.grid`` of 128 × 128 cells to the
   ``GET`` that says ``succeeded``, with a Celery worker of 1 and then of 2 processes (each warmed by a
   small map first). Printed: both times and the scale-out (time with 1 / time with 2).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import argparse  # noqa: E402
import os  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import uuid  # noqa: E402
from typing import Any  # noqa: E402

import heyoka as hy  # noqa: E402
import numpy as np  # noqa: E402

from nonholonomic import get_system  # noqa: E402
from nonholonomic.analysis import indicators  # noqa: E402
from nonholonomic.analysis.chaos_map import MapOptions, run_cells  # noqa: E402
from nonholonomic.analysis.chaos_map.grid import Grid, complete, default_ranges  # noqa: E402
from nonholonomic.analysis.ensemble import Member  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector  # noqa: E402

INERTIA = (2.0, 3.0, 4.5)
D = 0.7
A = (0.3, -0.2, 0.5)
LEVEL = {"energy": 2.0, "area": 0.0}
RATIO_TARGET = 0.8
REDIS_URL = "redis://127.0.0.1:6379/12"


def hand_written(lanes: int, tol: float) -> hy.taylor_adaptive_batch:
    """The ball's tangent-flow system with the indicators' quadratures, written here by hand."""
    M = hy.make_vars("M1", "M2", "M3")
    g = hy.make_vars("g1", "g2", "g3")
    w = hy.make_vars(*[f"w{i}" for i in range(6)])
    ell, y, z = hy.make_vars("l", "y", "z")
    T = hy.par[0]
    j = [1.0 / (i + D) for i in INERTIA]                        # J^-1, J = I + D
    Jg = [j[k] * g[k] for k in range(3)]
    s = D / (1.0 - D * (g[0] * Jg[0] + g[1] * Jg[1] + g[2] * Jg[2]))
    JgM = Jg[0] * M[0] + Jg[1] * M[1] + Jg[2] * M[2]
    om = [j[k] * M[k] + s * Jg[k] * JgM for k in range(3)]     # I_Q^-1 M (Sherman-Morrison)

    def cross(a: list, b: list) -> list:
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    f = [p + q for p, q in zip(cross(M, om), cross(g, list(A)))] + cross(g, om)
    x = list(M) + list(g)
    Jw = [hy.sum([hy.diff(f[i], x[k]) * w[k] for k in range(6)]) for i in range(6)]
    rate = hy.sum([w[i] * Jw[i] for i in range(6)]) / hy.sum([w[i] * w[i] for i in range(6)])
    eqs = (list(zip(x, f)) + [(w[i], Jw[i] - rate * w[i]) for i in range(6)]
           + [(ell, rate / T), (y, hy.time * rate / (T * T)), (z, 2.0 * y * T / hy.time)])
    return hy.taylor_adaptive_batch(eqs, np.zeros((len(eqs), lanes)), pars=np.zeros((1, lanes)), tol=tol)


def hand_run(ta: hy.taylor_adaptive_batch, X: np.ndarray, T: float) -> np.ndarray:
    """MEGNO of every cell with the hand-written integrator (the same grid as the core's)."""
    lanes = ta.batch_size
    t0 = indicators.START_FRACTION * T
    grid = np.repeat((t0 + np.linspace(0.0, T, indicators.FLI_POINTS + 1))[:, None], lanes, axis=1)
    w0 = indicators.initial_frame(6)[:, :1]
    out = np.empty(len(X))
    for first in range(0, len(X), lanes):
        rows = X[first:first + lanes]
        rows = np.vstack([rows, np.repeat(rows[-1:], lanes - len(rows), 0)])
        ta.set_time(t0)
        ta.pars[0] = T
        ta.state[:6] = rows.T
        ta.state[6:12] = w0
        ta.state[12:] = 0.0
        res = ta.propagate_grid(grid, max_steps=0)
        result = np.asarray(res[-1] if isinstance(res, tuple) else res)
        out[first:first + lanes] = result[-1, 14, : min(lanes, len(X) - first)]
    return out


def cells_of(shape: tuple[int, int]) -> tuple[Any, np.ndarray, np.ndarray]:
    system = get_system("chaplygin_ball", "linear")
    p = parameter_vector(system, {"inertia": list(INERTIA), "D": D, "a": list(A)})
    grid = Grid("gamma3", 0.0, ("gamma1", "M3"), LEVEL, shape)
    cells = complete(system, p, grid, default_ranges(system, p, grid))
    return system, p, cells.states[cells.inside]


def part_a(cells: int, T: float) -> None:
    side = int(np.ceil(np.sqrt(cells * 1.15)))
    system, p, X = cells_of((side, side))
    X = X[:cells]
    lanes, tol = hy.recommended_simd_size(), indicators.MACHINE_EPSILON
    P = np.repeat(p[None], len(X), 0)
    print(f"A. {len(X)} cells of the ball in a linear field, t = {T:g}, {lanes} SIMD lanes, one process")
    start = time.perf_counter()
    hand = hand_written(lanes, tol)
    work = max(len(X) * T, indicators.COMPACT_BELOW)  # a large map's mode (non-compact), like the hand-written one
    indicators.batch_template(system, tol, lanes, indicators.compact_for(work))
    print(f"   compile (hand + core, or read from heyoka's cache): {time.perf_counter() - start:.1f} s")
    hand_run(hand, X[:lanes], 1.0)  # warm (and Benettin's integrator compiled for the check)
    indicators.run_batch(system, P[:lanes], X[:lanes], 1.0, work=work)
    run_cells(system, [Member(k, p, X[k], {}) for k in range(lanes)], 1.0,
              MapOptions(("megno",), indicators.default_thresholds(1.0), 1))
    start = time.perf_counter()
    megno_hand = hand_run(hand, X, T)
    t_hand = time.perf_counter() - start
    start = time.perf_counter()
    found = indicators.run_batch(system, P, X, T, work=work)
    t_core = time.perf_counter() - start
    members = [Member(k, p, X[k], {}) for k in range(len(X))]
    options = MapOptions(("megno", "fli"), indicators.default_thresholds(T), len(X))
    start = time.perf_counter()
    cells_done = run_cells(system, members, T, options)
    t_map = time.perf_counter() - start
    checked = sum(1 for c in cells_done if c.check is not None)
    megno = np.array([f.megno for f in found])
    regular = megno < 2.5
    print(f"   hand-written heyoka batch: {len(X) / t_hand:8.1f} cells/s")
    print(f"   core indicators.run_batch: {len(X) / t_core:8.1f} cells/s   ratio {t_hand / t_core:.2f} "
          f"(target >= {RATIO_TARGET}) {'ok' if t_hand / t_core >= RATIO_TARGET else 'MISS'}")
    print(f"   core map path (run_cells, {checked} cells recomputed by Benettin): {len(X) / t_map:8.1f} cells/s   "
          f"ratio {t_hand / t_map:.2f}")
    print(f"   MEGNO core vs hand on the {int(regular.sum())} regular cells: max |difference| "
          f"{np.max(np.abs(megno[regular] - megno_hand[regular])):.2e}")


def part_b(shape: int, T: float, concurrencies: list[int]) -> None:
    import httpx

    from tests.support import free_port, start_api, start_worker, stop, wait_healthy

    body = {"system": {"kind": "chaplygin_ball", "inertia": list(INERTIA), "D": D,
                       "potential": {"kind": "linear", "a": list(A)}},
            "t_final": T, "indicators": ["megno", "fli"],
            "members": {"grid": {"surface": "gamma3", "coordinates": ["gamma1", "M3"], "level": LEVEL,
                                 "shape": [shape, shape]}}}
    warm = {**body, "t_final": 5.0, "members": {"grid": {**body["members"]["grid"], "shape": [8, 8]}}}
    print(f"B. a {shape} x {shape} map at t = {T:g} through the queue (Redis, Celery prefork)")
    times = {}
    logs = Path(tempfile.mkdtemp(prefix="bench-map-"))
    for concurrency in concurrencies:
        queue = f"bench-map-{uuid.uuid4().hex[:8]}"
        env = {"NONHOLONOMIC_JOB_TTL_S": "3600", "NONHOLONOMIC_MAX_T_FINAL": "1e6"}
        worker = start_worker(REDIS_URL, queue, logs / f"worker{concurrency}.log", concurrency=concurrency,
                              extra_env=env, warm_up=True)
        port = free_port()
        api = start_api(port, logs / f"api{concurrency}.log", {"REDIS_URL": REDIS_URL, "NONHOLONOMIC_QUEUE": queue,
                                                               **env})
        try:
            base = f"http://127.0.0.1:{port}"
            wait_healthy(base, timeout=300)
            with httpx.Client(base_url=base, timeout=60) as client:
                for request, timed in ((warm, False), (warm, False), (body, True)):
                    start = time.perf_counter()
                    r = client.post("/v1/ensembles", json=request)
                    assert r.status_code == 202, r.text
                    while True:
                        view = client.get(r.headers["location"]).json()
                        if view["status"] in ("succeeded", "failed", "cancelled"):
                            break
                        time.sleep(0.05)
                    if timed:
                        elapsed = time.perf_counter() - start
                        times[concurrency] = elapsed
                        m = view["summary"]["map"]
                        print(f"   {concurrency} process(es): {elapsed:7.1f} s  "
                              f"({shape * shape / elapsed:.0f} cells/s; "
                              f"{view['chunks']['total']} chunks; chaotic fraction {m['chaotic_fraction']:.3f}, "
                              f"{m['outside']} outside, {m['failed']} failed; recomputed cells agree "
                              f"{m['check']['agree']}/{m['check']['cells']})")
        finally:
            stop(api)
            stop(worker)
    if 1 in times and 2 in times:
        print(f"   scale-out 1 -> 2 processes: {times[1] / times[2]:.2f}x")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="64 x 64 cells at t = 200, part A on 256 cells")
    parser.add_argument("--skip-queue", action="store_true", help="part A only")
    args = parser.parse_args()
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}, heyoka {hy.__version__}")
    T = 200.0 if args.quick else 500.0
    part_a(256 if args.quick else 1024, T)
    if not args.skip_queue:
        part_b(64 if args.quick else 128, T, [1, 2])
    return 0


if __name__ == "__main__":
    sys.exit(main())
