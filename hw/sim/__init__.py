"""The simulator backend: hydraulic plant, valves and encoders of both machines."""

from hw.sim.backend import SimBackend

__all__ = ["SimBackend"]
