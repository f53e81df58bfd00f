"""The encoder input's resync (at the start, and at an E-stop's release): every joint's first
reading is believed outright and confirmed by the next; if that first one was a wrong
reading (section 6.2), the readings that agree against it replace it before they could add
up to a feedback fault. Against a confirmed belief, readings that agree with each other are
a stuck bit: a feedback fault."""

from __future__ import annotations

from control.encoder_input import EncoderInput
from hw.machine import load_machine
from hw.sim.backend import SimBackend
from hw.transmission import Transmission

UNIMATE = load_machine("unimate2000b")
BEND = 3
MS = 1_000_000


class LyingOnce(SimBackend):
    """The simulator, with Bend's next word given a wrong high bit once (``lie``)."""

    lie = False

    def read(self, raw: list[int]) -> None:
        super().read(raw)
        if self.lie:
            raw[BEND] ^= 1 << 11
            self.lie = False


def ticks(backend: SimBackend, encoders: EncoderInput, n: int) -> None:
    for _ in range(n):
        backend.clock.sleep_until(backend.clock.now_ns() + MS)
        encoders.read(backend)


def started() -> tuple[LyingOnce, EncoderInput, float]:
    backend = LyingOnce(UNIMATE, lockstep=True, glitch_scale=0.0)
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
    encoders.read(backend)  # the out-of-range word was not believed; this one is
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
