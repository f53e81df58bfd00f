"""The real-time side: the control subprocess, its shared memory, channel and client.

The client is loaded on first use, so the control process (``python -m
control.rt.process``) never imports it.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from control.client import ControlClient, ControllerError, Event, MoveHandle, MoveResult
    from control.rt.layout import Flag, LatencyHistogram, Mode, Status

_EXPORTS = {
    "ControlClient": "control.client",
    "ControllerError": "control.client",
    "Event": "control.client",
    "MoveHandle": "control.client",
    "MoveResult": "control.client",
    "Flag": "control.rt.layout",
    "LatencyHistogram": "control.rt.layout",
    "Mode": "control.rt.layout",
    "Status": "control.rt.layout",
}

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


def __getattr__(name: str) -> object:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'control' has no attribute {name!r}")
    return getattr(import_module(_EXPORTS[name]), name)
