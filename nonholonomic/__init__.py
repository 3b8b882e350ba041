"""nonholonomic: the science of the service, pure computation.

Borisov & Mamaev, "Hamiltonization of nonholonomic systems". Each system is defined once,
symbolically (:mod:`nonholonomic.systems`); numeric kernels (:mod:`nonholonomic.kernels`), the
integrator (:mod:`nonholonomic.integration`) and the evidence (:mod:`nonholonomic.evidence`) are
derived from that definition. No web, queue or file I/O here.
"""

from nonholonomic.simulation import CHECKS, SimulationResult, simulate
from nonholonomic.systems import SYSTEMS, get_system

__all__ = ["CHECKS", "SYSTEMS", "SimulationResult", "get_system", "simulate"]
__version__ = "0.1.0"
