"""nonholonomic: the science of the service, pure computation.

Borisov & Mamaev, "Hamiltonization of nonholonomic systems". Each system is defined once,
symbolically (:mod:`nonholonomic.systems`); numeric kernels (:mod:`nonholonomic.numerics.kernels`), the
integrator (:mod:`nonholonomic.numerics.integration`) and the evidence (:mod:`nonholonomic.evidence`) are
derived from that definition. No web, queue or file I/O here.

The package's face is lazy: ``from nonholonomic import simulate`` imports :mod:`nonholonomic.simulation`
when the name is first asked for, so importing one module of the package (``nonholonomic.refusals``:
7 ms) does not import the others (sympy and heyoka among them) and nothing cycles through this file.
One module is imported at once: :mod:`nonholonomic.numerics.precision`, which makes mpmath's working precision
per thread before any thread of the process evaluates (mpmath, 34 ms).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

import nonholonomic.numerics.precision  # noqa: F401  # installs mpmath's per-thread precision first

if TYPE_CHECKING:
    from nonholonomic.simulation import CHECKS, SimulationResult, simulate
    from nonholonomic.systems import SYSTEMS, get_system

__all__ = ["CHECKS", "SYSTEMS", "SimulationResult", "get_system", "simulate"]
__version__ = "0.1.0"

#: Where each name of the face lives.
_HOMES = {"CHECKS": "nonholonomic.simulation", "SimulationResult": "nonholonomic.simulation",
          "simulate": "nonholonomic.simulation", "SYSTEMS": "nonholonomic.systems",
          "get_system": "nonholonomic.systems"}


def __getattr__(name: str) -> Any:
    """A name of the face, imported from its module the first time it is asked for (PEP 562)."""
    if name not in _HOMES:
        raise AttributeError(f"module 'nonholonomic' has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_HOMES])
