"""Poincaré sections, the events: compiled integrators with the event ``S − value`` and the crossings they record.

heyoka's non-terminal events (``nt_event``, ``nt_event_batch``) on the event function
``S(x) − value`` find each crossing as a root of the event function's Taylor polynomial inside a
step; the callbacks (:class:`_Crossings`, :class:`_BatchCrossings`) evaluate the dense output
(``update_d_output``) at the event time, as heyoka's own Poincaré-section tutorial does.
``value`` is a runtime parameter (the slot after the system's parameters), so one compiled
integrator serves every level; it is compiled once per (system, surface, direction, tolerance)
and process (:func:`_template`), and copied once per thread (:func:`_integrator`).
Part of :mod:`.poincare` (the front door), where every name is importable.
"""

from __future__ import annotations

import copy
import threading
from collections import OrderedDict
from collections.abc import Sequence
from functools import lru_cache

import heyoka as hy
import numpy as np
import sympy as sp

from nonholonomic.analysis.poincare.surface import _heyoka_ready, _Prepared
from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.taylor import taylor_system

_HEYOKA_DIRECTION = {
    "increasing": hy.event_direction.positive,
    "decreasing": hy.event_direction.negative,
    "both": hy.event_direction.any,
}


class _Crossings:
    """nt_event callback of the scalar integrator: the time and the dense-output state at each crossing,
    up to ``capacity`` of them (``seen`` counts every one). The states are logged as raw bytes and the
    times in a list (cheaper per crossing than writing rows of arrays); :meth:`arrays` returns both."""

    def __init__(self) -> None:
        self.reset(0, 0)

    def reset(self, n_vars: int, capacity: int) -> None:
        self.n_vars, self.capacity = n_vars, capacity
        self.count, self.seen = 0, 0
        self.t: list[float] = []
        self.log = bytearray()

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The recorded times, shape ``(count,)``, and states, shape ``(count, n_vars)`` (copies), in time order."""
        t, x = np.array(self.t, dtype=float), np.frombuffer(bytes(self.log)).reshape(-1, self.n_vars)
        if any(b < a for a, b in zip(self.t, self.t[1:])):  # heyoka reports a step's crossings in time order
            order = np.argsort(t, kind="stable")
            t, x = t[order], x[order]
        return t, x

    def record(self, t: float, state: np.ndarray) -> None:
        """Keep one crossing (below ``capacity``)."""
        self.seen += 1
        if self.count < self.capacity:
            self.log += state.data  # the raw bytes (a C-contiguous array)
            self.t.append(t)
            self.count += 1

    def __call__(self, ta: hy.taylor_adaptive, t: float, d_sgn: int) -> None:
        self.record(t, ta.update_d_output(t))  # the dense output at t (a view of the integrator's buffer)


class _BatchCrossings:
    """nt_event_batch callback: one :class:`_Crossings` per lane (capacity 0 for padding lanes)."""

    def __init__(self, batch: int) -> None:
        self.lanes = [_Crossings() for _ in range(batch)]

    def reset(self, n_vars: int, capacities: Sequence[int]) -> None:
        for lane, capacity in zip(self.lanes, capacities):
            lane.reset(n_vars, capacity)

    def __call__(self, ta: hy.taylor_adaptive_batch, t: float, d_sgn: int, idx: int) -> None:
        lane = self.lanes[idx]
        if lane.count >= lane.capacity:
            lane.seen += 1
            return
        times = np.array(ta.time)  # a copy: the other lanes' times stay untouched
        times[idx] = t
        lane.record(t, np.ascontiguousarray(ta.update_d_output(times)[:, idx]))


@lru_cache(maxsize=16)
def _template(system: MechanicalSystem, expr: sp.Expr, direction: str, tolerance: float,
              batch: int) -> hy.taylor_adaptive | hy.taylor_adaptive_batch:
    """Compile the integrator of ``system`` with the event ``S − par[n_pars]`` (``batch = 0``: scalar)."""
    ts = taylor_system(system)
    event = ts.expression(_heyoka_ready(expr)) - hy.par[ts.n_pars]
    n_vars = len(ts.variables)
    if batch == 0:
        return hy.taylor_adaptive(ts.equations, [0.0] * n_vars, pars=[0.0] * (ts.n_pars + 1), tol=tolerance,
                                  nt_events=[hy.nt_event(event, _Crossings(), direction=_HEYOKA_DIRECTION[direction])])
    return hy.taylor_adaptive_batch(
        ts.equations, np.zeros((n_vars, batch)), pars=np.zeros((ts.n_pars + 1, batch)), tol=tolerance,
        nt_events=[hy.nt_event_batch(event, _BatchCrossings(batch), direction=_HEYOKA_DIRECTION[direction])])


_per_thread = threading.local()
_PER_THREAD_CAPACITY = 8


def _integrator(prep: _Prepared, direction: str, tolerance: float, batch: int = 0
                ) -> tuple[hy.taylor_adaptive | hy.taylor_adaptive_batch, _Crossings | _BatchCrossings]:
    """This thread's copy of the compiled integrator and its event callback (a small LRU per thread)."""
    cache: OrderedDict = _per_thread.__dict__.setdefault("cache", OrderedDict())
    key = (id(prep), direction, tolerance, batch)
    entry = cache.get(key)
    if entry is not None and entry[0] is prep:
        cache.move_to_end(key)
    else:
        ta = copy.deepcopy(_template(prep.system, prep.expr, direction, tolerance, batch))
        entry = cache[key] = (prep, ta, ta.nt_events[0].callback)
        while len(cache) > _PER_THREAD_CAPACITY:
            cache.popitem(last=False)
    return entry[1], entry[2]
