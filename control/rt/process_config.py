"""What the control subprocess is started with (``control/rt/process.py``), apart from the
process's own code: the client that starts it builds this without importing the loop, the
backends and the warm-up, which only the subprocess runs."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class ProcessConfig:
    """Everything the subprocess needs, picklable."""

    machine: str
    backend: str
    port: str | None
    seed: int
    lockstep: bool
    control_segment: str
    period_s: float
    spin_us: float
    realtime: bool
    heartbeat_timeout_s: float
    orphan_timeout_s: float
    sim_options: dict
    slots: int = 1  # ticks per sample (control/timing.py)
    slips: tuple[str, ...] = ()

    def to_json(self) -> str:
        return json.dumps(asdict(self))

    @classmethod
    def from_json(cls, text: str) -> ProcessConfig:
        return cls(**json.loads(text))
