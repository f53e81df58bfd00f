"""The encoder input after a resync (start, or an E-stop's release): the first reading is
believed outright, and if that one was a wrong reading (section 6.2) the readings that agree
against it replace it before they could add up to a feedback fault; past the settling
readings, readings that agree against the belief are a feedback fault (a stuck bit)."""

from __future__ import annotations

from control.encoder_input import AGREE_READS, SETTLE_READS, EncoderInput
from hw.machine import load_machine
from hw.sim.backend import SimBackend
from hw.transmission import Transmission

UNIMATE = load_machine("unimate2000b")
BEND = 3


def ticks(backend: SimBackend, encoders: EncoderInput, n: int) -> None:
    for _ in range(n):
        backend.clock.sleep_until(backend.clock.now_ns() + 1_000_000)
        encoders.read(backend)


def setup() -> tuple[SimBackend, EncoderInput, float]:
    backend = SimBackend(UNIMATE, lockstep=True, glitch_scale=0.0)
    encoders = EncoderInput(UNIMATE, Transmission(UNIMATE), 1.5)
    encoders.read(backend)
    ticks(backend, encoders, 5)
    return backend, encoders, encoders.position[BEND]


def test_a_wrong_first_reading_after_a_resync_is_replaced_without_a_fault() -> None:
    backend, encoders, truth = setup()
    backend.stick_bit(BEND, 11, 1)  # one high bit wrong: a jump of degrees
    encoders.resync(backend)  # believes the wrong reading outright
    assert abs(encoders.position[BEND] - truth) > 1.0
    backend.stick_bit(BEND, 11, None)
    ticks(backend, encoders, AGREE_READS)
    assert abs(encoders.position[BEND] - truth) < 0.1 and encoders.fault == ""


def test_agreeing_readings_against_a_settled_belief_are_a_feedback_fault() -> None:
    backend, encoders, truth = setup()
    ticks(backend, encoders, SETTLE_READS)  # the start's settling is over
    backend.stick_bit(BEND, 11, 1)
    ticks(backend, encoders, UNIMATE.supervision.glitch_limit)
    assert encoders.fault.startswith("feedback fault: Bend's encoder read")
    assert abs(encoders.position[BEND] - truth) < 0.1  # the stuck bit was never believed
