"""States on a level set of a system's integrals: the ``sample`` members of an ensemble.

``on_level(system, p, level, count, seed)`` draws ``count`` phase points that satisfy every
constraint of the system (|γ| = 1, (ω, γ) = 0, Φ(x) = 0 ...) and give the integrals named in
``level`` the requested values, e.g. the energy and the constant of areas of Chaplygin's ball
(eq. 2604-2) or the energy and K of the nonholonomic Jacobi problem (eqs. 2804-2, 2804-4).

Method (one plan per kind: its record's ``sampling``, :class:`nonholonomic.kinds.Sampling`)
-------------------------------------------------------------------------------------------
1. Positions. Unit vectors (γ, s, Γ, E) are uniform on the sphere (normalised standard normal
   vectors); E at a fixed angle to γ is ``(γ, E) γ + √(1 − (γ, E)²) v`` with v uniform among the
   unit vectors ⊥ γ. The centre x of the ball on the quadric (x, B⁻¹x) = 1 is uniform with respect to
   the surface area: x = B^(1/2) y with y uniform on the sphere is accepted with probability
   |B⁻¹x| / max |B⁻¹x| (the area element of x = B^(1/2) y is ∝ |B⁻¹x| dS_y), then moved onto the
   quadric by the system's own radial projection.
2. The velocity (or momentum) ``v = v₀ + t u``: u is uniform among the unit vectors of the
   admissible space (all of R³, or the plane ⊥ γ, ⊥ E, ⊥ Γ of the constraint (ω, γ) = 0,
   (ω, E) = 0, (M, Γ) = 0), v₀ a particular solution of the fixed linear integrals (v₀ = c γ for
   the area (M, γ) = c of the ball, c s for (s, L) = c). The energy of every kind is quadratic in
   the velocity at a fixed position, ``H(v₀ + t u) = e₀ + e₁ t + e₂ t²``; its three coefficients
   are read off the system's own energy kernel (at t = 0, ±1) and H = h is solved for t, taking
   either real root with probability ½ (one Newton step with the kernel polishes it).
3. The nonholonomic Jacobi problem with K fixed (U = 0 or k/2 x²): ω = a n + w, w ⊥ n. Then
   ``H = ½ D₀ a² + ½ (D₀ + D) |w|² + U(x)`` (eq. 2804-2 with (ω, n) = a, ERRATA 12) and K depends on
   w only, ``K = K₀(x) + |w|² q_K(ŵ)`` (eq. 2804-4; K₀ = −k (x, B⁻²x)/(D₀ + D), 0 for U = 0): w's
   direction is uniform in the tangent plane, |w| is set by K, and a (either sign, probability ½)
   by H as in step 2 with v₀ = w and u = n.
4. Every candidate is checked with the system's kernels: the constraints to 1e-12 (relative to
   their scale; in practice ~1e-15) and each fixed integral to 1e-12 of max(|value|, its scale).
   Candidates with no real root (the level is not reached from that position and direction), and
   positions thinned out in step 1, are rejected; the draws continue in batches of
   :data:`BATCH` candidates until ``count`` are accepted, at most ``max(1000 count, BATCH)``
   candidates (and 100 000 if none at all is accepted), else :class:`LevelError` says what the
   tried states would have needed (e.g. "needs energy >= 0.41").

The accepted states are these draws conditioned on reaching the level (e.g. with the area fixed,
positions γ from which (M, γ) = c already costs more than h − U(γ) never occur). Where the kinetic
energy is indefinite (Clebsch with α + β I_i of both signs, eq. 2504-12 with β < 0) the level set is
unbounded and |L|, |M| have heavy tails (directions near the null cone of the form).

Reproducibility: ``numpy.random.default_rng(seed)``; each batch draws the same arrays of
:data:`BATCH` rows whatever is accepted, so the same (system, parameters, level, seed) gives the
same states bit for bit, and a smaller ``count`` gives a prefix of a larger one.

The energy alone sets the scale of the velocities, so every level fixes it; which other integrals
a level may fix is :func:`fixable` (the catalog lists it). Constraint-like integrals (|γ|² = 1,
Φ(x) = 0, (ω, γ) = 0, (M, Γ) = 0) hold on every sample and are never fixed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from numbers import Integral, Real

import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.initial_state import vector_slice
from nonholonomic.kinds import Sampling
from nonholonomic.numerics.kernels import numeric
from nonholonomic.refusals import RefusedField
from nonholonomic.systems import registered

#: Candidates drawn per batch (fixed: the random stream and hence the samples do not depend on count).
BATCH = 2048
#: At most this many candidates per requested state.
TRIES_PER_STATE = 1000
#: Give up after this many candidates if none was accepted.
EARLY_GIVE_UP = 100_000
#: Tolerance of the constraints and of the fixed integrals on every returned state.
TOLERANCE = 1e-12


class LevelError(RefusedField):
    """A ``sample`` request that cannot be met.

    Attributes
    ----------
    field : str
        The offending request field: ``"level"``, ``"level.<name>"``, ``"count"`` or ``"seed"``.
    reason : str
        Why, in words (with the fixable names or the bound the level misses).
    """


# --- draws ----------------------------------------------------------------------------------------


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` unit vectors uniform on the sphere (normalised standard normal vectors)."""
    z = rng.standard_normal((n, 3))
    return z / np.linalg.norm(z, axis=1, keepdims=True)


def _unit_perp(rng: np.random.Generator, g: np.ndarray) -> np.ndarray:
    """Unit vectors uniform on the circle ⊥ each unit row of ``g`` (a standard normal vector
    projected on the plane is an isotropic normal vector of the plane)."""
    z = rng.standard_normal(g.shape)
    z -= np.sum(z * g, axis=1, keepdims=True) * g
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    # a second projection removes the rounding left along g (|(u, g)| ~ 1e-17)
    z -= np.sum(z * g, axis=1, keepdims=True) * g
    return z / np.linalg.norm(z, axis=1, keepdims=True)


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@dataclass
class _Draw:
    """One batch of candidates before the energy is solved.

    ``states`` holds the positions and the velocity ``base`` (v₀); the velocity is
    ``base + t direction`` once t solves H = h. ``valid`` marks the positions kept by the thinning of
    step 1; ``floors`` gives, per level name fixed before the energy, the least value reachable from
    each candidate (a candidate is kept where the level is at least its floor).
    """

    states: np.ndarray
    base: np.ndarray
    direction: np.ndarray
    valid: np.ndarray
    floors: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class _Context:
    system: MechanicalSystem
    p: np.ndarray
    level: Mapping[str, float]

    def slot(self, name: str) -> slice:
        return vector_slice(self.system, name)

    def integral_index(self, name: str) -> int:
        return [i.name for i in self.system.integrals].index(name)

    def parameter(self, name: str) -> np.ndarray:
        """The values of the parameter group ``name`` (in its symbols' order) from the vector p."""
        offset = 0
        for par in self.system.parameters:
            if par.name == name:
                return self.p[offset:offset + len(par.symbols)]
            offset += len(par.symbols)
        raise KeyError(name)

    def integral(self, states: np.ndarray, name: str) -> np.ndarray:
        with np.errstate(all="ignore"):
            return numeric(self.system).integrals(states, self.p)[:, self.integral_index(name)]

    def new_states(self, n: int, **vectors: np.ndarray) -> np.ndarray:
        states = np.zeros((n, self.system.dimension))
        for name, value in vectors.items():
            states[:, self.slot(name)] = value
        return states


Drawer = Callable[[_Context, np.random.Generator, int], _Draw]


def _sphere_then_velocity(position: str, velocity: str, plane: bool, linear: str | None) -> Drawer:
    """Drawer: ``position`` uniform on the sphere; the velocity direction uniform on the sphere
    (``plane`` False) or on the circle ⊥ the position (``plane`` True); if the level fixes the linear
    integral ``linear`` = (velocity, position) = c, the base is c·position and the direction ⊥ it."""

    def draw(ctx: _Context, rng: np.random.Generator, n: int) -> _Draw:
        g = _unit(rng, n)
        base = np.zeros((n, 3))
        if plane:
            u = _unit_perp(rng, g)
        elif linear is not None and linear in ctx.level:
            u = _unit_perp(rng, g)
            base = float(ctx.level[linear]) * g
        else:
            u = _unit(rng, n)
        return _Draw(ctx.new_states(n, **{position: g, velocity: base}), base, u, np.ones(n, bool))

    return draw


def _draw_chaplygin_ball_veselova(ctx: _Context, rng: np.random.Generator, n: int) -> _Draw:
    """γ uniform; E uniform, or at the fixed (γ, E); ω ⊥ E."""
    g = _unit(rng, n)
    if "gamma_E" in ctx.level:
        c = float(ctx.level["gamma_E"])
        E = _normalize(c * g + np.sqrt(1.0 - c * c) * _unit_perp(rng, g))
    else:
        E = _unit(rng, n)
    u = _unit_perp(rng, E)
    base = np.zeros((n, 3))
    return _Draw(ctx.new_states(n, gamma=g, E=E, omega=base), base, u, np.ones(n, bool))


def _quadric_matrix(ctx: _Context) -> np.ndarray:
    """A = B⁻¹ from the six entries 11, 12, 13, 22, 23, 33 held by the parameter "B"."""
    a11, a12, a13, a22, a23, a33 = ctx.parameter("B")
    return np.array([[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]])


def _draw_ball_on_quadric(ctx: _Context, rng: np.random.Generator, n: int) -> _Draw:
    """x uniform by area on (x, A x) = 1; ω = w + a n with |w| from K (if fixed), a from H."""
    A = _quadric_matrix(ctx)
    lam, Q = np.linalg.eigh(A)
    root_B = (Q / np.sqrt(lam)) @ Q.T                      # A^(-1/2) = B^(1/2)
    x = _unit(rng, n) @ root_B                             # (x, A x) = 1: uniform-on-sphere pushed forward
    keep = rng.random(n) * np.sqrt(lam[-1]) <= np.linalg.norm(x @ A, axis=1)   # area element ∝ |A x|
    x = x / np.sqrt(np.sum(x * (x @ A), axis=1, keepdims=True))                 # radial projection
    normal = _normalize(x @ A)
    zeros = np.zeros((n, 3))
    floors: dict[str, np.ndarray] = {}
    if "K" in ctx.level:
        u = _unit_perp(rng, normal)
        # K(w) = K0 + |w|^2 q_K(u): K0 at omega = 0, q_K = K(u) - K0 (eq. 2804-4, read off the kernel)
        K0 = ctx.integral(ctx.new_states(n, x=x, omega=zeros), "K")
        qK = ctx.integral(ctx.new_states(n, x=x, omega=u), "K") - K0
        with np.errstate(all="ignore"):
            size = np.sqrt((float(ctx.level["K"]) - K0) / qK)
        floors["K"] = K0
        base = np.where(np.isfinite(size)[:, None], size[:, None] * u, 0.0)
        direction = normal
    else:
        base, direction = zeros, _unit(rng, n)
    return _Draw(ctx.new_states(n, x=x, omega=base), base, direction, keep, floors)


def _drawer(plan: Sampling) -> Drawer:
    """The drawer of a kind's :class:`~nonholonomic.kinds.Sampling` plan."""
    if plan.method == "chaplygin_ball_veselova":
        return _draw_chaplygin_ball_veselova
    if plan.method == "ball_on_quadric":
        return _draw_ball_on_quadric
    if plan.position is None:
        raise ValueError("a sphere_then_velocity plan names its position vector")
    return _sphere_then_velocity(plan.position, plan.velocity, plan.plane, plan.linear)


def plan_of(system: MechanicalSystem) -> Sampling | None:
    """The sampling plan of ``system``'s kind (its record's ``sampling``), or None (no states on a level set)."""
    record = registered(system.kind)
    return None if record is None else record.sampling


# --- public API -----------------------------------------------------------------------------------


def fixable(system: MechanicalSystem) -> tuple[str, ...]:
    """The integrals a ``sample`` level may fix for ``system`` (its kind and potential), energy first.

    Chaplygin's ball: energy and the area c = (M, γ) (eq. 2604-2); the nonholonomic Jacobi problem with
    U = 0 or k/2 x²: energy and K (eqs. 2804-2, 2804-4), with the linear potential the energy only;
    Chaplygin's ball with the Veselova constraint: energy and (γ, E); Neumann and Clebsch: energy and
    the area (s, L); Veselova, the rubber ball and eq. (2504-12) on e(3): the energy.

    A kind without a plan (a surface or a system written by the user) has none: ``()``.
    """
    plan = plan_of(system)
    if plan is None:
        return ()
    claimed = {claim.name for claim in system.integrals}
    return tuple(name for name in plan.fixable if name in claimed)


def describe_sampling(system: MechanicalSystem) -> str:
    """One line on how :func:`on_level` draws the states of ``system`` (for the catalog)."""
    plan = plan_of(system)
    if plan is None:
        return no_plan(system)
    return plan.words(fixable(system))


def no_plan(system: MechanicalSystem) -> str:
    """Why ``system`` samples no level: its kind has no plan (the extent of a user's surface or system's level
    sets is unknown)."""
    record = registered(system.kind)
    unknown = "the extent of its level sets is unknown"
    why = (f"the system is the user's own: {unknown}" if record is None or record.written_by_user else
           f"the surface is the user's own: {unknown}" if record.surface else
           f"the kind {system.kind} declares no sampling plan")
    return f"no states drawn on a level set ({why}): give the members' initial states or a sweep"


def _checked_plan(system: MechanicalSystem) -> Sampling:
    """The plan of a system :func:`_check_request` accepted (it refuses a kind without one)."""
    plan = plan_of(system)
    assert plan is not None
    return plan


def _check_request(system: MechanicalSystem, parameters: np.ndarray, level: Mapping[str, float],
                   count: int, seed: int) -> dict[str, float]:
    if isinstance(count, bool) or not isinstance(count, Integral) or count < 1:
        raise LevelError("count", f"must be a positive integer, got {count!r}")
    if isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0:
        raise LevelError("seed", f"must be a non-negative integer, got {seed!r}")
    if plan_of(system) is None:
        raise LevelError("level", f"{system.kind}: {no_plan(system)}")
    if np.shape(parameters) != (len(system.parameter_symbols),):
        raise ValueError(f"parameters: expected {len(system.parameter_symbols)} values in the order "
                         f"{[str(s) for s in system.parameter_symbols]}, got shape {np.shape(parameters)}")
    if not isinstance(level, Mapping):
        raise LevelError("level", "must map integral names to values")
    names = fixable(system)
    listed = ", ".join(names)
    integrals = {i.name: i for i in system.integrals}
    for name in level:
        if name not in names:
            if name in integrals:
                why = (f"{integrals[name].formula} is an integral of {system.kind} (potential {system.potential}) "
                       "that a level cannot fix")
            else:
                why = f"not an integral of {system.kind} (potential {system.potential})"
            raise LevelError(f"level.{name}", f"{why}; a level may fix: {listed}")
    values: dict[str, float] = {}
    for name, value in level.items():
        if isinstance(value, bool) or not isinstance(value, Real) or not np.isfinite(float(value)):
            raise LevelError(f"level.{name}", f"must be a finite number, got {value!r}")
        values[name] = float(value)
    if "energy" not in values:
        raise LevelError("level.energy", f"required: the energy sets the size of the velocities; a level may fix: "
                                         f"{listed}")
    if "gamma_E" in values and abs(values["gamma_E"]) > 1.0:
        raise LevelError("level.gamma_E", f"(gamma, E) of two unit vectors lies in [-1, 1], got {values['gamma_E']:g}")
    return values


def _solve_energy(ctx: _Context, draw: _Draw, h: float,
                  pick_first: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Solve ``H(base + t·direction) = h`` for t, row by row.

    Returns
    -------
    states : the candidates with the solved velocity (rows without a real root unchanged).
    solved : the valid rows with a real root.
    extremum : ``e₀ − e₁²/(4 e₂)``, the least (e₂ > 0) or greatest (e₂ < 0) energy on each line.
    curvature : e₂.
    """
    slot = ctx.slot(_checked_plan(ctx.system).velocity)
    states, base, u = draw.states, draw.base, draw.direction

    def energy(v: np.ndarray) -> np.ndarray:
        trial = states.copy()
        trial[:, slot] = v
        return ctx.integral(trial, "energy")

    # H is quadratic in the velocity at fixed position: e0 + e1 t + e2 t^2 from t = 0, ±1.
    e0, plus, minus = energy(base), energy(base + u), energy(base - u)
    e2 = (plus + minus) / 2 - e0
    e1 = (plus - minus) / 2
    c0 = e0 - h
    with np.errstate(all="ignore"):
        disc = e1 * e1 - 4 * e2 * c0
        q = -(e1 + np.where(e1 >= 0, 1.0, -1.0) * np.sqrt(disc)) / 2   # stable roots q/e2 and c0/q
        first, second = q / e2, np.where(q == 0, 0.0, c0 / q)
        t = np.where(pick_first, first, second)
        # one Newton step on the kernel's own energy
        residual = energy(base + t[:, None] * u) - h
        slope = e1 + 2 * e2 * t
        polished = t - residual / slope
        better = np.isfinite(polished) & (np.abs(energy(base + polished[:, None] * u) - h) < np.abs(residual))
        t = np.where(better, polished, t)
        extremum = e0 - e1 * e1 / (4 * e2)
    solved = draw.valid & (disc >= 0) & np.isfinite(t)
    out = states.copy()
    out[:, slot] = np.where(solved[:, None], base + t[:, None] * u, base)
    return out, solved, extremum, e2


def _verified(ctx: _Context, states: np.ndarray, values: Mapping[str, float]) -> np.ndarray:
    """Rows on every constraint (to TOLERANCE·max(1, scale)) and on the level (to TOLERANCE·max(|value|, scale))."""
    kernels = numeric(ctx.system)
    with np.errstate(all="ignore"):
        ok = np.all(np.isfinite(states), axis=1)
        if ctx.system.constraints:
            c = kernels.constraints(states, ctx.p)
            scale = np.maximum(1.0, np.abs(kernels.constraint_scales(states, ctx.p)))
            target = np.array([k.value for k in ctx.system.constraints])
            ok &= np.all(np.abs(c - target) <= TOLERANCE * scale, axis=1)
        integrals = kernels.integrals(states, ctx.p)
        scales = np.abs(kernels.integral_scales(states, ctx.p))
        for name, value in values.items():
            i = ctx.integral_index(name)
            ok &= np.abs(integrals[:, i] - value) <= TOLERANCE * np.maximum(abs(value), scales[:, i])
    return ok


def verified(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray,
             values: Mapping[str, float]) -> np.ndarray:
    """Which rows of ``states`` satisfy every constraint and give the integrals in ``values`` their values,
    to :data:`TOLERANCE` of their scale (the check every sampled state passes)."""
    return _verified(_Context(system, np.asarray(parameters, dtype=float), values), states, values)


def _unreachable(ctx: _Context, values: Mapping[str, float], tries: int, floors: dict[str, float],
                 energy_low: float, energy_high: float, unverified: int) -> LevelError:
    """The error for a level no tried candidate reached, with what the tried states needed."""
    asked = " and ".join(f"{k} = {v:g}" for k, v in values.items())
    head = f"no state with {asked} in {tries} tries"
    for name, floor in floors.items():
        if np.isfinite(floor) and values[name] < floor:
            return LevelError(f"level.{name}", f"{head}: every tried state has {name} >= {floor:.6g} "
                                               f"(needs {name} >= {floor:.6g})")
    field = "level.energy" if len(values) == 1 else "level"
    given = "" if len(values) == 1 else " with " + " and ".join(f"{k} = {v:g}" for k, v in values.items()
                                                                if k != "energy")
    h = values["energy"]
    below = not np.isfinite(energy_low) or h < energy_low
    above = not np.isfinite(energy_high) or h > energy_high
    if (np.isfinite(energy_low) or np.isfinite(energy_high)) and below and above:
        needs = " or ".join([f">= {energy_low:.6g}"] * bool(np.isfinite(energy_low))
                            + [f"<= {energy_high:.6g}"] * bool(np.isfinite(energy_high)))
        extreme = " and ".join(["least"] * bool(np.isfinite(energy_low))
                               + ["greatest"] * bool(np.isfinite(energy_high)))
        return LevelError(field, f"{head}: the tried states{given} need energy {needs} (the {extreme} energy over "
                                 "the tried positions and velocity directions)")
    if unverified:
        return LevelError("level", f"{head}: {unverified} candidates reached the level but failed the check of the "
                                   f"constraints and integrals to {TOLERANCE:g}")
    return LevelError(field, f"{head}: the level is too rarely reached from random positions and directions")


def on_level(system: MechanicalSystem, parameters: np.ndarray, level: Mapping[str, float], count: int,
             seed: int) -> np.ndarray:
    """``count`` states of ``system`` on the level set ``level`` of its integrals.

    Parameters
    ----------
    system : the system (kind and potential).
    parameters : the parameter vector, in the order of ``system.parameter_symbols``
        (:func:`nonholonomic.numerics.kernels.parameter_vector`).
    level : integral name → value, names from :func:`fixable` (the energy is required), e.g.
        ``{"energy": 1.0, "area": 0.3}`` for Chaplygin's ball (eq. 2604-2) or
        ``{"energy": 1.0, "K": 0.5}`` for the nonholonomic Jacobi problem (eqs. 2804-2, 2804-4).
    count : how many states.
    seed : seed of ``numpy.random.default_rng``.

    Returns
    -------
    numpy.ndarray
        Shape ``(count, system.dimension)``, columns in the order of ``system.state_symbols``; every
        row on every constraint (to 1e-12 of its scale) with the fixed integrals at the requested values
        (to 1e-12 of max(|value|, the integral's scale)). Drawn as described in the module docstring;
        the same arguments give the same array bit for bit, a smaller ``count`` a prefix of it.

    Raises
    ------
    LevelError
        ``count`` or ``seed`` not a positive/non-negative integer; a name the level cannot fix
        (``level.<name>``, listing the fixable ones); no energy; a level not reached within
        ``max(1000 count, BATCH)`` candidates (100 000 if none is accepted), with the bound the tried
        states needed (e.g. ``needs energy >= 0.41``).
    ValueError
        If ``parameters`` has the wrong length.
    """
    values = _check_request(system, parameters, level, count, seed)
    ctx = _Context(system, np.asarray(parameters, dtype=float), values)
    draw_batch = _drawer(_checked_plan(system))
    rng = np.random.default_rng(seed)
    budget = max(TRIES_PER_STATE * count, BATCH)
    accepted: list[np.ndarray] = []
    found = tries = unverified = 0
    floors = {name: np.inf for name in values}
    energy_low, energy_high = np.inf, -np.inf
    while found < count and tries < budget and not (found == 0 and tries >= EARLY_GIVE_UP):
        draw = draw_batch(ctx, rng, BATCH)
        pick_first = rng.random(BATCH) < 0.5
        tries += BATCH
        for name, floor in draw.floors.items():
            floors[name] = min(floors[name], float(np.min(floor[draw.valid], initial=np.inf)))
            draw.valid = draw.valid & (values[name] >= floor)
        states, solved, extremum, curvature = _solve_energy(ctx, draw, values["energy"], pick_first)
        ok = solved & _verified(ctx, states, values)
        unverified += int(np.count_nonzero(solved & ~ok))
        convex, concave = draw.valid & (curvature > 0), draw.valid & (curvature < 0)
        energy_low = min(energy_low, float(np.min(extremum[convex], initial=np.inf)))
        energy_high = max(energy_high, float(np.max(extremum[concave], initial=-np.inf)))
        accepted.append(states[ok])
        found += int(np.count_nonzero(ok))
    if found < count:
        raise _unreachable(ctx, values, tries, floors, energy_low, energy_high, unverified)
    return np.ascontiguousarray(np.concatenate(accepted)[:count])
