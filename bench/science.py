"""Three open questions of the paper, settled through the API (embedded mode, in-process).

Run from the repository root::

    .venv/bin/python bench/science.py --quick            # ~1 min: every study, small and short
    .venv/bin/python bench/science.py                    # ~10 min on 2 cores: the numbers of docs/science.md
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

This file holds the studies and the command line; the rest lives in sibling modules, imported from
this directory: ``science_config`` (systems, levels, sections, thresholds, run sizes),
``science_geometry`` (the measures, charts and states), ``science_api`` (the service in embedded
mode and the per-member analysis), ``science_separatrix`` (the separatrix probe) and
``science_output`` (CSV, JSON and plots for ``--out``). Every name they define is also a name of
this module (tests/unit/test_science.py uses them as ``science.NAME``).
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
BENCH = Path(__file__).resolve().parent
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))     # the sibling modules science_*.py, also when loaded by importlib

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

# Re-exported (defined in the parts, not used here): every name of the single-file version stays a
# name of this module.
from science_api import (  # noqa: E402  # noqa: E402
    STATE_COLUMNS as STATE_COLUMNS,
    Api,
    Ensemble as Ensemble,
    _fmt,
    _parse_csv as _parse_csv,
    analyse,
    section_matrix as section_matrix,
    summarize,
)
from science_config import (  # noqa: E402
    BALL,
    BALL_LEVEL,
    BALL_LINEAR,
    BALL_SECTION,
    FULL,
    GROWTH_CHAOTIC,
    JACOBI,
    JACOBI_LEVEL,
    JACOBI_LINEAR,
    JACOBI_ROUND,
    JACOBI_SECTION,
    LYAPUNOV,
    MIN_POINTS as MIN_POINTS,  # noqa: E402
    ORDER_REGULAR,
    QUICK,
    ROUND_LEVEL,
    TORUS_AREA,
    TORUS_ENERGY,
    Config,
)
from science_geometry import (  # noqa: E402  # noqa: E402
    ball_chart as ball_chart,
    ball_energy as ball_energy,
    ball_omega as ball_omega,
    ball_on_torus,
    ball_state,
    exponent_measures as exponent_measures,
    jacobi_chart as jacobi_chart,
    jacobi_state as jacobi_state,
    neighbour_order as neighbour_order,
    roughness as roughness,
    wrap,
)
from science_output import (  # noqa: E402
    _plots as _plots,
    _rows_by_index as _rows_by_index,
    write_outputs,  # noqa: E402
)
from science_separatrix import (  # noqa: E402  # noqa: E402
    Line as Line,
    _features as _features,
    _job_section,
    ball_line,
    jacobi_line,
    separatrix_probe,
)
from scipy.optimize import brentq  # noqa: E402

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
    print(f"\nMembers on one level, section and largest exponent to t = {cfg.t_final:g}:")
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
        M3_res = brentq(lambda v, q=q, p=p: closing(v, q, p)[0], lo, hi, xtol=1e-15, rtol=1e-15)
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
