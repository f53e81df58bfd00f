"""The encoder input's resync (at the start, and at an E-stop's release): every joint's first
reading is believed outright and confirmed by the next; if that first one was a wrong
reading (section 6.2), the readings that agree against it replace it before they could add
up to a feedback fault. Against a confirmed belief, readings that agree with each other are
a stuck bit: a feedback fault.

Each sample is judged once: a serial board whose answers are late leaves the backend
returning the words it returned before, with the same ``sample_ns`` (``LateReplies`` does
that to the simulator here); a wrong word read again so is one glitch, not a glitch a tick,
and confirms no belief."""

from __future__ import annotations

from control.rt.encoder_input import EncoderInput
from hw.machine import load_machine
from hw.sim.backend import SimBackend
from hw.transmission import Transmission

UNIMATE = load_machine("unimate2000b")
ROTATE = 1
BEND = 3
MS = 1_000_000


class LateReplies(SimBackend):
    """The simulator, with Bend's next word given a wrong high bit once (``lie``), and read
    through late answers as the serial backend reads them: the next ``late`` reads (and
    ``late_after_lie`` after the lie) return the words and sample time of the read before."""

    lie = False
    late = 0
    late_after_lie = 0

    def read(self, raw: list[int]) -> None:
        if self.late:
            self.late -= 1
            raw[:] = self.held  # sample_ns as it was: the same sample
            return
        super().read(raw)
        if self.lie:
            raw[BEND] ^= 1 << 11
            self.lie = False
            self.late = self.late_after_lie
        self.held = list(raw)


def ticks(backend: SimBackend, encoders: EncoderInput, n: int) -> None:
    for _ in range(n):
        backend.clock.sleep_until(backend.clock.now_ns() + MS)
        encoders.read(backend)


def started() -> tuple[LateReplies, EncoderInput, float]:
    backend = LateReplies(UNIMATE, lockstep=True, glitch_scale=0.0)
    encoders = EncoderInput(UNIMATE, Transmission(UNIMATE), 1.5)
    encoders.resync(backend, MS)
    return backend, encoders, encoders.position[BEND]


def test_a_resync_that_first_reads_a_wrong_word_settles_on_the_true_one() -> None:
    backend, encoders, truth = started()
    backend.lie = True
    encoders.resync(backend, MS)  # believes the wrong word, then the true ones replace it
    assert abs(encoders.position[BEND] - truth) < 0.1
    assert encoders.fault == "" and all(encoders.confirmed)
    assert encoders.glitches[BEND] >= 2  # the true readings rejected before they agreed


def test_agreeing_readings_against_a_confirmed_belief_are_a_feedback_fault() -> None:
    backend, encoders, truth = started()
    assert all(encoders.confirmed)
    backend.stick_bit(BEND, 11, 1)
    ticks(backend, encoders, UNIMATE.supervision.glitch_limit)
    assert encoders.fault.startswith("feedback fault: Bend's encoder read")
    assert abs(encoders.position[BEND] - truth) < 0.1  # the stuck bit was never believed


def test_a_resync_never_believes_a_reading_outside_the_joints_range() -> None:
    backend, encoders, truth = started()
    top = 1 << 12  # the Gray word's top bit: half the disk away
    backend.stick_bit(BEND, 12, 0 if backend_word(backend, BEND) & top else 1)
    encoders.believe = [True] * 6  # as a resync leaves it, before its next reading
    encoders.read(backend)
    wrong = encoders.reading[BEND]
    assert not UNIMATE.joints[BEND].lower <= wrong <= UNIMATE.joints[BEND].upper
    backend.stick_bit(BEND, 12, None)
    ticks(backend, encoders, 1)  # the out-of-range word was not believed; this one is
    assert abs(encoders.position[BEND] - truth) < 0.1 and encoders.fault == ""


def backend_word(backend: SimBackend, joint: int) -> int:
    raw = [0] * 6
    SimBackend.read(backend, raw)
    return raw[joint]


def test_after_a_long_stall_a_wrong_word_outside_the_range_is_a_glitch_not_a_fault() -> None:
    """A controller stopped for 3 s gives every joint a reach across its whole range; a
    wrong word then read outside the range is rejected, and the true words go on."""
    backend, encoders, truth = started()
    ticks(backend, encoders, 2)
    backend.clock.sleep_until(backend.clock.now_ns() + 3000 * MS)  # the stall
    top = 1 << 12  # the Gray word's top bit: half the disk away
    backend.stick_bit(BEND, 12, 0 if backend_word(backend, BEND) & top else 1)
    encoders.read(backend)
    backend.stick_bit(BEND, 12, None)
    wrong = encoders.reading[BEND]
    assert not UNIMATE.joints[BEND].lower <= wrong <= UNIMATE.joints[BEND].upper
    assert encoders.fault == "" and encoders.glitches[BEND] == 1
    ticks(backend, encoders, 10)
    assert encoders.fault == "" and abs(encoders.position[BEND] - truth) < 0.1


def test_words_outside_the_range_that_go_on_are_a_feedback_fault() -> None:
    backend, encoders, truth = started()
    top = 1 << 12
    backend.stick_bit(BEND, 12, 0 if backend_word(backend, BEND) & top else 1)
    ticks(backend, encoders, UNIMATE.supervision.glitch_limit - 1)
    assert encoders.fault == ""
    ticks(backend, encoders, 1)
    assert encoders.fault.startswith("feedback fault: Bend's encoder reads")
    assert "outside its range" in encoders.fault
    assert abs(encoders.position[BEND] - truth) < 0.1  # never believed


def test_a_wrong_word_read_again_through_late_answers_is_judged_once() -> None:
    """One wrong word, then the board's answers 10 ms late: the ten reads of the same sample
    are one glitch, not five rejections in a row (a feedback fault), and the belief stays."""
    backend, encoders, truth = started()
    backend.lie, backend.late_after_lie = True, 10
    ticks(backend, encoders, 11)
    assert encoders.fault == "" and encoders.glitches[BEND] == 1
    assert abs(encoders.position[BEND] - truth) < 0.1
    ticks(backend, encoders, 3)  # the answers come again: believed, as before the wrong word
    assert encoders.fault == "" and encoders.glitches[BEND] == 1
    assert abs(encoders.position[BEND] - truth) < 0.1


def test_a_word_that_stays_wrong_is_a_feedback_fault_at_the_glitch_limit_th_new_sample() -> None:
    """A stuck bit read through late answers (each sample read four times): the rejections
    in a row count samples, so the fault comes at the ``glitch_limit``-th new sample, with
    the stuck word never believed."""
    backend, encoders, truth = started()
    limit = UNIMATE.supervision.glitch_limit
    backend.stick_bit(BEND, 11, 0 if backend_word(backend, BEND) & (1 << 11) else 1)
    for sample in range(1, limit):
        ticks(backend, encoders, 1)
        backend.late = 3
        ticks(backend, encoders, 3)
        assert encoders.fault == "", f"a fault after {sample} samples"
        assert encoders.glitches[BEND] == sample
    ticks(backend, encoders, 1)
    assert encoders.fault.startswith(f"feedback fault: Bend's encoder read {limit} jumps")
    assert encoders.glitches[BEND] == limit
    assert abs(encoders.position[BEND] - truth) < 0.1


def test_a_resync_does_not_confirm_a_wrong_word_by_reading_it_again() -> None:
    """The first word a resync reads is wrong and the answers after it are late: reading it
    again confirms nothing, so the true words that follow replace it (they agree with each
    other against an unconfirmed belief) within the resync, without a fault."""
    backend, encoders, truth = started()
    backend.lie, backend.late_after_lie = True, 3
    encoders.resync(backend, MS)
    assert encoders.fault == "" and all(encoders.confirmed)
    assert abs(encoders.position[BEND] - truth) < 0.1
    ticks(backend, encoders, 10)
    assert encoders.fault == "" and abs(encoders.position[BEND] - truth) < 0.1


def test_a_resync_waits_for_new_samples_through_late_answers() -> None:
    """A resync's first words true, the answers after them late for longer than its
    ``SETTLE_READS``: it reads on until a new sample confirms every belief."""
    backend, encoders, truth = started()
    backend.late = 12
    encoders.resync(backend, MS)
    assert all(encoders.confirmed) and encoders.fault == ""
    assert abs(encoders.position[BEND] - truth) < 0.1


def test_in_the_thesis_timing_each_joint_is_judged_once_on_each_sample() -> None:
    """One joint judged a tick (``joints``): a sample judged for Bend is still new to Rotate,
    and Bend's wrong word read again at its next slot is not judged twice."""
    backend, encoders, _ = started()
    for joint in (ROTATE, BEND):
        backend.stick_bit(joint, 11, 0 if backend_word(backend, joint) & (1 << 11) else 1)
    backend.clock.sleep_until(backend.clock.now_ns() + MS)
    encoders.read(backend, range(BEND, BEND + 1))
    assert encoders.glitches[BEND] == 1 and encoders.glitches[ROTATE] == 0
    backend.late = 2
    encoders.read(backend, range(ROTATE, ROTATE + 1))  # the same sample, new to Rotate
    assert encoders.glitches[ROTATE] == 1
    encoders.read(backend, range(BEND, BEND + 1))  # the same sample again: Bend keeps its count
    assert encoders.glitches[BEND] == 1 and encoders.fault == ""
