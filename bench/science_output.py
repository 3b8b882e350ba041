"""The output of bench/science.py with ``--out``: the section CSVs (the API's export), the requests,
the numbers as JSON and, if matplotlib is importable, PNG plots of the sections, the exponents and
the tori. Part of bench/science.py.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from science_api import Api
from science_config import JACOBI
from science_geometry import jacobi_chart, wrap

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
