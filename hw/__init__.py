"""The hardware boundary: machine descriptions, the Backend interface and its implementations."""

from hw.backend import Backend, Clock, LinkCounters, RealClock, StepClock
from hw.factory import BACKENDS, make_backend
from hw.machine import Coefficients, Joint, Machine, MachineError, builtin_names, load_machine

__all__ = [
    "BACKENDS",
    "Backend",
    "Clock",
    "Coefficients",
    "Joint",
    "LinkCounters",
    "Machine",
    "MachineError",
    "RealClock",
    "StepClock",
    "builtin_names",
    "load_machine",
    "make_backend",
]
