"""The separatrix probe of study 1: a symmetric line of a section (``Line``, ``jacobi_line``,
``ball_line``), the separatrices on it found by bisection with single jobs, and the orbits started
next to them (``separatrix_probe``). Part of bench/science.py.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from science_api import Api, _fmt, analyse, summarize
from science_config import BALL_SECTION, JACOBI_SECTION, LYAPUNOV, MIN_POINTS, Config
from science_geometry import ball_state, jacobi_chart, jacobi_state

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
