"""The tangent flow of :mod:`nonholonomic.analysis.lyapunov` and its re-orthonormalisation.

heyoka derives the variational equations from the system's one symbolic definition:
``hy.var_ode_sys(taylor_system(system).state_equations, hy.var_args.vars, order=1)``, i.e. the
state x and the n×n matrix Φ = ∂x(t)/∂x(t₀) with dΦ/dt = (∂f/∂x) Φ, plus one quadrature variable s
with ds/dt = div f. The columns of Φ start from a fixed orthonormal frame and are re-orthonormalised
by a Householder QR factorisation Φ Q = Q' R at the QR times (Benettin, Galgani, Giorgilli and
Strelcyn 1980; Shimada and Nagashima 1979). Here: the compiled integrators (once per process, one
copy per thread), the initial frame, the QR times and one QR step.
"""

from __future__ import annotations

import copy
import math
import threading
from collections import OrderedDict
from collections.abc import Callable
from functools import lru_cache
from typing import TypeVar, cast

import heyoka as hy
import numpy as np
from scipy.linalg.lapack import dgeqrf, dorgqr

from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import IntegrationError
from nonholonomic.numerics.taylor import taylor_system

#: Seed of the fixed (reproducible) random orthonormal frame the tangent vectors start from.
FRAME_SEED = 1980


@lru_cache(maxsize=16)
def variational_equations(system: MechanicalSystem,
                          pars: tuple[int, ...] = ()) -> tuple[tuple[hy.expression, hy.expression], ...]:
    """The heyoka equations of the tangent flow of ``system``: x, then Φ, then s = ∫ div f dt.

    Φ is ``hy.var_ode_sys(state_equations, args, order=1)``'s matrix of ∂x_i/∂(x_j(t₀)) and, with ``pars``,
    ∂x_i/∂p_k for the runtime parameters ``pars`` (their sensitivities, for a branch's continuation in a
    parameter), stored row-major after the n state variables (entry ``n + i (n + len(pars)) + j``); the layout
    is checked against heyoka's names for the partials.

    Raises
    ------
    RuntimeError
        If heyoka's layout of the partials is not the documented row-major one.
    """
    ts = taylor_system(system)
    n = ts.n_state
    args = hy.var_args.vars if not pars else list(ts.variables[:n]) + [hy.par[k] for k in pars]
    vs = hy.var_ode_sys(ts.state_equations, args, order=1)
    eqs = list(vs.sys)
    check_partials(eqs, [str(v) for v in ts.variables[:n]], n + len(pars))
    divergence = hy.sum([hy.diff(rhs, var) for var, rhs in ts.state_equations])
    s = hy.make_vars("lyapunov_div_f")
    return tuple(eqs) + ((s, divergence),)


def check_partials(eqs: list[tuple[hy.expression, hy.expression]], names: list[str], width: int) -> None:
    """Check heyoka's row-major layout of first-order partials: entry ``n + i width + j`` is ∂x_i/∂(argument j)
    for the n state ``names`` and ``width`` arguments of ``hy.var_ode_sys``.

    Raises
    ------
    RuntimeError
        If an entry is not where the layout puts it.
    """
    n = len(names)
    for i in range(n):
        for j in range(width):
            lhs = str(eqs[n + i * width + j][0])
            if lhs != f"∂[({j}, 1)]{names[i]}":
                raise RuntimeError(f"unexpected heyoka variational layout: entry {n + i * width + j} is {lhs}")


@lru_cache(maxsize=16)
def variational_template(system: MechanicalSystem, tolerance: float, pars: tuple[int, ...] = ()) -> hy.taylor_adaptive:
    """Compile the tangent-flow integrator at ``tolerance`` (with the sensitivities to ``pars``), once per process.

    Compact mode: Chaplygin's ball in a linear field (43 variables) compiles in about a second;
    without it, in about two minutes, for a propagation only ~1.6× faster.
    """
    eqs = list(variational_equations(system, pars))
    return hy.taylor_adaptive(eqs, np.zeros(len(eqs)), tol=tolerance, compact_mode=True)


@lru_cache(maxsize=16)
def variational_batch_template(system: MechanicalSystem, tolerance: float, lanes: int) -> hy.taylor_adaptive_batch:
    """Compile the batch-mode tangent-flow integrator (``lanes`` members), once per process."""
    eqs = list(variational_equations(system))
    return hy.taylor_adaptive_batch(eqs, np.zeros((len(eqs), lanes)), tol=tolerance, compact_mode=True)


_per_thread = threading.local()
#: Copies one thread keeps, least recently used dropped first (as many as the templates' caches).
THREAD_COPIES = 16
T = TypeVar("T")


def thread_copy(key: tuple[object, ...], template: Callable[[], T]) -> T:
    """This thread's own copy of a compiled integrator (``template()`` deep-copied on first use; the last
    :data:`THREAD_COPIES` kept, least recently used dropped first). Shared by the tangent flows here and
    the chaos indicators' (:mod:`nonholonomic.analysis.chaos_map.indicators`)."""
    cache: OrderedDict[tuple[object, ...], object] = _per_thread.__dict__.setdefault("cache", OrderedDict())
    if key not in cache:
        cache[key] = copy.deepcopy(template())
        while len(cache) > THREAD_COPIES:
            cache.popitem(last=False)
    cache.move_to_end(key)
    return cast(T, cache[key])  # what template() gave under this key


def _integrator(system: MechanicalSystem, tolerance: float, lanes: int = 0,
                pars: tuple[int, ...] = ()) -> hy.taylor_adaptive:
    """This thread's own copy of the compiled integrator (``lanes`` 0: scalar, with the sensitivities to
    ``pars``)."""
    return thread_copy(("tangent", system, tolerance, lanes, pars),
                       lambda: variational_template(system, tolerance, pars) if lanes == 0
                       else variational_batch_template(system, tolerance, lanes))


def initial_frame(n: int) -> np.ndarray:
    """The orthonormal n×n frame the tangent vectors start from (fixed seed: reproducible, and
    generic, unlike the coordinate axes, which may lie in an invariant subspace)."""
    q, r = np.linalg.qr(np.random.default_rng(FRAME_SEED).standard_normal((n, n)))
    return q * np.sign(np.diag(r))


def _qr_times(t_final: float, interval: float, transient: float) -> tuple[np.ndarray, int]:
    """The QR times (transient phase, then the averaged phase) and where the averaged phase starts."""

    def segment(start: float, end: float) -> np.ndarray:
        span = end - start
        if span <= 0:
            return np.empty(0)
        k = max(int(math.ceil(span / interval * (1 - 1e-12))), 1)
        return np.append(start + np.arange(1, k) * interval, end)

    before, after = segment(0.0, transient), segment(transient, t_final)
    return np.concatenate([before, after]), len(before)


def _reorthonormalise(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """QR of the evolved frame: the new orthonormal frame and log|R_ii| (Householder: LAPACK's
    dgeqrf/dorgqr, called directly, a sixth of numpy.linalg.qr's overhead on a 6×6 matrix)."""
    qr, tau, _, info = dgeqrf(V)
    if info != 0:
        raise IntegrationError(f"QR factorisation failed (LAPACK info {info})")
    with np.errstate(divide="ignore"):
        logs = np.log(np.abs(np.diag(qr)))
    q, _, info = dorgqr(qr, tau)
    return q, logs
