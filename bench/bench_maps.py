"""Benchmark of the isomorphism maps and of the ``isomorphisms`` job check.

A. Mapping states: the core's compiled kernels (``nonholonomic.isomorphisms.apply``, generated
   from each map's sympy definition) against a plain-numpy implementation written here from the
   paper's formulas (ERRATA 3, 4, 8 applied), one state at a time, as a researcher's script would.
   The two must agree (max difference printed) and the ratio is reported. Target ≥ 10×.
B. The trajectory comparison of the job check: the target integrated by heyoka (tolerance
   machine epsilon) against scipy DOP853 at rtol = atol = 1e-12, from the same mapped initial
   state at the same times; ratio of times and of the distances to the mapped trajectory.

Run from the repository root: ``.venv/bin/python bench/bench_maps.py`` (~30 s on 2 cores).
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from nonholonomic import isomorphisms as iso  # noqa: E402
from nonholonomic.numerics.integration import integrate  # noqa: E402
from nonholonomic.numerics.kernels import parameter_vector  # noqa: E402

I = np.array([1.0, 2.0, 3.5])
D = 0.7
STATES = 20000
CASES = {
    "veselova_to_e3": {"inertia": list(I)},
    "veselova_to_neumann": {"inertia": list(I)},
    "e3_to_clebsch": {"inertia": list(I), "alpha": 0.7, "beta": -0.4},
    "chaplygin_ball_to_clebsch": {"inertia": list(I), "D": D},
    "rubber_ball_to_veselova": {"inertia": list(I), "D": D},
}


def reference(name: str, x: np.ndarray) -> np.ndarray:
    """The map of one state, plain numpy, from the paper (target state only)."""
    a, b = x[:3], x[3:]
    if name == "veselova_to_e3":  # eq. 2504-10-2
        rho = np.sqrt(b @ (b / I))
        return np.concatenate([rho * np.sqrt(I) * a, b / (rho * np.sqrt(I))])
    if name == "veselova_to_neumann":  # s = gamma, L = rho omega
        rho = np.sqrt(b @ (b / I))
        return np.concatenate([b, rho * a])
    if name == "e3_to_clebsch":  # Proposition 1
        return np.concatenate([np.sqrt(I) * b / np.sqrt(b @ (I * b)), a / np.sqrt(I)])
    if name == "chaplygin_ball_to_clebsch":  # Theorem 3 with ERRATA 8
        J = I + D
        B = I / J
        rho = 1 / np.sqrt(np.linalg.det(np.diag(J) - D * np.outer(b, b)))
        return np.concatenate([np.sqrt(B) * b / np.sqrt(b @ (B * b)), rho * a / np.sqrt(B)])
    return x.copy()  # rubber ball: the identity, I -> J in the parameters


def median_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    summary = []
    print(f"A. mapping {STATES} states: compiled kernels vs plain numpy per state")
    for name, parameters in CASES.items():
        m = iso.get_map(name)
        p = parameter_vector(m.source, parameters)
        X = iso.sample_states(m, p, STATES)
        iso.apply(m, p, X[:10])  # compile
        core = median_time(lambda m=m, p=p, X=X: iso.apply(m, p, X), 5)
        ref_states = None

        def by_hand(name=name, X=X) -> None:
            nonlocal ref_states
            ref_states = np.array([reference(name, x) for x in X])

        hand = median_time(by_hand, 1)
        diff = float(np.max(np.abs(iso.apply(m, p, X)["states"] - ref_states)))
        ratio = hand / core
        ok = ratio >= 10 and diff <= 1e-12
        summary.append(f"{name:28s} map {STATES} states: {core * 1e3:7.2f} ms vs {hand * 1e3:8.1f} ms by hand: "
                       f"{ratio:6.1f}x, max |difference| {diff:.1e} {'' if ok else 'MISS'}")
        print(summary[-1])

    print("B. trajectory comparison of the job check: target by heyoka vs DOP853 (rtol 1e-12), t = 200")
    for name, parameters in CASES.items():
        m = iso.get_map(name)
        p = parameter_vector(m.source, parameters)
        x0 = iso.sample_states(m, p, 1, seed=5)[0]
        source = integrate(m.source, p, x0, 200.0, 201)
        times = source.tau if m.time_variable == "tau" else source.t
        mapped = iso.apply(m, p, source.states)
        p_target, y0 = mapped["target_parameters"][0], mapped["states"][0]
        integrate(m.target, p_target, y0, 0.0, 0, times=times)  # compile
        runs = {}
        for engine, tol, repeat in (("heyoka", None, 5), ("scipy", 1e-12, 1)):
            def go(engine=engine, tol=tol, runs=runs, m=m, p_target=p_target, y0=y0, times=times) -> None:
                runs[engine] = integrate(m.target, p_target, y0, 0.0, 0, times=times, engine=engine, tolerance=tol)
            runs[engine + "_time"] = median_time(go, repeat)
        dist = {e: float(np.max(np.abs(runs[e].states - mapped["states"]))) for e in ("heyoka", "scipy")}
        speed = runs["scipy_time"] / runs["heyoka_time"]
        summary.append(f"{name:28s} target {runs['heyoka_time'] * 1e3:6.1f} ms vs {runs['scipy_time'] * 1e3:7.1f} ms: "
                       f"{speed:5.0f}x faster; distance {dist['heyoka']:.1e} vs {dist['scipy']:.1e} "
                       f"({dist['scipy'] / max(dist['heyoka'], 1e-300):.0f}x smaller)")
        print(summary[-1])
    print("\nSUMMARY")
    print("\n".join(summary))


if __name__ == "__main__":
    main()
