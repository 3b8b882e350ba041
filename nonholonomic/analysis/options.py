"""What a job or an ensemble asks of the analysis: a Poincaré section, a Lyapunov spectrum.

Plain values (the schemas build them from a request); ``run`` calls the analysis module on one
orbit, ``run_batch`` on the members of an ensemble chunk.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, NotRequired, TypedDict

import numpy as np

from nonholonomic.definition import MechanicalSystem
from nonholonomic.numerics.integration import IntegrationError, ProgressCallback

if TYPE_CHECKING:
    from nonholonomic.analysis.lyapunov import Spectrum
    from nonholonomic.analysis.poincare import Section


class _SectionKeywords(TypedDict):
    """The keyword arguments :class:`SectionOptions` passes to :func:`~.poincare.section` (and the batch)."""

    value: float
    direction: str
    max_points: int
    coordinates: NotRequired[tuple[str, ...]]


@dataclass(frozen=True)
class SectionOptions:
    """A Poincaré section ``surface(x) = value`` crossed in ``direction`` (see :mod:`.poincare`)."""

    surface: str
    value: float = 0.0
    direction: str = "increasing"
    coordinates: tuple[str, str] | None = None
    max_points: int = 10_000

    def _keywords(self) -> _SectionKeywords:
        keywords: _SectionKeywords = {"value": self.value, "direction": self.direction,
                                      "max_points": self.max_points}
        if self.coordinates is not None:
            keywords["coordinates"] = tuple(self.coordinates)
        return keywords

    def run(self, system: MechanicalSystem, p: np.ndarray, y0: np.ndarray, t_final: float, *,
            tolerance: float | None = None, progress: ProgressCallback | None = None) -> Section:
        from nonholonomic.analysis.poincare import section

        return section(system, p, y0, t_final, self.surface, tolerance=tolerance, progress=progress,
                       **self._keywords())

    def run_batch(self, system: MechanicalSystem, P: np.ndarray, Y0: np.ndarray, t_final: float, *,
                  tolerance: float | None = None,
                  progress: ProgressCallback | None = None) -> list[Section | IntegrationError]:
        from nonholonomic.analysis.poincare import section_batch

        return section_batch(system, P, Y0, t_final, self.surface, tolerance=tolerance, progress=progress,
                             **self._keywords())


@dataclass(frozen=True)
class SpectrumOptions:
    """``count`` Lyapunov exponents (all by default), QR every ``interval``, averaging after ``transient``."""

    count: int | None = None
    interval: float = 1.0
    transient: float = 0.0

    def run(self, system: MechanicalSystem, p: np.ndarray, y0: np.ndarray, t_final: float, *,
            tolerance: float | None = None, progress: ProgressCallback | None = None) -> Spectrum:
        from nonholonomic.analysis.lyapunov import spectrum

        return spectrum(system, p, y0, t_final, count=self.count, interval=self.interval,
                        transient=self.transient, tolerance=tolerance, progress=progress)

    def run_batch(self, system: MechanicalSystem, P: np.ndarray, Y0: np.ndarray, t_final: float, *,
                  tolerance: float | None = None,
                  progress: ProgressCallback | None = None) -> list[Spectrum | IntegrationError]:
        """Every member's spectrum: the largest exponents in batch mode when ``count`` is 1, else one by one."""
        from nonholonomic.analysis.lyapunov import largest_batch, spectrum

        if self.count == 1:
            return largest_batch(system, P, Y0, t_final, interval=self.interval, transient=self.transient,
                                 tolerance=tolerance, progress=progress)
        out: list[Spectrum | IntegrationError] = []
        for i, (p, y0) in enumerate(zip(P, Y0)):
            member_progress = None if progress is None else (
                lambda f, i=i: progress((i + f) / len(P)))
            try:
                out.append(spectrum(system, p, y0, t_final, count=self.count, interval=self.interval,
                                    transient=self.transient, tolerance=tolerance, progress=member_progress))
            except IntegrationError as exc:
                out.append(exc)
        return out


@dataclass(frozen=True)
class PeriodicOrbitOptions:
    """A periodic orbit of the ``period``-th return map to ``surface = value``, seeded by the job's initial state
    (:mod:`.periodic_orbit`), its continuation through ``sweep_vectors`` (one parameter vector per value of
    ``sweep_parameter``, :mod:`nonholonomic.analysis.periodic_orbit.continuation`), and its branch by
    pseudo-arclength (``branch``, :mod:`nonholonomic.analysis.periodic_orbit.branch`)."""

    surface: str
    value: float = 0.0
    direction: str = "increasing"
    period: int = 1
    coordinates: tuple[str, str] | None = None
    level: tuple[str, ...] | None = None
    sweep_parameter: str | None = None
    sweep_values: tuple[float, ...] = ()
    sweep_vectors: tuple[np.ndarray, ...] = ()
    branch: Any = None  # BranchOptions (imported lazily with the solver)

    def run(self, system: MechanicalSystem, p: np.ndarray, y0: np.ndarray, t_final: float, *,
            tolerance: float | None = None, progress: ProgressCallback | None = None) -> tuple[Any, Any, Any]:
        """The orbit; with a sweep, its :class:`~nonholonomic.analysis.periodic_orbit.continuation.Branch`; with a
        branch, its :class:`~nonholonomic.analysis.periodic_orbit.branch.OrbitBranch` (None when not asked for,
        or when the orbit was not closed: there is nothing to continue)."""
        from nonholonomic.analysis.periodic_orbit import find_periodic_orbit
        from nonholonomic.analysis.periodic_orbit.branch import follow_branch
        from nonholonomic.analysis.periodic_orbit.continuation import continue_orbit
        from nonholonomic.numerics.integration import MACHINE_EPSILON

        parts = 1 + bool(self.sweep_values) + (self.branch is not None)

        def part(i: int) -> ProgressCallback | None:
            return None if progress is None else (lambda f: progress((i + f) / parts))

        orbit = find_periodic_orbit(system, p, y0, self.surface, value=self.value, direction=self.direction,
                                    period=self.period, level=self.level, coordinates=self.coordinates,
                                    t_final=t_final, tolerance=tolerance, progress=part(0))
        if self.branch is not None and orbit.status != "found":
            orbit = replace(orbit, warnings=orbit.warnings + (
                f"no branch: the orbit is {orbit.status}, a branch is followed from an isolated orbit found",))
        if not orbit.closed:
            return orbit, None, None
        tol = MACHINE_EPSILON if tolerance is None else tolerance
        sweep = branch = None
        if self.sweep_values:
            sweep = continue_orbit(system, orbit, self.sweep_parameter or "", self.sweep_values, self.sweep_vectors,
                                   tolerance=tol, progress=part(1))
        if self.branch is not None and orbit.status == "found":
            branch = follow_branch(system, p, orbit, self.branch, tolerance=tol, progress=part(parts - 1))
        return orbit, sweep, branch
