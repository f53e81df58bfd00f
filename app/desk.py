"""What the app hands every tab when it builds it. The client comes later, when the controller
is up: the app hands it down with ``TabPage.client_ready``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from app.event_log import EventLog
from app.history import History
from hw.machine import Machine
from kinematics.unimate import Unimate2000B


@dataclass(frozen=True)
class Desk:
    """The machine and its kinematics, the backend's name, where runs are saved, the
    status history the sampler fills (200 Hz) and the session's event log."""

    machine: Machine
    model: Unimate2000B | None  # the closed-form kinematics; None for a machine without (the rig)
    backend: str  # sim or serial
    data_dir: Path
    history: History
    dt: float  # between a path's rows: the machine's sample time, or the thesis timing's
    events: EventLog = field(default_factory=EventLog)
