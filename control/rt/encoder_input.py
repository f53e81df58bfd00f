"""Encoder input: words from the backend to joint positions, through the glitch filter.

Section 6.2: the multiplexed encoders sometimes read a wrong word. Each word
becomes its actuator's coordinate through the transmission, and each actuator's
reading is judged there, where a wrong word shows alone: a jump further than
the actuator can move (its ``full_duty_speed``, times the margin) since its last
good reading is rejected and counted. A wrong word within that reach (a wrong low
bit) cannot be told from motion and is believed; then, with the joint moving fast,
the true readings after it can lie beyond the belief's reach, and five rejections
in a row would be a feedback fault. So ``RECALL_READS`` rejected readings in a row
that are each within reach of one of the ``EARLIER`` beliefs before the present one
are believed: the present belief was the wrong reading. The
thesis saw two or three wrong readings at a time (Figure 6.1); ``glitch_limit``
rejections in a row are not a glitch but a lying encoder (a stuck bit, a cut
cable), and a feedback fault: no jump is ever believed, except the first
reading and the first after a reset (``resync``). A reading past the joint's range by more than
``range_margin_counts`` (once homed) is never believed, however long since the last (a
stalled controller's reach spans the whole range): ``glitch_limit`` of them in a row are a
feedback fault, the joint outside its range or its encoder lying. The
believed actuator coordinates then become joint positions (the Yaw reading
includes Bend), so a wrong Bend word leaves Yaw's position as right as Bend's.

Each sample is judged once. A serial board's late reply leaves ``read`` returning the words
it returned before (the backend's ``sample_ns`` unchanged): judged again, one wrong word would
be rejected once a tick and make ``glitch_limit`` "jumps in a row" by itself in a few ms, and
re-read during a resync it would confirm itself. So a joint's reading is judged only when its
sample is new to it; until then the joint keeps its belief, and its rejections in a row count
samples, not ticks.
"""

from __future__ import annotations

from hw.backend import Backend
from hw.machine import Machine
from hw.transmission import Transmission

AGREE_READS = 3  # rejected readings in a row that agree, to replace an unconfirmed belief
SETTLE_READS = 8  # new samples a resync takes at most to confirm every joint's belief
RESYNC_READS = 3 * SETTLE_READS  # reads it takes at most: a late serial board's answers too
EARLIER = 2  # beliefs before the present one that a rejected reading is also judged from
RECALL_READS = 2  # rejected readings in a row within reach of an earlier belief, to believe


class EncoderInput:
    """Inputs: the backend's words and sample time. Outputs: ``position`` (joint units),
    ``raw`` words and ``glitches`` per joint. ``homed`` is False until a quadrature
    encoder is zeroed."""

    def __init__(self, machine: Machine, transmission: Transmission, margin: float) -> None:
        n = self.n = machine.n_joints
        self.joints = machine.joints
        self.transmission = transmission
        self.glitch_limit = machine.supervision.glitch_limit
        margin_counts = machine.supervision.range_margin_counts
        self.low = [j.lower - margin_counts * abs(j.encoder.gradient) for j in machine.joints]
        self.high = [j.upper + margin_counts * abs(j.encoder.gradient) for j in machine.joints]
        self.fault = ""  # why the feedback cannot be believed, naming the joint
        self.fault_joint = -1
        self.raw = [0] * n
        self.offset = [0] * n  # quadrature counts at the zero (set by the rig's initialise)
        self.reading = [0.0] * n  # this tick's actuator readings, unfiltered
        self.actuator = [0.0] * n  # believed actuator coordinates
        self.position = [0.0] * n  # believed joint positions
        self.glitches = [0] * n
        self.rejects = [0] * n
        self.believe = [True] * n  # the first reading is believed
        # ... but it may be a wrong reading (section 6.2): until a reading agrees with it,
        # AGREE_READS rejected readings in a row that agree with each other replace it
        self.confirmed = [False] * n
        self.agree = [0] * n  # rejected readings in a row that agree with each other
        self.last_reject = [0.0] * n
        self.last_reject_ns = [0] * n
        self.last_ok_ns = [0] * n
        # per joint, the EARLIER beliefs before the present one, newest first: (reading, when)
        self.earlier: list[list[tuple[float, int]]] = [[(0.0, 0)] * EARLIER for _ in range(n)]
        self.recall = [0] * n  # rejected readings in a row within reach of an earlier belief
        self.speed_per_ns = [j.full_duty_speed * 1e-9 * margin for j in machine.joints]
        self.step_floor = [3 * abs(j.encoder.gradient) for j in machine.joints]  # 3 counts
        self.homed = machine.encoder_kind == "gray"
        self.judged_ns: list[int | None] = [None] * n  # the sample each joint was last judged on

    def read(self, backend: Backend, joints: range | None = None) -> None:
        """Read the board and judge the readings of ``joints`` (all; in the thesis's timing
        the one joint whose encoder this tick switched on) that come from a sample not judged
        yet; the others keep their belief."""
        raw, reading, actuator = self.raw, self.reading, self.actuator
        backend.read(raw)
        now = backend.sample_ns  # a late serial reply re-reads old words: time them so
        self.transmission.actuators_from_words(raw, self.offset, reading)
        rejects, last_ok, believe = self.rejects, self.last_ok_ns, self.believe
        speed, floor, confirmed = self.speed_per_ns, self.step_floor, self.confirmed
        judged = self.judged_ns
        for j in range(self.n) if joints is None else joints:
            if judged[j] == now:
                continue  # judged already: a late reply's words again
            judged[j] = now
            a = reading[j]
            inside = not self.homed or self.low[j] <= a <= self.high[j]
            agrees = abs(a - actuator[j]) <= speed[j] * (now - last_ok[j]) + floor[j]
            if inside and (agrees or believe[j] or self.believed_wrong(j, a, now)
                           or self.recalled(j, a, now)):
                confirmed[j] = agrees and not believe[j]
                earlier = self.earlier[j]
                self.recall[j] = 0
                if agrees and not believe[j]:
                    earlier.pop()
                    earlier.insert(0, (actuator[j], last_ok[j]))
                else:  # a belief judged wrong, or none before this reading: no reach to judge by
                    earlier[:] = [(a, now)] * EARLIER
                actuator[j] = a
                last_ok[j] = now
                rejects[j] = 0
                believe[j] = False
            else:
                rejects[j] += 1
                self.glitches[j] += 1
                self.last_reject[j], self.last_reject_ns[j] = a, now
                if rejects[j] >= self.glitch_limit and not inside:
                    self.implausible(j, f"reads {a:.2f}{self.joints[j].symbol}, outside its "
                                        f"range {self.joints[j].limit_text()}")
                elif rejects[j] >= self.glitch_limit:
                    self.implausible(j, f"read {rejects[j]} jumps in a row (to "
                                        f"{a:.2f}{self.joints[j].symbol} from "
                                        f"{actuator[j]:.2f}{self.joints[j].symbol}), more than "
                                        "it can move: a stuck bit or a bad cable")
        self.transmission.joints_from_actuators(actuator, self.position)

    def believed_wrong(self, j: int, a: float, now: int) -> bool:
        """Whether reading ``a``, rejected against a belief no reading has confirmed yet (the
        one believed outright at a resync), agrees with the readings rejected just before it
        (``AGREE_READS`` in a row): then that one reading was the wrong one. Against a
        confirmed belief, readings that agree with each other are a stuck bit or a bad
        cable: a feedback fault."""
        if self.confirmed[j] or not self.rejects[j]:
            self.agree[j] = 0
            return False
        near = self.speed_per_ns[j] * (now - self.last_reject_ns[j]) + self.step_floor[j]
        self.agree[j] = self.agree[j] + 1 if abs(a - self.last_reject[j]) <= near else 0
        return self.agree[j] + 1 >= AGREE_READS

    def recalled(self, j: int, a: float, now: int) -> bool:
        """Whether reading ``a``, rejected against the present belief, is the
        ``RECALL_READS``-th in a row within reach of one of the beliefs before it: then the
        present belief was a wrong reading within reach, and the readings are the joint."""
        reach, floor = self.speed_per_ns[j], self.step_floor[j]
        if any(abs(a - b) <= reach * (now - t) + floor for b, t in self.earlier[j]):
            self.recall[j] += 1
        else:
            self.recall[j] = 0
        return self.recall[j] >= RECALL_READS

    def implausible(self, j: int, what: str) -> None:
        """Record the first feedback fault: the controller latches the E-stop on it."""
        if not self.fault:
            self.fault_joint = j
            self.fault = f"feedback fault: {self.joints[j].name}'s encoder {what}"

    def resync(self, backend: Backend, period_ns: int) -> None:
        """Believe the readings anew (the joints may have moved while nobody watched) and
        forget a feedback fault: read until a second sample confirms every joint's belief,
        ``period_ns`` apart, at most ``SETTLE_READS`` new samples after the first (and
        ``RESYNC_READS`` reads). A wrong reading believed outright is replaced by the
        readings that agree against it on the way (``believed_wrong``). The words in hand
        are believed whether judged before or not, but only a new sample confirms them: a
        read that returns them again (a serial board that has not answered yet) would
        confirm a wrong word by itself. A few milliseconds, before the loop starts or in a
        reset, every valve closed."""
        self.believe = [True] * self.n
        self.rejects = [0] * self.n
        self.recall = [0] * self.n
        self.judged_ns = [None] * self.n
        self.fault, self.fault_joint = "", -1
        self.read(backend)
        clock = backend.clock
        sampled, samples = backend.sample_ns, 0
        for _ in range(RESYNC_READS):
            if all(self.confirmed) or samples >= SETTLE_READS:
                break
            clock.sleep_until(clock.now_ns() + period_ns)
            self.read(backend)
            if backend.sample_ns != sampled:
                sampled, samples = backend.sample_ns, samples + 1

    def zero(self) -> None:
        """Rig, section 3.5: where the actuators rest now becomes the encoders' zero."""
        transmission = self.transmission
        for j in range(self.n):
            self.offset[j] += round(transmission.count_of(j, self.actuator[j]))
        transmission.actuators_from_words(self.raw, self.offset, self.actuator)
        self.earlier = [[(a, t)] * EARLIER for a, t in zip(self.actuator, self.last_ok_ns,
                                                            strict=True)]
        transmission.joints_from_actuators(self.actuator, self.position)
        self.homed = True
