"""The paper's isomorphisms: Veselova → e(3), Veselova → Neumann, Proposition 1 (e(3) → Clebsch),
Theorem 3 (Chaplygin's ball → Clebsch) and the rubber ball → Veselova.

Each map is defined once, symbolically: the target state as expressions in the source state and
parameters, the target's parameters (level constants such as c included) likewise, the time
substitution dτ/dt, and the level set on which the map holds. Everything else is derived:

* the push-forward residual ``DΦ·f / (dτ/dt) − g(Φ(x))`` at states on the level set (f the
  source field, g the target field with the target parameters of that state), relative to the
  size of the two terms;
* the mapped trajectory against the target system integrated independently (its own definition,
  heyoka) from the mapped initial state, at the same times in the target's time variable.

Sign convention: every e(3) field is dx/dτ = {H, x} (eq. 2504-10-2, ERRATA 4), so Proposition 1's
time scale is k = +√det I.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache

import numpy as np
import sympy as sp

from nonholonomic.definition import (
    FirstIntegral,
    InvariantMeasure,
    MechanicalSystem,
    Projection,
    dot,
)
from nonholonomic.evidence.measure import CheckEvidence
from nonholonomic.hamiltonization.forms import hamiltonian_form
from nonholonomic.initial_state import constraint_problems, initial_state_problems, project_initial_state, vector_slice
from nonholonomic.numerics.integration import integrate
from nonholonomic.numerics.kernels import VectorKernel, parameter_vector, state_vector, vectorize
from nonholonomic.refusals import RefusedFields
from nonholonomic.systems import (
    SUPPORTED_POTENTIALS,
    SYSTEMS,
    chaplygin_ball as ball,
    clebsch,
    get_system,
    neumann,
    rubber_ball as rb,
    veselova as ves,
    veselova_e3 as ve3,
)

#: Relative push-forward residual accepted as round-off.
PUSH_FORWARD_TOLERANCE = 1e-10
#: Distance between the mapped and the independently integrated target trajectory accepted, per
#: unit of the target's time (both integrations at machine precision; errors grow linearly on tori).
TRAJECTORY_TOLERANCE_RATE = 1e-11
TRAJECTORY_TOLERANCE_FLOOR = 1e-9


@dataclass(frozen=True)
class LevelCondition:
    """A relation a source state must satisfy for the map to hold (beyond the source's constraints):
    ``|expression − value| ≤ tolerance · max(1, scale)``."""

    name: str
    expression: sp.Expr
    value: float
    formula: str
    scale: sp.Expr = sp.Integer(1)
    tolerance: float = 1e-9
    projection: Projection | None = None


@dataclass(frozen=True)
class IsomorphismMap:
    """A map from one system's phase space to another's, with a time substitution.

    Attributes
    ----------
    name, title, equation, formula : identification and the map in the paper's words.
    source, target : the two definitions (the target is integrated independently).
    forward : the target state (``target.state_symbols`` order) in the source state and parameters.
    target_parameters : the target's parameter values (``target.parameter_symbols`` order) in the
        source parameters and state (level constants like c depend on the state).
    time_density : dτ/dt in the source variables (1 if the times agree).
    time_variable : ``"t"`` or ``"tau"``: which of the source trajectory's times is the target's time.
    conditions : level conditions beyond the source's own constraints.
    constants : ``(name, expression, meaning)`` reported with each mapped state.
    inverse : the source state in the target state and source parameters, if given.
    corrections : where the paper's printed form was corrected (ERRATA items, new findings).
    """

    name: str
    title: str
    equation: str
    formula: str
    source: MechanicalSystem
    target: MechanicalSystem
    forward: tuple[sp.Expr, ...]
    target_parameters: tuple[sp.Expr, ...]
    time_density: sp.Expr
    time_variable: str
    conditions: tuple[LevelCondition, ...] = ()
    constants: tuple[tuple[str, sp.Expr, str], ...] = ()
    inverse: tuple[sp.Expr, ...] | None = None
    corrections: tuple[str, ...] = field(default=())

    @property
    def arguments(self) -> tuple[sp.Symbol, ...]:
        return self.source.state_symbols + self.source.parameter_symbols


# --------------------------------------------------------------------------------------------------
# the maps

def _sqrt_diag(entries: Sequence[sp.Expr], power: sp.Rational) -> sp.Matrix:
    return sp.diag(*[e ** power for e in entries])


def _e3_target(source: MechanicalSystem) -> MechanicalSystem:
    """Veselova's system after the time substitution as a system of its own: e(3), H (2504-11),
    dx/dτ = {H, x}, any of Veselova's potentials (Ũ(Γ) = U(γ(Γ)))."""

    form = hamiltonian_form(source)
    assert form is not None
    M, G = sp.Matrix(form.bracket.variables[:3]), sp.Matrix(form.bracket.variables[3:])
    H = form.hamiltonian
    size_M, size_G = sp.sqrt(dot(M, M)), sp.sqrt(dot(G, G))
    return MechanicalSystem(
        kind="e3_veselova_form", potential=source.potential,
        title="Veselova's system on e(3) after dtau = dt / (rho_omega sqrt(det I)) (eq. 2504-10-2, 2504-11)",
        equation="2504-11", parameters=source.parameters, state=ve3.STATE,
        rhs=form.bracket.hamiltonian_vector_field(H),
        integrals=(FirstIntegral("energy", H, sp.Abs(H) + dot(M, M), "H = (Gamma, I Gamma) M^2 / 2 + U(gamma(Gamma))",
                                 "2504-11"),
                   FirstIntegral("geometric", dot(G, G), sp.Integer(1), "(Gamma, Gamma)", "2504-10-2"),
                   FirstIntegral("area", dot(M, G), size_M * size_G, "(M, Gamma)", "2504-10-2")),
        measure=InvariantMeasure(sp.Integer(1), "rho = 1 (Lie-Poisson)", "2504-10-2"),
        reduced_time=None, potential_formula=source.potential_formula + ", U(gamma(Gamma))",
    )


@cache
def veselova_to_e3(potential: str = "zero") -> IsomorphismMap:
    """Eq. (2504-10-2): M = ρ_ω I^(1/2) ω, Γ = ρ_ω⁻¹ I^(−1/2) γ, dτ = dt/(ρ_ω √det I), any potential;
    the inverse ω = (Γ, IΓ)^(1/2) I^(−1/2) M, γ = (Γ, IΓ)^(−1/2) I^(1/2) Γ."""

    source = get_system("veselova", potential)
    form = hamiltonian_form(source)
    assert form is not None and source.reduced_time is not None
    target = _e3_target(source)
    return IsomorphismMap(
        name="veselova_to_e3", title="Veselova's system -> Hamiltonian system on e(3)",
        equation="2504-10-2, 2504-11", formula=form.formula,
        source=source, target=target, forward=form.to_bracket_variables,
        target_parameters=source.parameter_symbols, time_density=source.reduced_time.density, time_variable="tau",
        constants=(("H", form.hamiltonian.xreplace(dict(zip(form.bracket.variables, form.to_bracket_variables))),
                    "energy = H of eq. 2504-11"),),
        inverse=form.from_bracket_variables,
        corrections=("ERRATA 4: the field is dx/dtau = {H, x} with the e(3) bracket as printed",
                     "after eq. 2504-11 the leaf is (M, Gamma) = 0, printed (M, gamma) = 0"),
    )


def _proposition_1(I_diag: Sequence[sp.Expr], M: sp.Matrix, G: sp.Matrix) -> tuple[sp.Matrix, sp.Matrix, sp.Expr]:
    """Proposition 1's change of variables: s = (Γ, IΓ)^(−1/2) I^(1/2) Γ, L = I^(−1/2) M, and the
    level c = M² (Γ, IΓ) / det I."""
    I = sp.diag(*I_diag)
    GIG = dot(G, I * G)
    s = _sqrt_diag(I_diag, sp.Rational(1, 2)) * G / sp.sqrt(GIG)
    L = _sqrt_diag(I_diag, -sp.Rational(1, 2)) * M
    c = dot(M, M) * GIG / (I_diag[0] * I_diag[1] * I_diag[2])
    return s, L, c


@cache
def e3_to_clebsch() -> IsomorphismMap:
    """Proposition 1: (M, Γ) of eq. (2504-12) on Γ² = 1, (M, Γ) = 0 → (s, L) of the Clebsch case
    (2504-13) with the same α, β, I, c = M²(Γ, IΓ)/det I and k = +√det I (ERRATA 4), same time."""

    source, target = get_system("veselova_e3"), get_system("clebsch")
    I_diag = (ve3.I1, ve3.I2, ve3.I3)
    s, L, c = _proposition_1(I_diag, ve3.M, ve3.Gamma)
    det_I = I_diag[0] * I_diag[1] * I_diag[2]
    values = {clebsch.I1: ve3.I1, clebsch.I2: ve3.I2, clebsch.I3: ve3.I3, clebsch.alpha: ve3.alpha,
              clebsch.beta: ve3.beta, clebsch.c: c, clebsch.k: sp.sqrt(det_I)}
    return IsomorphismMap(
        name="e3_to_clebsch", title="Proposition 1: Hamiltonian (2504-12) on e(3) -> Clebsch case (2504-13)",
        equation="Proposition 1, 2504-12, 2504-13",
        formula=("L = I^(-1/2) M, s = (Gamma, I Gamma)^(-1/2) I^(1/2) Gamma on Gamma^2 = 1, (M, Gamma) = 0; target: "
                 "Clebsch with the same I, alpha, beta, c = M^2 (Gamma, I Gamma) / det I, k = +sqrt(det I); same time"),
        source=source, target=target, forward=tuple(s) + tuple(L),
        target_parameters=tuple(values[x] for x in target.parameter_symbols), time_density=sp.Integer(1),
        time_variable="t",
        constants=(("c", c, "M^2 (Gamma, I Gamma) / det I (Proposition 1's level)"),),
        corrections=("ERRATA 4: k = +sqrt(det I) with dx/dt = {H, x}; the printed -sqrt(det I) gives residual 2.0",
                     "the Hamiltonian printed after Proposition 1 needs -c/2 det I (Gamma, I^-1 Gamma) "
                     "in its beta part",
                     "Gamma^2 = 1 is needed (printed as a consequence); off it the residual is O(1)"),
    )


@cache
def veselova_to_neumann() -> IsomorphismMap:
    """The theorem after Proposition 1 (U = 0): Veselova → e(3) (2504-10-2) composed with
    Proposition 1 at α = 1, β = 0. It gives s = γ, L = ρ_ω ω, and the Neumann problem with the same
    I, c = 2h/det I (h the energy) and k = +√det I in τ (dτ = dt/(ρ_ω √det I))."""

    e3_map = veselova_to_e3("zero")
    source, target = e3_map.source, get_system("neumann")

    I_diag = (ves.I1, ves.I2, ves.I3)
    to_e3 = dict(zip(e3_map.target.state_symbols, e3_map.forward))
    M, G = (sp.Matrix(e3_map.target.state_symbols[:3]), sp.Matrix(e3_map.target.state_symbols[3:]))
    s, L, c = _proposition_1(I_diag, M, G)
    s, L, c = s.xreplace(to_e3), L.xreplace(to_e3), c.xreplace(to_e3)
    det_I = I_diag[0] * I_diag[1] * I_diag[2]
    values = {neumann.I1: ves.I1, neumann.I2: ves.I2, neumann.I3: ves.I3, neumann.c: c, neumann.k: sp.sqrt(det_I)}
    return IsomorphismMap(
        name="veselova_to_neumann", title="Veselova's system (U = 0) -> Neumann problem, on an energy level",
        equation="theorem after Proposition 1; 2504-10-2, 2504-13",
        formula=("s = (Gamma, I Gamma)^(-1/2) I^(1/2) Gamma = gamma, L = I^(-1/2) M = rho_omega omega, "
                 "rho_omega = (gamma, I^-1 gamma)^(1/2); target: Neumann with the same I, c = 2 h / det I "
                 "(h = (I omega, omega)/2), k = +sqrt(det I); d tau = dt / (rho_omega sqrt(det I))"),
        source=source, target=target, forward=tuple(s) + tuple(L),
        target_parameters=tuple(values[x] for x in target.parameter_symbols),
        time_density=e3_map.time_density, time_variable="tau",
        constants=(("c", c, "2 h / det I, h = (I omega, omega) / 2"),),
        corrections=("ERRATA 3: N = (gamma, I^-1 gamma)^(-1/2); ERRATA 4: k = +sqrt(det I) with dx/dtau = {H, x}",),
    )


@cache
def chaplygin_ball_to_clebsch() -> IsomorphismMap:
    """Theorem 3 as corrected by ERRATA 8 (U = 0, (M, γ) = 0): L = ρ_μ M, s = (γ, Bγ)^(−1/2) B^(1/2) γ,
    L̃ = B^(−1/2) L, B = I J⁻¹; the Clebsch case with I → B, α = −β = det J / D, c = L²(γ, Bγ)/det B,
    k = +√det B, in τ (dτ = ρ_μ dt)."""

    source, target = get_system("chaplygin_ball", "zero"), get_system("clebsch")
    assert source.reduced_time is not None
    J = [ball.I1 + ball.D, ball.I2 + ball.D, ball.I3 + ball.D]
    B = [ball.I1 / J[0], ball.I2 / J[1], ball.I3 / J[2]]
    rho = ball.measure_density()
    L = rho * ball.M
    s, L_tilde, c_B = _proposition_1(B, L, ball.gamma)
    det_J, det_B = J[0] * J[1] * J[2], B[0] * B[1] * B[2]
    values = {clebsch.I1: B[0], clebsch.I2: B[1], clebsch.I3: B[2], clebsch.alpha: det_J / ball.D,
              clebsch.beta: -det_J / ball.D, clebsch.c: c_B, clebsch.k: sp.sqrt(det_B)}
    M, g = ball.M, ball.gamma
    area = dot(M, g)
    return IsomorphismMap(
        name="chaplygin_ball_to_clebsch", title="Theorem 3: Chaplygin's ball (U = 0, (M, gamma) = 0) -> Clebsch case",
        equation="theorem after eq. 2604-7 (ERRATA 8); 2604-5, 2504-13",
        formula=("L = rho_mu M, s = (gamma, B gamma)^(-1/2) B^(1/2) gamma, L~ = B^(-1/2) L, B = I J^-1; target: "
                 "Clebsch with I -> B, alpha = -beta = det J / D, c = L^2 (gamma, B gamma) / det B, k = +sqrt(det B); "
                 "d tau = rho_mu dt"),
        source=source, target=target, forward=tuple(s) + tuple(L_tilde),
        target_parameters=tuple(values[x] for x in target.parameter_symbols),
        time_density=source.reduced_time.density, time_variable="tau",
        conditions=(LevelCondition("M", area, 0.0, "(M, gamma) = 0 (zero constant of areas)",
                                   scale=sp.sqrt(dot(M, M) * dot(g, g)),
                                   projection=Projection("M", tuple(M - area / dot(g, g) * g),
                                                         "M -> M - (M, gamma) gamma / (gamma, gamma)")),),
        constants=(("c", c_B, "L^2 (gamma, B gamma) / det B"),),
        corrections=("ERRATA 8: s = (gamma, B gamma)^(-1/2) B^(+1/2) gamma (printed B^(-1/2)); target constants "
                     "alpha = -beta = det J / D, k = +sqrt(det B), c = L^2 (gamma, B gamma) / det B",),
    )


@cache
def rubber_ball_to_veselova(potential: str = "zero") -> IsomorphismMap:
    """The rubber-ball paragraph (ERRATA 10): the same (ω, γ) and time, Veselova's system with I → J = I + D·1."""

    source, target = get_system("rubber_ball", potential), get_system("veselova", potential)
    values = {ves.I1: rb.I1 + rb.D, ves.I2: rb.I2 + rb.D, ves.I3: rb.I3 + rb.D}
    shared = {x: x for x in target.parameter_symbols if x in source.parameter_symbols}
    values.update({x: v for x, v in shared.items() if x not in values})
    missing = [x for x in target.parameter_symbols if x not in values]
    if missing:  # pragma: no cover - the two kinds share their potentials' parameters
        raise ValueError(f"no value for {missing}")
    return IsomorphismMap(
        name="rubber_ball_to_veselova", title="Rubber ball -> Veselova's system with I -> J = I + D 1",
        equation="rubber-ball paragraph after eq. 2704-6 (ERRATA 10)",
        formula="omega -> omega, gamma -> gamma, same time; target: Veselova with I -> J = I + D 1, same potential",
        source=source, target=target, forward=tuple(source.state_symbols),
        target_parameters=tuple(values[x] for x in target.parameter_symbols),
        time_density=sp.Integer(1), time_variable="t", inverse=tuple(target.state_symbols),
        corrections=("ERRATA 10: I_Q omega' = J omega' - D (omega', gamma) gamma (printed J omega)",),
    )


@dataclass(frozen=True)
class MapEntry:
    """One of the paper's maps: its source kind, how it is built for a source potential, and the source
    potentials it holds for (None: all of the source's)."""

    source: str
    build: Callable[..., IsomorphismMap]
    potentials: tuple[str, ...] | None = None


#: Every map by name.
MAPS: dict[str, MapEntry] = {
    "veselova_to_e3": MapEntry("veselova", veselova_to_e3),
    "veselova_to_neumann": MapEntry("veselova", lambda potential="zero": veselova_to_neumann(), ("zero",)),
    "e3_to_clebsch": MapEntry("veselova_e3", lambda potential="zero": e3_to_clebsch(), ("zero",)),
    "chaplygin_ball_to_clebsch": MapEntry("chaplygin_ball", lambda potential="zero": chaplygin_ball_to_clebsch(),
                                          ("zero",)),
    "rubber_ball_to_veselova": MapEntry("rubber_ball", rubber_ball_to_veselova),
}


def get_map(name: str, potential: str = "zero") -> IsomorphismMap:
    """The map ``name`` for a source with ``potential``.

    Raises
    ------
    KeyError
        Unknown map, or a potential the map does not hold for (the message says which it needs).
    """
    if name not in MAPS:
        raise KeyError(f"unknown map {name!r}; known: {', '.join(MAPS)}")
    entry = MAPS[name]
    if entry.potentials is not None and potential not in entry.potentials:
        raise KeyError(f"{name} holds for the potential {' or '.join(entry.potentials)} only, not {potential!r}")
    return entry.build(potential)


def maps_for(kind: str, potential: str) -> list[str]:
    """Names of the maps whose source is ``kind`` with ``potential`` (a built-in one: the maps are
    derived for named potentials, not for a user's expression)."""

    return [name for name, entry in MAPS.items()
            if entry.source == kind and potential in (entry.potentials or SUPPORTED_POTENTIALS[kind])]


# --------------------------------------------------------------------------------------------------
# numerics

@dataclass(frozen=True)
class _Kernels:
    forward: VectorKernel
    target_parameters: VectorKernel
    time_density: VectorKernel
    push_forward: VectorKernel
    target_field: VectorKernel
    conditions: VectorKernel
    condition_scales: VectorKernel
    constants: VectorKernel
    inverse: VectorKernel | None
    level_projections: tuple[VectorKernel | None, ...]


@cache
def kernels(m: IsomorphismMap) -> _Kernels:
    """Compiled forward map, target parameters, dτ/dt, both sides of the push-forward identity,
    level conditions and constants (all over source state + source parameters)."""
    args = m.arguments
    x = sp.Matrix(m.source.state_symbols)
    Phi = sp.Matrix(m.forward)
    push = Phi.jacobian(x) * sp.Matrix(m.source.rhs) / m.time_density
    at_image = dict(zip(m.target.state_symbols, m.forward)) | dict(zip(m.target.parameter_symbols, m.target_parameters))
    g = [e.xreplace(at_image) for e in m.target.rhs]
    inverse = None
    if m.inverse is not None:
        inverse = vectorize(m.inverse, m.target.state_symbols + m.source.parameter_symbols)
    return _Kernels(
        forward=vectorize(m.forward, args), target_parameters=vectorize(m.target_parameters, args),
        time_density=vectorize([m.time_density], args), push_forward=vectorize(list(push), args),
        target_field=vectorize(g, args),
        conditions=vectorize([c.expression for c in m.conditions] or [sp.Integer(0)], args),
        condition_scales=vectorize([c.scale for c in m.conditions] or [sp.Integer(1)], args),
        constants=vectorize([e for _, e, _ in m.constants] or [sp.Integer(0)], args),
        inverse=inverse,
        level_projections=tuple(None if c.projection is None else vectorize(c.projection.expression, args)
                                for c in m.conditions),
    )


def condition_violations(m: IsomorphismMap, parameters: np.ndarray, states: np.ndarray) -> list[list[tuple[str, str]]]:
    """For each state: ``(field, reason)`` of every level condition it violates (with the value and
    the tolerance); the source's own constraints are the caller's (:mod:`nonholonomic.simulation`)."""
    if not m.conditions:
        return [[] for _ in range(len(states))]
    k = kernels(m)
    values, scales = k.conditions(states, parameters), k.condition_scales(states, parameters)
    out = []
    for row, scale_row in zip(values, scales):
        problems = []
        for cond, value, scale in zip(m.conditions, row, scale_row):
            allowed = cond.tolerance * max(1.0, abs(float(scale)))
            off = float(value - cond.value)
            if not np.isfinite(off) or abs(off) > allowed:
                problems.append((cond.name, f"{m.name} needs {cond.formula}: value {value:.12g}, off by {off:.3g} "
                                            f"(tolerance {allowed:.3g})"))
        out.append(problems)
    return out


def project_to_level(m: IsomorphismMap, parameters: np.ndarray, states: np.ndarray) -> np.ndarray:
    """``states`` moved onto the source's constraints, then onto the map's level conditions."""

    out = np.array([project_initial_state(m.source, parameters, y)[0] for y in states])
    for cond, project in zip(m.conditions, kernels(m).level_projections):
        if cond.projection is None or project is None:
            continue
        out[:, vector_slice(m.source, cond.projection.vector)] = project(out, parameters)
    return out


def apply(m: IsomorphismMap, parameters: np.ndarray, states: np.ndarray) -> dict[str, np.ndarray]:
    """The mapped states, the target parameters and the constants at each state (rows)."""
    k = kernels(m)
    return {"states": k.forward(states, parameters), "target_parameters": k.target_parameters(states, parameters),
            "constants": k.constants(states, parameters)[:, : len(m.constants)]}


def push_forward_residual(m: IsomorphismMap, parameters: np.ndarray, states: np.ndarray) -> float:
    """``max |DΦ f/(dτ/dt) − g(Φ)|₁ / (|DΦ f/(dτ/dt)|₁ + |g(Φ)|₁)`` over ``states``."""
    k = kernels(m)
    push, g = k.push_forward(states, parameters), k.target_field(states, parameters)
    scale = np.sum(np.abs(push), axis=1) + np.sum(np.abs(g), axis=1)
    scale = np.where(scale > 0, scale, 1.0)
    return float(np.max(np.sum(np.abs(push - g), axis=1) / scale))


def sample_states(m: IsomorphismMap, parameters: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """``count`` random source states on the map's level set (normal components, then projected)."""
    rng = np.random.default_rng(seed)
    return project_to_level(m, parameters, rng.normal(size=(count, m.source.dimension)))


@dataclass(frozen=True)
class TrajectoryComparison:
    """The mapped source trajectory against the target integrated from the mapped initial state."""

    times: np.ndarray
    mapped: np.ndarray
    target: np.ndarray
    distance: float
    relative_distance: float
    parameter_spread: float
    tolerance: float
    segment_distance: float
    segments: int


def compare_trajectories(m: IsomorphismMap, parameters: np.ndarray, t: np.ndarray, tau: np.ndarray | None,
                         states: np.ndarray) -> TrajectoryComparison:
    """Map a source trajectory and integrate the target (heyoka, its own definition) from the
    mapped initial state at the same times in the target's time variable.

    ``parameter_spread`` is the largest relative change of the target parameters along the
    trajectory (the level constants are integrals, so it must be round-off).
    """
    if m.time_variable == "tau":
        if tau is None:
            raise ValueError(f"{m.name} compares in tau, but the trajectory has no reduced time")
        times = np.asarray(tau, dtype=float)
    else:
        times = np.asarray(t, dtype=float)
    mapped = apply(m, parameters, states)
    p_target = mapped["target_parameters"]
    # relative to each parameter's size along the trajectory (a level constant may be 0, e.g. c at rest)
    size_p = np.maximum(np.max(np.abs(p_target), axis=0), 1e-12) if p_target.size else np.ones(0)
    spread = float(np.max(np.abs(p_target - p_target[0]) / size_p)) if p_target.size else 0.0
    target = integrate(m.target, p_target[0], mapped["states"][0], 0.0, 0, times=times)
    diff = np.abs(mapped["states"] - target.states)
    distance = float(np.max(diff))
    size = float(np.max(np.abs(mapped["states"])))
    tolerance = max(TRAJECTORY_TOLERANCE_FLOOR, TRAJECTORY_TOLERANCE_RATE * float(abs(times[-1])))
    # restarted from the mapped state at the start of each of (at most) 50 sample intervals
    segment = 0.0
    starts = np.unique(np.linspace(0, len(times) - 2, min(len(times) - 1, 50)).astype(int))
    for k in starts:
        step = float(times[k + 1] - times[k])
        if step <= 0:
            continue
        end = integrate(m.target, p_target[0], mapped["states"][k], 0.0, 0, times=np.array([0.0, step])).states[-1]
        segment = max(segment, float(np.max(np.abs(end - mapped["states"][k + 1]))))
    return TrajectoryComparison(times, mapped["states"], target.states, distance, distance / max(size, 1e-300),
                                spread, tolerance, segment, len(starts))


def isomorphism_evidence(system: MechanicalSystem, parameters: np.ndarray, t: np.ndarray, tau: np.ndarray | None,
                         states: np.ndarray, max_points: int = 50) -> list[CheckEvidence]:
    """The job check ``isomorphisms``: for every map from ``system``, the push-forward residual at
    the job's states and the mapped trajectory against the independently integrated target.

    A map whose level condition the job's initial state violates (e.g. the ball with (M, γ) ≠ 0)
    is reported as not applicable (verdict None) with the condition and its value.
    """
    out: list[CheckEvidence] = []
    idx = np.unique(np.linspace(0, len(states) - 1, min(len(states), max_points)).astype(int))
    for name in maps_for(system.kind, system.potential):
        m = get_map(name, system.potential)
        problems = condition_violations(m, parameters, states[:1])[0]
        if problems:
            out.append(CheckEvidence(
                name=f"isomorphism:{name}", quantity="level condition", formula=m.formula, equation=m.equation,
                method="not applicable", residual=None, tolerance=None, passed=None,
                detail="; ".join(reason for _, reason in problems)))
            continue
        residual = push_forward_residual(m, parameters, states[idx])
        out.append(CheckEvidence(
            name=f"isomorphism:{name}", quantity="push-forward field residual", formula=m.formula,
            equation=m.equation, method="pointwise", residual=residual, tolerance=PUSH_FORWARD_TOLERANCE,
            passed=bool(np.isfinite(residual) and residual <= PUSH_FORWARD_TOLERANCE),
            detail=(f"max over {len(idx)} trajectory samples of |D Phi f / (dtau/dt) - g(Phi)|_1 / "
                    "(|D Phi f / (dtau/dt)|_1 "
                    f"+ |g(Phi)|_1), g the field of {m.target.kind} with the target parameters of each state; "
                    + "; ".join(m.corrections))))
        cmp = compare_trajectories(m, parameters, t, tau, states)
        whole = bool(np.isfinite(cmp.distance) and cmp.distance <= cmp.tolerance)
        local = bool(np.isfinite(cmp.segment_distance) and cmp.segment_distance <= TRAJECTORY_TOLERANCE_FLOOR)
        constant = cmp.parameter_spread <= 1e-10
        detail = (f"{m.target.kind} integrated by heyoka from the mapped initial state at the same "
                  f"{'reduced times tau' if m.time_variable == 'tau' else 'times t'} (up to {cmp.times[-1]:.6g}): "
                  f"max |mapped - target| = {cmp.distance:.3g} (relative {cmp.relative_distance:.3g}); restarted from "
                  f"the mapped state at {cmp.segments} sample intervals: {cmp.segment_distance:.3g} (tolerance "
                  f"{TRAJECTORY_TOLERANCE_FLOOR:g}); the target parameters (level constants) vary by "
                  f"{cmp.parameter_spread:.2g} along the trajectory")
        if not whole and local:
            detail += ("; the whole-horizon distance exceeds its tolerance while every restarted interval agrees: "
                       "nearby trajectories separate (sensitive dependence), so round-off of 1e-16 grows; the map "
                       "is judged on the intervals")
        out.append(CheckEvidence(
            name=f"isomorphism:{name}", quantity="mapped trajectory vs independently integrated target",
            formula=m.formula, equation=m.equation, method="trajectory",
            residual=cmp.distance if whole else cmp.segment_distance,
            tolerance=cmp.tolerance if whole else TRAJECTORY_TOLERANCE_FLOOR,
            passed=bool((whole or local) and constant), detail=detail))
        if m.inverse is not None:
            inverse = kernels(m).inverse
            assert inverse is not None  # compiled whenever the map has an inverse
            back = inverse(apply(m, parameters, states[idx])["states"], parameters)
            err = float(np.max(np.abs(back - states[idx])) / max(float(np.max(np.abs(states[idx]))), 1e-300))
            out.append(CheckEvidence(
                name=f"isomorphism:{name}", quantity="inverse map", formula=m.formula, equation=m.equation,
                method="pointwise", residual=err, tolerance=1e-12, passed=bool(err <= 1e-12),
                detail=f"max relative |Phi^-1(Phi(x)) - x| over {len(idx)} samples"))
    return out


# --------------------------------------------------------------------------------------------------
# the endpoint's work: describe a map, map named states

class MapInputError(RefusedFields):
    """Bad states for a map: ``problems()`` lists ``(field, reason)`` with fields like ``states[2].gamma``."""


def _groups(system: MechanicalSystem, values: np.ndarray) -> dict[str, object]:
    out: dict[str, object] = {}
    i = 0
    for par in system.parameters:
        n = len(par.symbols)
        chunk = [float(v) for v in values[i:i + n]]
        out[par.name] = chunk[0] if n == 1 and par.shape == "scalar" else chunk
        i += n
    return out


def _vectors(system: MechanicalSystem, row: np.ndarray) -> dict[str, list[float]]:
    out, i = {}, 0
    for vec in system.state:
        n = len(vec.symbols)
        out[vec.name] = [float(v) for v in row[i:i + n]]
        i += n
    return out


def describe(m: IsomorphismMap) -> dict[str, object]:
    """The map in words: source, target, time, level set, constants and corrections."""

    return {
        "name": m.name, "title": m.title, "equation": m.equation, "formula": m.formula,
        "source": {"kind": m.source.kind, "potential": m.source.potential,
                   "state": [v.name for v in m.source.state]},
        "target": {"kind": m.target.kind, "potential": m.target.potential, "title": m.target.title,
                   "state": [v.name for v in m.target.state], "job_kind": m.target.kind in SYSTEMS},
        "time": ("the same time t" if m.time_variable == "t" else
                 f"the reduced time tau: {m.source.reduced_time.formula}"
                 if m.source.reduced_time is not None and m.source.reduced_time.density == m.time_density
                 else f"the reduced time tau, d tau / dt = {sp.sstr(m.time_density)}"),
        "level_set": [c.formula for c in m.source.constraints] + [c.formula for c in m.conditions],
        "constants": [{"name": n, "meaning": meaning} for n, _, meaning in m.constants],
        "inverse": m.inverse is not None,
        "corrections": list(m.corrections),
        "convention": "every e(3) field is dx/dtau = {H, x} (eq. 2504-10-2, ERRATA 4)",
    }


def map_states(m: IsomorphismMap, parameters: dict[str, object], states: Sequence[dict[str, Sequence[float]]],
               *, inverse: bool = False, project: bool = False) -> dict[str, object]:
    """Apply ``m`` (or its inverse) to named states.

    Parameters
    ----------
    parameters : the source's parameter groups (``{"inertia": [..], "D": ..}``, potential's included).
    states : source states by vector name (target states if ``inverse``).
    inverse : map target states back (maps with an inverse only).
    project : move each source state onto the constraints and level set first (reported).

    Raises
    ------
    MapInputError
        Unknown or missing vectors, or a state off the level set where the map holds (the
        condition, its value and the tolerance are named).
    """

    p = parameter_vector(m.source, dict(parameters))
    problems: list[tuple[str, str]] = []
    rows: list[np.ndarray] = []
    projections: list[list[dict[str, object]]] = []
    if inverse:
        if m.inverse is None:
            raise MapInputError([("inverse", f"{m.name} has no inverse here")])
        inv = kernels(m).inverse
        assert inv is not None
        names = [v.name for v in m.target.state]
        for i, state in enumerate(states):
            bad = sorted(set(state) ^ set(names))
            if bad:
                problems += [(f"states[{i}].{b}", f"expected exactly the target vectors {', '.join(names)}")
                             for b in bad]
                continue
            y = np.concatenate([np.asarray(state[n], dtype=float) for n in names])
            x = inv(y[None, :], p)[0]
            problems += [(f"states[{i}].{f.field.removeprefix('initial_state.')}",
                          f"its image under the inverse map {f.reason}") for f in constraint_problems(m.source, p, x)]
            rows.append(y)
        if problems:
            raise MapInputError(problems)
        Y = np.array(rows)
        X = inv(Y, p)
        return {**_header(m, p), "direction": "inverse",
                "states": [{"state": _vectors(m.source, x)} for x in X]}
    for i, state in enumerate(states):
        found = initial_state_problems(m.source, parameters, state, project)
        if found:
            problems += [(f"states[{i}]." + f.field.removeprefix("initial_state."), f.reason) for f in found]
            continue
        y = state_vector(m.source, dict(state), p)
        done: list[dict[str, object]] = []
        if project:
            y, reports = project_initial_state(m.source, p, y)
            done = [{"field": f"states[{i}]." + r.field.removeprefix("initial_state."), "change": r.change,
                     "projection": r.projection} for r in reports]
            before = y.copy()
            y = project_to_level(m, p, y[None, :])[0]
            if np.any(y != before):
                done.append({"field": f"states[{i}]", "change": float(np.max(np.abs(y - before))),
                             "projection": "; ".join(c.projection.formula for c in m.conditions if c.projection)})
        problems += [(f"states[{i}].{f}", r) for f, r in condition_violations(m, p, y[None, :])[0]]
        rows.append(y)
        projections.append(done)
    if problems:
        raise MapInputError(problems)
    X = np.array(rows)
    out = apply(m, p, X)
    residual = push_forward_residual(m, p, X)
    densities = kernels(m).time_density(X, p)[:, 0]
    mapped = []
    for j, x in enumerate(X):
        entry: dict[str, object] = {
            "state": _vectors(m.target, out["states"][j]),
            "target_parameters": _groups(m.target, out["target_parameters"][j]),
            "constants": {n: float(v) for (n, _, _), v in zip(m.constants, out["constants"][j])},
            "time_density": float(densities[j]),
        }
        if project:
            entry["source_state"] = _vectors(m.source, x)
            entry["projections"] = projections[j]
        mapped.append(entry)
    return {**_header(m, p), "direction": "forward", "states": mapped,
            "push_forward_residual": {"value": residual, "tolerance": PUSH_FORWARD_TOLERANCE,
                                      "passed": bool(residual <= PUSH_FORWARD_TOLERANCE),
                                      "detail": "max over the given states of |D Phi f / (dtau/dt) - g(Phi)|_1 / "
                                                "(|D Phi f / (dtau/dt)|_1 + |g(Phi)|_1)"},
            "target_job_system": _job_system(m, out["target_parameters"][0])}


def _header(m: IsomorphismMap, p: np.ndarray) -> dict[str, object]:
    return {"map": describe(m), "source_parameters": _groups(m.source, p)}


def _job_system(m: IsomorphismMap, p_target: np.ndarray) -> dict[str, object] | None:
    """The target as a job's ``system`` block (for the first state), or None if it is not a job kind."""

    if m.target.kind not in SYSTEMS:
        return None
    groups = _groups(m.target, p_target)
    own = {par.name for par in SYSTEMS[m.target.kind].PARAMETERS}
    return {"kind": m.target.kind, **{k: v for k, v in groups.items() if k in own},
            "potential": {"kind": m.target.potential, **{k: v for k, v in groups.items() if k not in own}}}
