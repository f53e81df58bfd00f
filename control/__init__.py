"""The real-time side: the control subprocess, its shared memory, channel and client."""

from control.client import ControlClient, ControllerError, Event, MoveHandle, MoveResult
from control.layout import Flag, LatencyHistogram, Mode, Status

__all__ = [
    "ControlClient",
    "ControllerError",
    "Event",
    "Flag",
    "LatencyHistogram",
    "Mode",
    "MoveHandle",
    "MoveResult",
    "Status",
]
