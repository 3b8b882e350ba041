"""Benchmark: the sampled ansatz for a measure and linear integrals (issue 33, item 4) against the exact symbolic
searches, on systems both can do; then its cost where only it can run.

Run from the repository root::

    .venv/bin/python bench/bench_sampled_search.py

For Veselova's system and the rolling disk (closed forms: the symbolic searches run), in one process, each cold
(the compiled flow not shared between them): the symbolic measure search (:func:`measure_verdict`) and the sampled one
(:func:`sampled_measure`), their wall times, the ratio, and whether the two densities agree up to a constant
factor at random points. Then Chaplygin's sphere and the rattleback (no closed form): the sampled measure and
integrals, wall time and what they found.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import os
import time

import numpy as np
import sympy as sp


def main() -> None:
    from nonholonomic.lagrangian.equations import dependent_columns, derive
    from nonholonomic.lagrangian.measure_search import _search_symbolic
    from nonholonomic.lagrangian.parse import parse_system
    from nonholonomic.lagrangian.sampled_search import _manifold, sampled_integrals, sampled_measure
    from nonholonomic.systems.lagrangian_classics import CLASSICS
    from tests.lagrangian_examples import CHAPLYGIN_SPHERE, VESELOVA

    print(f"load average {os.getloadavg()[0]:.2f}")
    rng = np.random.default_rng(3)
    for name, spec in (("Veselova", VESELOVA), ("rolling disk", CLASSICS["rolling_disk"]["job"]["system"])):
        data = parse_system(spec)
        derive(data)
        tic = time.perf_counter()
        symbolic = _search_symbolic(data)
        t_symbolic = time.perf_counter() - tic
        dependent = dependent_columns(data)
        assert dependent is not None
        tic = time.perf_counter()
        sampled = sampled_measure(data, dependent)
        t_sampled = time.perf_counter() - tic
        agree = "-"
        if symbolic[0] == "found" and sampled.status == "found" and sampled.density is not None:
            values = dict(zip(data.parameters, data.values))
            ratios = []
            for point in rng.uniform(0.3, 1.3, (6, len(data.q))):
                at = {**values, **dict(zip(data.q, point))}
                ratios.append(float(symbolic[1].xreplace(at)) / float(sampled.density.xreplace(at)))
            agree = "yes" if np.ptp(ratios) <= 1e-10 * abs(ratios[0]) else f"no (ratios {ratios[:2]})"
        print(f"{name:<14} symbolic {t_symbolic:7.2f} s ({symbolic[0]})  sampled {t_sampled:7.2f} s "
              f"({sampled.status})  ratio {t_sampled / t_symbolic:5.2f}  same density up to a constant: {agree}")
        _manifold.cache_clear()
    large = (("Chaplygin's sphere", CHAPLYGIN_SPHERE), ("rattleback", CLASSICS["rattleback"]["job"]["system"]))
    for name, spec in large:
        data = parse_system(spec)
        tic = time.perf_counter()
        derive(data)
        t_derive = time.perf_counter() - tic
        dependent = dependent_columns(data)
        assert dependent is not None
        tic = time.perf_counter()
        measure = sampled_measure(data, dependent)
        t_measure = time.perf_counter() - tic
        tic = time.perf_counter()
        integrals = sampled_integrals(data, dependent)
        t_integrals = time.perf_counter() - tic
        density = "-" if measure.density is None else sp.sstr(measure.density)[:60] + "..."
        print(f"{name:<18} elimination {t_derive:6.2f} s  measure {t_measure:6.2f} s ({measure.status}: {density})  "
              f"linear integrals {t_integrals:6.2f} s ({len(integrals.integrals)} found)")


if __name__ == "__main__":
    main()
