"""Encoder input: words from the backend to joint positions, through the glitch filter.

Section 6.2: the multiplexed encoders sometimes read a wrong word. Each word
becomes its actuator's coordinate through the transmission, and each actuator's
reading is judged there, where a wrong word shows alone: a jump further than
the actuator can move since its last good reading is rejected and counted, and
after ``resync`` rejections in a row the reading is believed (the actuator
really is there). The believed actuator coordinates then become joint
positions (the Yaw reading includes Bend), so a wrong Bend word leaves Yaw's
position as right as Bend's.
"""

from __future__ import annotations

from hw.backend import Backend
from hw.machine import Machine
from hw.transmission import Transmission


class EncoderInput:
    """Inputs: the backend's words and sample time. Outputs: ``position`` (joint units),
    ``raw`` words and ``glitches`` per joint. ``homed`` is False until a quadrature
    encoder is zeroed."""

    def __init__(self, machine: Machine, transmission: Transmission, margin: float,
                 resync: int) -> None:
        n = self.n = machine.n_joints
        self.transmission = transmission
        self.resync_after = resync
        self.raw = [0] * n
        self.offset = [0] * n  # quadrature counts at the zero (set by the rig's initialise)
        self.reading = [0.0] * n  # this tick's actuator readings, unfiltered
        self.actuator = [0.0] * n  # believed actuator coordinates
        self.position = [0.0] * n  # believed joint positions
        self.glitches = [0] * n
        self.rejects = [resync] * n  # believe the first reading
        self.last_ok_ns = [0] * n
        self.speed_per_ns = [j.max_speed * 1e-9 * margin for j in machine.joints]
        self.step_floor = [3 * abs(j.encoder.gradient) for j in machine.joints]  # 3 counts
        self.homed = machine.encoder_kind == "gray"

    def read(self, backend: Backend) -> None:
        raw, reading, actuator = self.raw, self.reading, self.actuator
        backend.read(raw)
        now = backend.sample_ns  # a late serial reply re-reads old words: time them so
        self.transmission.actuators_from_words(raw, self.offset, reading)
        rejects, last_ok, resync = self.rejects, self.last_ok_ns, self.resync_after
        speed, floor = self.speed_per_ns, self.step_floor
        for j in range(self.n):
            a = reading[j]
            if (abs(a - actuator[j]) <= speed[j] * (now - last_ok[j]) + floor[j]
                    or rejects[j] >= resync):
                actuator[j] = a
                last_ok[j] = now
                rejects[j] = 0
            else:
                rejects[j] += 1
                self.glitches[j] += 1
        self.transmission.joints_from_actuators(actuator, self.position)

    def resync(self, backend: Backend) -> None:
        """Believe the next reading outright: the joints may have moved while nobody watched."""
        self.rejects = [self.resync_after] * self.n
        self.read(backend)

    def zero(self) -> None:
        """Rig, section 3.5: where the actuators rest now becomes the encoders' zero."""
        transmission = self.transmission
        for j in range(self.n):
            self.offset[j] += round(transmission.count_of(j, self.actuator[j]))
        transmission.actuators_from_words(self.raw, self.offset, self.actuator)
        transmission.joints_from_actuators(self.actuator, self.position)
        self.homed = True
