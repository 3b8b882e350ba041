"""Lyapunov spectra from heyoka's variational equations, with the structure that constrains them.

The tangent flow is integrated exactly as heyoka derives it from the system's one symbolic
definition: ``hy.var_ode_sys(taylor_system(system).state_equations, hy.var_args.vars, order=1)``
(τ is not needed), i.e. the state x and the n×n matrix Φ = ∂x(t)/∂x(t₀) with dΦ/dt = (∂f/∂x) Φ,
plus one quadrature variable s with ds/dt = div f. Every ``interval`` the columns of Φ (which start
from an orthonormal frame Q) are re-orthonormalised by a QR factorisation Φ Q = Q' R and
log|R_ii| is accumulated (the standard method of Benettin, Galgani, Giorgilli and Strelcyn 1980;
Shimada and Nagashima 1979): ``λ_i = Σ log|R_ii| / (t_final − transient)``. No two-trajectory
differences are taken.

Structure reported beside the exponents:

* **The sum.** Liouville: d/dt ln det Φ = div f, so Σ_i λ_i(T) = (1/T) ∫ div f dt exactly, for
  every T. A claimed invariant measure ρ d(state) (``div(ρ f) = 0``; Chaplygin's ball eq. 2604-3,
  the ball on a quadric eq. 2804-3) gives div f = −d/dt ln ρ along an orbit, so
  Σ_i λ_i(T) = −[ln ρ]_{t₀}^{T} / T → 0 on a bounded orbit where ρ stays positive and finite.
  Three numbers are reported: the sum of the exponents (from R), the quadrature (1/T)∫div f dt
  (``divergence_average``, independent of R and of the claim) and the claim's prediction
  −[ln ρ]/T (``measure_average``). A measure that is not invariant shows as a mismatch (warning).
* **Exponents that must vanish.** The variational equations live in the ambient coordinates (6
  for the ball: M, γ), where the constraints (|γ| = 1, Φ(x) = 0 ...) are first integrals too.
  One exponent vanishes for the time direction (f(x(t)) = Φ f(x(t₀)) stays bounded and away from 0
  on a bounded orbit off equilibria) and one for each functionally independent first integral I
  (the covector dI is carried unchanged by the adjoint flow). Dependent ones (|γ| = 1 beside
  (γ, γ)) are listed but not counted. If the measure holds and only one exponent is left, it
  vanishes too (the sum is 0): the ball with U = 0 has time + H + (γ, γ) + c + F = 5, hence all 6.

Layout: this module is the front door (:func:`spectrum`, :func:`largest_batch`: the QR loop, scalar
and batch, with its inputs' validation); every name below is importable from here.

* :mod:`.variational`: the tangent flow heyoka derives, its compiled integrators, the
  initial frame, the QR times and one QR step;
* :mod:`.zeros`: the exponents that must vanish and why (:class:`ExpectedZero`,
  :func:`expected_zeros`, :func:`reversing_involution`);
* :mod:`.result`: the :class:`Spectrum`, its running estimates (convergence) and the
  checks of its sum.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import heyoka as hy
import numpy as np

from nonholonomic.analysis.lyapunov.result import (
    CONVERGENCE_WARNING,
    MAX_CONVERGENCE_ROWS,
    MEASURE_TOLERANCE,
    QUADRATURE_TOLERANCE,
    Spectrum,
    _Accumulator,
    _finish,
)
from nonholonomic.analysis.lyapunov.variational import (
    FRAME_SEED,
    _integrator,
    _qr_times,
    _reorthonormalise,
    initial_frame,
    variational_batch_template,
    variational_equations,
    variational_template,
)
from nonholonomic.analysis.lyapunov.zeros import (
    LIE_TOLERANCE,
    RANK_TOLERANCE,
    ExpectedZero,
    expected_zeros,
    reversing_involution,
)
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import (
    MACHINE_EPSILON,
    IntegrationCancelled,
    IntegrationError,
    ProgressCallback,
)
from nonholonomic.numerics.integration_batch import lane_sources
from nonholonomic.numerics.taylor import taylor_system

__all__ = [
    "CONVERGENCE_WARNING",
    "FRAME_SEED",
    "LIE_TOLERANCE",
    "MAX_CONVERGENCE_ROWS",
    "MAX_QR_STEPS",
    "MEASURE_TOLERANCE",
    "PIECE_STEPS",
    "QUADRATURE_TOLERANCE",
    "RANK_TOLERANCE",
    "ExpectedZero",
    "Spectrum",
    "expected_zeros",
    "initial_frame",
    "largest_batch",
    "reversing_involution",
    "spectrum",
    "variational_batch_template",
    "variational_equations",
    "variational_template",
]

#: A run may not need more re-orthonormalisations than this (``interval`` too small for ``t_final``).
MAX_QR_STEPS = 5_000_000
#: A QR interval is integrated in pieces of at most this many steps, with a progress report between
#: them: a cancellation or a time limit acts within one piece, however long the interval.
PIECE_STEPS = 2_000


# --- one run ---------------------------------------------------------------------------------------


def _validate(system: MechanicalSystem, t_final: float, count: int | None, interval: float, transient: float,
              tolerance: float | None) -> tuple[int, float]:
    n = system.dimension
    if not (math.isfinite(t_final) and t_final > 0):
        raise ValueError(f"t_final: must be a finite number > 0, got {t_final}")
    if not (math.isfinite(interval) and interval > 0):
        raise ValueError(f"interval: must be a finite number > 0, got {interval}")
    if not (math.isfinite(transient) and 0 <= transient < t_final):
        raise ValueError(f"transient: must satisfy 0 <= transient < t_final = {t_final:g}, got {transient}")
    if t_final / interval > MAX_QR_STEPS:
        raise ValueError(f"interval: {interval:g} needs more than {MAX_QR_STEPS} re-orthonormalisations up to "
                         f"t_final = {t_final:g}")
    c = n if count is None else count
    if isinstance(c, bool) or int(c) != c or not 1 <= c <= n:
        raise ValueError(f"count: must be an integer between 1 and the dimension {n}, got {count}")
    tol = MACHINE_EPSILON if tolerance is None else float(tolerance)
    if not (math.isfinite(tol) and 0 < tol < 1):
        raise ValueError(f"tolerance: must be a number in (0, 1), got {tolerance}")
    return int(c), tol


def _check_inputs(system: MechanicalSystem, parameters: np.ndarray, states: np.ndarray) -> None:
    n_user = len(system.parameter_symbols)
    if parameters.shape[-1] != n_user:
        raise ValueError(f"parameters: {system.kind} needs {n_user} parameters, got shape {parameters.shape}")
    if states.shape[-1] != system.dimension:
        raise ValueError(f"initial_state: {system.kind} needs {system.dimension} components, got shape {states.shape}")
    if not (np.all(np.isfinite(parameters)) and np.all(np.isfinite(states))):
        raise ValueError("parameters/initial_state: non-finite number")


def spectrum(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_state: np.ndarray,
    t_final: float,
    *,
    count: int | None = None,
    interval: float = 1.0,
    transient: float = 0.0,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> Spectrum:
    """The Lyapunov spectrum of the orbit through ``initial_state`` (QR method on heyoka's
    variational equations).

    Parameters
    ----------
    system : the symbolic definition.
    parameters : the system's parameters, in the order of ``system.parameter_symbols``.
    initial_state : x(0), in the order of ``system.state_symbols``.
    t_final : end of the run; the exponents average over ``[transient, t_final]``.
    count : how many exponents to report (the largest; default the whole spectrum,
        ``system.dimension``).
    interval : time between re-orthonormalisations (the last one may be shorter).
    transient : time integrated first (with re-orthonormalisation, so the frame aligns too) and
        left out of the averages.
    tolerance : heyoka's tolerance (default machine epsilon).
    progress : ``progress(t / t_final) -> keep_going`` after each re-orthonormalisation; False
        cancels (raises :class:`IntegrationCancelled`).

    Returns
    -------
    Spectrum

    Raises
    ------
    ValueError
        Naming the field (``t_final``, ``interval``, ``transient``, ``count``, ``tolerance``,
        ``parameters``, ``initial_state``).
    IntegrationError
        If heyoka stops early (non-finite state ...).
    IntegrationCancelled
    """
    count_, tol = _validate(system, float(t_final), count, float(interval), float(transient), tolerance)
    p = np.asarray(parameters, dtype=float)
    y0 = np.asarray(initial_state, dtype=float)
    _check_inputs(system, p, y0)
    if p.ndim != 1 or y0.ndim != 1:
        raise ValueError("parameters/initial_state: need one vector each")
    n = system.dimension
    ts = taylor_system(system)
    ta = _integrator(system, tol)  # compiled once per process, copied once per thread; not timed
    start = time.perf_counter()
    times, first = _qr_times(float(t_final), float(interval), float(transient))
    acc = _Accumulator(n, times, first, float(transient))
    if first == 0:
        acc.state_start = y0.copy()
    Q = initial_frame(n)
    ta.time = 0.0
    ta.pars[:] = ts.runtime_parameters(p)[: len(ta.pars)]
    state = ta.state
    state[:n] = y0
    steps = 0
    for k, t in enumerate(times):
        state[n: n + n * n] = Q.reshape(-1)
        state[-1] = 0.0
        outcome, nsteps = _propagate(ta, float(t), float(t_final), progress)
        steps += nsteps
        if outcome != hy.taylor_outcome.time_limit:
            raise IntegrationError(f"heyoka stopped at t = {ta.time:g} with outcome {outcome.name}")
        Q, logs = _reorthonormalise(state[n: n + n * n].reshape(n, n))
        if not np.all(np.isfinite(logs)):
            raise IntegrationError(f"degenerate tangent frame at t = {t:g} (log|R_ii| = {logs.tolist()})")
        acc.add(k, logs, float(state[-1]))
        if k + 1 == first:
            acc.state_start = state[:n].copy()
        if progress is not None and not progress(min(float(t) / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {t:g}")
    return _finish(system, p, acc, state[:n].copy(), count_, float(interval), float(transient), float(t_final),
                   tol, steps, time.perf_counter() - start)


def largest_batch(
    system: MechanicalSystem,
    parameters: np.ndarray,
    initial_states: np.ndarray,
    t_final: float,
    *,
    interval: float = 1.0,
    transient: float = 0.0,
    tolerance: float | None = None,
    progress: ProgressCallback | None = None,
) -> list[Spectrum | IntegrationError]:
    """The largest exponent of each member (``count = 1``) with heyoka's batch mode.

    ``hy.recommended_simd_size()`` members share one batch integrator of the same variational
    equations as :func:`spectrum` (the last batch padded with copies of its last member); each
    member's :class:`Spectrum` is the one :func:`spectrum` gives it with ``count = 1``, equal up to
    rounding in the last bits (heyoka's vectorised code may round differently; on a chaotic orbit
    that difference grows like the trajectories' own), except ``wall_time_s``: the batch's wall time
    divided among its members. A member whose lane fails fails alone: its entry is the
    :class:`IntegrationError` that integrating it alone gives; the batch is then run again without it.

    Parameters
    ----------
    parameters : shape ``(n_members, n_parameters)``.
    initial_states : shape ``(n_members, dimension)``.
    t_final, interval, transient, tolerance : as for :func:`spectrum`.
    progress : ``progress(fraction of the members' work done) -> keep_going``; False cancels.

    Returns
    -------
    list
        One :class:`Spectrum` or :class:`IntegrationError` per member, in order.

    Raises
    ------
    ValueError, IntegrationCancelled
    """
    _, tol = _validate(system, float(t_final), 1, float(interval), float(transient), tolerance)
    P = np.asarray(parameters, dtype=float)
    Y0 = np.asarray(initial_states, dtype=float)
    if P.ndim != 2 or Y0.ndim != 2 or len(P) != len(Y0):
        raise ValueError(f"parameters/initial_states: need shapes (n_members, n_parameters) and (n_members, "
                         f"dimension) with the same n_members, got {P.shape} and {Y0.shape}")
    _check_inputs(system, P, Y0)
    lanes = hy.recommended_simd_size()
    results: list[Spectrum | IntegrationError] = []
    for first in range(0, len(P), lanes):
        members = list(range(first, min(first + lanes, len(P))))

        def lane_progress(fraction: float, first: int = first, count: int = len(members)) -> bool:
            return True if progress is None else bool(progress((first + count * fraction) / len(P)))

        results.extend(_batch(system, P[members], Y0[members], float(t_final), float(interval), float(transient),
                              tol, lanes, lane_progress))
    return results


def _batch(system: MechanicalSystem, P: np.ndarray, Y0: np.ndarray, t_final: float, interval: float,
           transient: float, tol: float, lanes: int, progress: ProgressCallback) -> list[Spectrum | IntegrationError]:
    """Up to ``lanes`` members in one batch; a failing member is integrated alone for its error and
    the batch is run again without it (lanes do not influence each other)."""
    failed: dict[int, IntegrationError] = {}
    while True:
        source = lane_sources(len(P), failed, lanes)
        if source is None:
            return [failed[i] for i in range(len(P))]
        start = time.perf_counter()
        outcome = _run_lanes(system, P[source], Y0[source], t_final, interval, transient, tol, progress)
        if isinstance(outcome, list):
            wall = (time.perf_counter() - start) / len(P)
            return [failed[i] if i in failed else _with_wall(outcome[i], wall) for i in range(len(P))]
        for lane in outcome:
            i = source[lane]
            try:
                spectrum(system, P[i], Y0[i], t_final, count=1, interval=interval, transient=transient, tolerance=tol)
                failed[i] = IntegrationError("batch lane failed; integrated alone it succeeded")
            except IntegrationError as exc:
                failed[i] = exc


def _with_wall(s: Spectrum, wall: float) -> Spectrum:
    return replace(s, wall_time_s=wall)


def _propagate(ta: hy.taylor_adaptive, t: float, t_final: float,
               progress: ProgressCallback | None) -> tuple[hy.taylor_outcome, int]:
    """``propagate_until(t)`` in pieces of at most :data:`PIECE_STEPS` steps (the same steps as one call),
    asking ``progress`` in between; returns the outcome and the steps taken."""
    steps = 0
    while True:
        outcome, _, _, nsteps, _, _ = ta.propagate_until(t, max_steps=PIECE_STEPS)
        steps += nsteps
        if outcome != hy.taylor_outcome.step_limit:
            return outcome, steps
        if progress is not None and not progress(min(ta.time / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {ta.time:g}")


def _run_lanes(system: MechanicalSystem, P: np.ndarray, Y0: np.ndarray, t_final: float, interval: float,
               transient: float, tol: float, progress: ProgressCallback) -> list[Spectrum] | set[int]:
    """One batch: every lane's spectrum, or the set of lanes that failed."""
    n, lanes = system.dimension, len(P)
    ts = taylor_system(system)
    ta = _integrator(system, tol, lanes)
    times, first = _qr_times(t_final, interval, transient)
    accs = [_Accumulator(n, times, first, transient) for _ in range(lanes)]
    frames = [initial_frame(n) for _ in range(lanes)]
    ta.set_time(0.0)
    ta.pars[:] = ts.runtime_parameters(P.T)[: ta.pars.shape[0]]
    state = ta.state
    state[:n] = Y0.T
    if first == 0:
        for j in range(lanes):
            accs[j].state_start = Y0[j].copy()
    steps = np.zeros(lanes, dtype=np.int64)
    bad: set[int] = set()
    for k, t in enumerate(times):
        for j in range(lanes):
            state[n: n + n * n, j] = frames[j].reshape(-1)
        state[-1] = 0.0
        going = True
        while going and not bad:  # in pieces of PIECE_STEPS steps, asking progress in between
            ta.propagate_until(float(t), max_steps=PIECE_STEPS)
            going = False
            for j, (outcome, _, _, nsteps) in enumerate(ta.propagate_res):
                steps[j] += nsteps
                if outcome == hy.taylor_outcome.step_limit:
                    going = True
                elif outcome != hy.taylor_outcome.time_limit:
                    bad.add(j)
            if going and not bad and not progress(min(float(np.min(ta.time)) / t_final, 1.0)):
                raise IntegrationCancelled(f"cancelled at t = {float(np.min(ta.time)):g}")
        if bad:
            return bad
        for j in range(lanes):
            frames[j], logs = _reorthonormalise(state[n: n + n * n, j].reshape(n, n))
            if not np.all(np.isfinite(logs)):
                bad.add(j)
            accs[j].add(k, logs, float(state[-1, j]))
            if k + 1 == first:
                accs[j].state_start = state[:n, j].copy()
        if bad:
            return bad
        if not progress(min(float(t) / t_final, 1.0)):
            raise IntegrationCancelled(f"cancelled at t = {t:g}")
    return [_finish(system, P[j], accs[j], state[:n, j].copy(), 1, interval, transient, t_final, tol,
                    int(steps[j]), 0.0) for j in range(lanes)]
