"""Property tests (hypothesis): random admissible balls and states keep every integral and the
invariant measure."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from nonholonomic import get_system, simulate
from nonholonomic.evidence.measure import pointwise_divergence_residual

moment = st.floats(0.2, 5.0)
# Components are 0 or of size >= 1e-6: below that, products underflow (|M|² ~ 1e-340) and the
# pointwise residual |Σ ∂(ρf_i)/∂x_i| / Σ|∂(ρf_i)/∂x_i| compares round-off with round-off.
component = st.one_of(st.just(0.0), st.floats(1e-6, 1.0), st.floats(-1.0, -1e-6))
vector = st.tuples(component, component, component)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(inertia=st.tuples(moment, moment, moment), D=st.one_of(st.just(0.0), st.floats(1e-6, 3.0)), M=vector,
       g=vector.filter(lambda v: np.linalg.norm(v) > 0.1), a=vector, potential=st.sampled_from(["zero", "linear"]))
def test_integrals_and_measure_hold_for_random_balls(inertia, D, M, g, a, potential):
    gamma = np.asarray(g) / np.linalg.norm(g)
    params = {"inertia": inertia, "D": D, **({"a": a} if potential == "linear" else {})}
    system = get_system("chaplygin_ball", potential)
    result = simulate(system, params, {"M": M, "gamma": gamma}, 100.0, 101, checks=["integrals"])
    for item in result.integrals:
        assert item.max_rel_drift <= 1e-12, (item.name, item.max_rel_drift)
    assert pointwise_divergence_residual(system, result.parameters, result.trajectory.states) <= 1e-12
