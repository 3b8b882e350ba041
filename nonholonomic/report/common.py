"""Shared pieces of the report's claims: the parameter sets, cached simulations, and converters
from the core's evidence to :class:`~nonholonomic.report.verdict.Check`."""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import numpy as np
import sympy as sp

from nonholonomic import bounded, isomorphisms as iso
from nonholonomic.evidence.measure import CheckEvidence
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import parameter_vector
from nonholonomic.report.verdict import Check
from nonholonomic.simulation import SimulationResult, simulate
from nonholonomic.systems import SYSTEMS, get_system

#: Principal moments used throughout (a generic, non-symmetric body).
INERTIA = [1.0, 2.0, 3.5]
#: D = m R² of the balls.
D = 0.7
#: A linear potential U = (a, γ).
A = [0.3, -0.2, 0.5]
#: (ω, γ) on the Veselova constraint (ω, γ) = 0 and |γ| = 1.
OMEGA0, GAMMA0 = [0.5, -0.2, 0.15], [0.0, 0.6, 0.8]
#: Time span of the report's integrations.
T_FINAL = 100.0

_runs: dict[str, SimulationResult] = {}


def run(kind: str, potential: str, parameters: dict[str, Any], state: dict[str, Sequence[float]],
        t_final: float = T_FINAL, samples: int = 201, checks: Sequence[str] = ("integrals",)) -> SimulationResult:
    """A simulation, cached per process by its inputs."""
    key = json.dumps([kind, potential, parameters, state, t_final, samples, list(checks)], sort_keys=True)
    if key not in _runs:
        _runs[key] = simulate(get_system(kind, potential), parameters, state, t_final, samples, checks=checks)
    return _runs[key]


def example(kind: str) -> tuple[str, dict[str, Any], dict[str, Sequence[float]]]:
    """(potential, parameters, initial state) of a kind's catalog example."""
    ex = SYSTEMS[kind].EXAMPLE
    system = dict(ex["system"])
    potential = dict(system.pop("potential", {"kind": "zero"}))
    system.pop("kind")
    return potential.pop("kind"), {**system, **potential}, ex["initial_state"]


def integrals_check(result: SimulationResult, names: Sequence[str] | None = None) -> Check:
    """The integrals ``names`` (default all) conserved along ``result``: worst relative drift."""
    items = [i for i in result.integrals if names is None or i.name in names]
    if not items:
        return Check(None, None, None, "trajectory", f"no integral named {names} was evaluated")
    worst = max(items, key=lambda i: i.max_rel_drift / i.tolerance)
    t = float(result.trajectory.t[-1])
    return Check(all(i.passed for i in items), worst.max_rel_drift, worst.tolerance, "trajectory",
                 f"max relative drift over t = {t:g} ({result.trajectory.engine}): "
                 + ", ".join(f"{i.name} {i.max_rel_drift:.2g}" for i in items))


def evidence_check(item: CheckEvidence) -> Check:
    """A core :class:`CheckEvidence` as a report check."""
    return Check(item.passed, item.residual, item.tolerance, item.method, item.detail)


def proof(verdict: bool | None, detail: str) -> Check:
    """A symbolic proof's verdict as a check (residual 0 when proven)."""
    return Check(verdict, 0.0 if verdict else None, 0.0, "symbolic", detail)


def trig_identity(expr: sp.Expr, q: tuple[sp.Symbol, ...], values: dict[sp.Symbol, float], what: str) -> Check:
    """``expr ≡ 0`` in (q, parameters) decided exactly (t = tan(q/2), numerator expanded; parameters
    symbolic; run to its end, cached), with the largest |expr| at 40 random points (``values`` for the
    parameters) as residual. If sympy cannot decide it, the pointwise values decide."""
    from nonholonomic.rational_trig import rational_trig_is_zero

    rng = np.random.default_rng(0)
    f = sp.lambdify(list(q) + list(values), expr, "numpy")
    pts = rng.uniform(0.1, np.pi - 0.1, (40, len(q)))
    residual = float(np.max(np.abs([f(*x, *values.values()) for x in pts])))
    outcome = bounded.run(("report-trig", what, expr, q), rational_trig_is_zero, (expr, q))
    verdict = outcome.value if outcome.status == "done" else None
    method = "symbolic"
    detail = f"{what}: exact decision in t = tan(q/2) (parameters symbolic)"
    if verdict is None:
        method, verdict = "pointwise", residual <= 1e-12
        why = f"sympy could not decide ({outcome.message})" if outcome.status == "error" else \
            "not rational in t = tan(q/2)"
        detail = f"{what}: {why}; max |value| at 40 random points {residual:.3g}"
    else:
        detail += f"; max |value| at 40 random points {residual:.3g}"
    if method == "symbolic":
        return Check(bool(verdict), 0.0 if verdict else residual, 0.0, method, detail)
    return Check(bool(verdict), residual, 1e-12, method, detail)


def map_checks(name: str, parameters: dict[str, Any], potential: str = "zero") -> list[Check]:
    """A map's push-forward residual at 50 states of its level set and its trajectory (t <= 200)
    against the target integrated independently."""
    m = iso.get_map(name, potential)
    p = parameter_vector(m.source, parameters)
    X = iso.sample_states(m, p, 50)
    residual = iso.push_forward_residual(m, p, X)
    source = integrate(m.source, p, iso.sample_states(m, p, 1, seed=7)[0], 200.0, 201)
    cmp = iso.compare_trajectories(m, p, source.t, source.tau, source.states)
    return [Check.at_most(residual, iso.PUSH_FORWARD_TOLERANCE, "pointwise",
                          f"max relative push-forward residual at 50 random states of the level set: {residual:.2g}"),
            Check.at_most(cmp.distance, cmp.tolerance, "trajectory",
                          f"mapped trajectory (t <= 200) vs {m.target.kind} integrated independently in "
                          f"{m.time_variable}: max distance {cmp.distance:.2g}")]
