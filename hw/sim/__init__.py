"""The simulator backend: hydraulic plant, valves and encoders of both machines."""

from hw.sim.backend import SimBackend, check_plant

__all__ = ["SimBackend", "check_plant"]
