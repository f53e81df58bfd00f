"""The transmission of one machine: every map between actuators and joints, in one object.

ros2_control keeps actuator↔joint maps in a ``transmission_interface``; this is
ours, built from the machine file, and everyone who needs coupling, polarity or
scaling asks it (the control loop, the simulator's plant and encoders,
identification, excitation and tuning).

Positions. An encoder measures its actuator: a word decodes to a count (Gray
code, section 5.3; quadrature counts less the zero found by the rig's
initialise), and the calibration of rtshare.h turns it into the actuator's
coordinate, ``a = gradient·count + constant`` (joint units, mm or degrees). A
joint coupled to another (rtshare.h ``joint_dep``: the Yaw chain drive runs
through Bend) reads ``q = a + coupling·q[coupled_to]``; velocities map the same
way. End stops act on actuators, at the joint's limits.

Duty. The controller's output ``u`` (%) is in each joint's positive sense. The
valve gets ``polarity·u``, with negative output scaled down first (the rig's
area ratio, section 3.6, errata #11). The minimum PWM measured per valve side
(section 5.4.1) belongs to the output side that opens it (errata #27).

Per-tick maps fill caller-owned lists and touch plain floats only; the batch
maps take numpy arrays ``(..., J)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from hw.gray import gray_table, gray_to_binary
from hw.machine import Joint, Machine, MachineError

GRAY_TABLE_BITS = 16  # Gray encoders up to this wide decode by table lookup (64 k entries)


class Transmission:
    """Encoder decode and calibration, joint coupling, valve polarity and down-scaling."""

    def __init__(self, machine: Machine) -> None:
        joints = machine.joints
        self.n = n = machine.n_joints
        self.gray = machine.encoder_kind == "gray"
        self.gray_decode = (gray_table(machine.encoder_bits)  # wider: decoded word by word
                            if self.gray and machine.encoder_bits <= GRAY_TABLE_BITS else [])
        self.gradient = [j.encoder.gradient for j in joints]
        self.constant = [j.encoder.constant for j in joints]
        self.coupled_to = [-1 if j.encoder.coupled_to is None or j.encoder.coupling == 0.0
                           else j.encoder.coupled_to for j in joints]
        self.coupling = [j.encoder.coupling if c >= 0 else 0.0
                         for j, c in zip(joints, self.coupled_to, strict=True)]
        self.polarity = [float(j.polarity) for j in joints]
        self.down_scale = [j.down_scale for j in joints]
        self.order = _coupling_order(machine, self.coupled_to)
        self.coupled = [(j, self.coupled_to[j], self.coupling[j]) for j in self.order
                        if self.coupled_to[j] >= 0]
        self._matrix = np.eye(n)  # q = M a: each coupled row adds its partner's row
        for j, k, c in self.coupled:
            self._matrix[j] += c * self._matrix[k]
        self._inverse = np.eye(n)  # a = q - c q[k]
        for j, k, c in self.coupled:
            self._inverse[j, k] -= c

    # -- encoders: words to actuator coordinates, and back -----------------------------------

    def actuators_from_words(self, raw: Sequence[int], offset: Sequence[int],
                             out: list[float]) -> None:
        """Actuator coordinates (joint units) of encoder words ``raw``; ``offset`` is each
        quadrature encoder's count at its zero (section 3.5)."""
        gradient, constant = self.gradient, self.constant
        if self.gray:
            table = self.gray_decode
            size = len(table)
            for j in range(self.n):
                word = raw[j]  # a word wider than the encoder's decodes too; the filter judges it
                count = table[word] if 0 <= word < size else gray_to_binary(word)
                out[j] = gradient[j] * count + constant[j]
        else:
            for j in range(self.n):
                out[j] = gradient[j] * (raw[j] - offset[j]) + constant[j]

    def count_of(self, j: int, actuator: float) -> float:
        """The (fractional) encoder count at actuator coordinate ``actuator`` of joint ``j``."""
        return (actuator - self.constant[j]) / self.gradient[j]

    # -- positions and velocities: actuators to joints, and back -----------------------------

    def joints_from_actuators(self, actuator: Sequence[float], out: list[float]) -> None:
        """Joint readings of actuator coordinates: ``q = a + coupling·q[coupled_to]``; works for
        positions and velocities alike."""
        for j in range(self.n):
            out[j] = actuator[j]
        for j, k, c in self.coupled:
            out[j] += c * out[k]

    def actuators_from_joints(self, joint: Sequence[float], out: list[float]) -> None:
        """Actuator coordinates of joint readings (positions or velocities): the inverse map."""
        for j in range(self.n):
            out[j] = joint[j]
        for j, k, c in self.coupled:
            out[j] -= c * joint[k]

    def joints_of(self, actuator: np.ndarray) -> np.ndarray:
        """Batch ``joints_from_actuators``: ``(..., J)`` actuator coordinates to joint readings."""
        return np.asarray(actuator, dtype=float) @ self._matrix.T

    def actuators_of(self, joint: np.ndarray) -> np.ndarray:
        """Batch ``actuators_from_joints``: ``(..., J)`` joint readings to actuator coordinates."""
        return np.asarray(joint, dtype=float) @ self._inverse.T

    def reading_bounds(self, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interval map: the lowest and highest joint readings ``(..., J)`` when each actuator
        moves anywhere within ``low``…``high`` of its own (a coupled partner's included)."""
        m = self._matrix.T
        lo = np.asarray(low, dtype=float)
        hi = np.asarray(high, dtype=float)
        return lo @ np.maximum(m, 0) + hi @ np.minimum(m, 0), \
            hi @ np.maximum(m, 0) + lo @ np.minimum(m, 0)

    # -- duty: controller output to valve, and back ------------------------------------------

    def valve_duties(self, u: Sequence[float], out: list[float]) -> None:
        """Valve duty (%) of every joint for controller outputs ``u``, into ``out``:
        ``valve_duty`` below, with the machine's numbers read once."""
        polarity, down = self.polarity, self.down_scale
        for j in range(self.n):
            value = u[j]
            out[j] = polarity[j] * (value * down[j] if value < 0.0 else value)



def valve_duty(joint: Joint, u: float) -> float:
    """Valve duty (%) for controller output ``u``: down-scaled if negative (section 3.6,
    errata #11), then the joint's polarity (errata #17); ``Transmission.valve_duties`` is
    the same for every joint at once."""
    if u < 0.0:
        u *= joint.down_scale
    return joint.polarity * u


def output_of(joint: Joint, valve: float) -> float:
    """The controller output a valve duty stands for: ``valve_duty`` undone."""
    u = valve * joint.polarity
    return u / joint.down_scale if u < 0.0 else u


def output_min_pwm(joint: Joint) -> tuple[float, float]:
    """Minimum PWM (%) for a positive and for a negative controller output.

    Section 5.4.1 measured the minimums per valve side, and the valve duty is
    polarity·u (errata #27), so on a joint with polarity −1 a positive u opens
    the valve's negative side.
    """
    if joint.polarity > 0:
        return joint.min_pwm_pos, joint.min_pwm_neg
    return joint.min_pwm_neg, joint.min_pwm_pos


def _coupling_order(machine: Machine, coupled_to: list[int]) -> list[int]:
    """Joints in an order where each coupled joint comes after its partner; a cycle of
    couplings has no readings and is a MachineError."""
    order: list[int] = []
    state = [0] * len(coupled_to)  # 0 unseen, 1 on the path, 2 placed
    for start in range(len(coupled_to)):
        path = []
        j = start
        while j >= 0 and state[j] == 0:
            state[j] = 1
            path.append(j)
            j = coupled_to[j]
        if j >= 0 and state[j] == 1:
            name = machine.joints[start].key
            raise MachineError(f"{machine.path.name}: joints.{name}.encoder.coupled_to: the "
                               "couplings form a cycle, so no joint reading can be computed")
        for k in reversed(path):
            state[k] = 2
            order.append(k)
    return order
