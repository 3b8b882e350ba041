"""The evidence of a reduced time τ = ∫ N dt integrated by quadrature (a reducing multiplier that is not known
to be analytic and positive, :mod:`nonholonomic.numerics.reduced_time`): the check of τ against an independent
quadrature, and the domain of the Hamiltonization (Theorem 1's time change is one only where N ≠ 0).
"""

from __future__ import annotations

from typing import Any

from nonholonomic.definition import MechanicalSystem
from nonholonomic.evidence.measure import CheckEvidence
from nonholonomic.numerics.integration import Trajectory
from nonholonomic.numerics.reduced_time import CHECK_TOLERANCE, ReducedTimeReport

__all__ = ["domain_json", "domain_warnings", "time_change_evidence"]


def _times(times: list[float], count: int) -> str:
    shown = ", ".join(f"{t:.10g}" for t in times[:8])
    return shown + (f" ... ({count} in all)" if count > 8 else "")


def domain_warnings(system: MechanicalSystem, report: ReducedTimeReport) -> list[str]:
    """What the result must say about where the time change dτ = N dt holds."""
    assert system.reduced_time is not None
    N = f"N = {system.reduced_time.density}"
    out = []
    if report.zero_count:
        out.append(f"{N} vanishes at t = {_times(report.zeros, report.zero_count)} without changing sign: the time "
                   "change d tau = N dt and the Hamiltonian form are singular there (tau stops); tau is integrated "
                   "across each zero, and each interval between them is a Hamiltonization of its own")
    if report.sign_change_count:
        out.append(f"{N} changes sign at t = {_times(report.sign_changes, report.sign_change_count)}: tau runs "
                   "backwards where N < 0, and the time change is a Hamiltonization only on each interval where "
                   "N != 0 (where the reduction's solution for the cyclic velocities is singular)")
    if report.not_real_from is not None:
        out.append(f"{N} is not real from t = {report.not_real_from:.10g} on: tau is not defined after it (null)")
    if report.unconverged:
        out.append(f"the quadrature of tau left {report.unconverged} piece(s) past its tolerance after the "
                   "bisections allowed; see the reduced_time check")
    return out


def domain_json(report: ReducedTimeReport | None) -> dict[str, Any] | None:
    """The ``time.tau_domain`` block of a result: where N vanishes, changes sign or is not real."""
    if report is None:
        return None
    return {"method": report.method, "zeros": report.zeros, "zero_count": report.zero_count,
            "sign_changes": report.sign_changes, "sign_change_count": report.sign_change_count,
            "not_real_from": report.not_real_from, "nonzero_until": report.positive_until()}


def time_change_evidence(system: MechanicalSystem, trajectory: Trajectory) -> tuple[list[CheckEvidence], list[str]]:
    """The ``reduced_time`` check and the domain's warnings when τ was integrated by quadrature, else nothing."""
    report, check = trajectory.reduced_time, trajectory.reduced_time_check
    if report is None or check is None or system.reduced_time is None:
        return [], []
    residual, tolerance, passed = check
    evidence = CheckEvidence(
        name="reduced_time", quantity="tau(t) = integral of N dt at every sample",
        formula=system.reduced_time.formula, equation=system.reduced_time.equation,
        method=(f"{report.method}; checked against Romberg's method (2^k + 1 equally spaced points per piece "
                "between the samples, segment ends and the kinks and zeros located) on the same dense output"),
        residual=residual, tolerance=tolerance, passed=passed,
        detail=(f"max |tau - tau_Romberg| = {residual:.3g} (tolerance {CHECK_TOLERANCE:g} (1 + max |tau|)); "
                f"{report.pieces} Gauss-Legendre pieces ({report.at_rounding} at N's rounding, "
                f"{report.unconverged} past the tolerance), their error estimate {report.error_estimate:.3g}; "
                f"Romberg's own {report.check_error_estimate:.3g}; N vanishes {report.zero_count} times, changes "
                f"sign {report.sign_change_count} times"))
    return [evidence], domain_warnings(system, report)
