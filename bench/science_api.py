"""The service in embedded mode (``Api``: ensembles and jobs posted through FastAPI's TestClient,
``Ensemble``: a finished ensemble with its section export) and the per-member analysis of an
ensemble (``analyse``, ``summarize``). Part of bench/science.py.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from science_config import GROWTH_CHAOTIC, MIN_POINTS, ORDER_REGULAR
from science_geometry import exponent_measures, neighbour_order, roughness

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
