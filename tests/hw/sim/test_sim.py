"""SimBackend: the Backend contract, lazy time, PWM timing, polarity, E-stop, determinism."""

from __future__ import annotations

import pytest

from hw.backend import Backend, LinkCounters, RealClock, StepClock
from hw.factory import make_backend
from hw.gray import gray_to_binary
from hw.machine import load_machine
from hw.sim.backend import SimBackend

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
MS = 1_000_000
HOME = [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]


def readings(sim: SimBackend, raw: list[int]) -> list[float]:
    """Joint readings from raw words, as the control side converts them."""
    q = []
    for spec, word in zip(sim.machine.joints, raw, strict=True):
        value = spec.encoder.gradient * gray_to_binary(word) + spec.encoder.constant
        if spec.encoder.coupled_to is not None:
            value += spec.encoder.coupling * q[spec.encoder.coupled_to]
        q.append(value)
    return q


def tick(sim: SimBackend, raw: list[int], duty: list[float], ticks: int) -> None:
    """The control loop's shape: read, write, sleep to the next deadline."""
    for _ in range(ticks):
        sim.read(raw)
        sim.write(duty)
        sim.clock.sleep_until(sim.clock.now_ns() + MS)


@pytest.mark.parametrize("machine", [UNIMATE, RIG])
def test_satisfies_the_backend_protocol(machine: object) -> None:
    sim = SimBackend(machine, lockstep=True)
    assert isinstance(sim, Backend)
    assert isinstance(sim.clock, StepClock)
    assert isinstance(sim.counters, LinkCounters)
    assert sim.fault == "" and sim.estop is False
    sim.open()
    sim.close()
    sim.close()


def test_factory_builds_the_simulator() -> None:
    sim = make_backend(UNIMATE, "sim", seed=3, lockstep=True)
    assert isinstance(sim, SimBackend) and isinstance(sim.clock, StepClock)
    assert isinstance(SimBackend(RIG).clock, RealClock)


def test_unimate_words_read_the_initial_pose() -> None:
    sim = SimBackend(UNIMATE, lockstep=True, initial=[1200.0, 10.0, -5.0, 20.0, 30.0, -45.0])
    raw = [0] * 6
    sim.read(raw)
    assert readings(sim, raw) == pytest.approx([1200.0, 10.0, -5.0, 20.0, 30.0, -45.0], abs=0.15)


def test_time_passes_only_when_the_loop_sleeps() -> None:
    sim = SimBackend(UNIMATE, lockstep=True, initial=HOME, glitch_scale=0.0)
    sim.open()
    raw = [0] * 6
    sim.write([-60.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    before = sim.joint_positions()
    sim.read(raw)
    assert sim.joint_positions() == before
    tick(sim, raw, [-60.0, 0, 0, 0, 0, 0], 500)
    assert sim.joint_positions()[0] > before[0] + 10.0


def test_positive_duty_moves_the_unimate_towards_smaller_readings() -> None:
    # polarity -1; the control side multiplies its output by polarity to move the right way
    for joint in range(6):
        for control, direction in ((50.0, 1.0), (-50.0, -1.0)):
            sim = SimBackend(UNIMATE, lockstep=True, initial=HOME, glitch_scale=0.0)
            raw = [0] * 6
            sim.read(raw)
            start = readings(sim, raw)[joint]
            duty = [0.0] * 6
            duty[joint] = control * UNIMATE.joints[joint].polarity
            tick(sim, raw, duty, 300)
            sim.read(raw)
            assert (readings(sim, raw)[joint] - start) * direction > 1.0
            if control * UNIMATE.joints[joint].polarity > 0:
                assert readings(sim, raw)[joint] < start


def test_duty_is_clipped_quantised_and_applied_at_the_next_pwm_period() -> None:
    sim = SimBackend(RIG, lockstep=True)
    sim.clock.sleep_until(MS)
    sim.write([150.0])
    assert sim.applied_duty() == [0.0]  # the 325 us period that started at 0.975 ms runs on
    sim.clock.sleep_until(MS + 299_999)
    assert sim.applied_duty() == [0.0]
    sim.clock.sleep_until(MS + 300_000)
    assert sim.applied_duty() == [100.0]
    sim.write([-12.7])
    sim.clock.sleep_until(2 * MS)
    assert sim.applied_duty() == [-12.0]


def test_estop_closes_every_valve_whatever_is_commanded() -> None:
    sim = SimBackend(UNIMATE, lockstep=True, initial=HOME, glitch_scale=0.0)
    raw = [0] * 6
    full = [-80.0, 80.0, -80.0, 80.0, -80.0, 80.0]
    tick(sim, raw, full, 200)
    assert any(abs(v) > 5.0 for v in sim.joint_velocities())
    sim.press_estop(True)
    assert sim.estop and sim.applied_duty() == [0.0] * 6
    tick(sim, raw, full, 100)
    stopped = sim.joint_positions()
    tick(sim, raw, full, 500)
    assert sim.joint_positions() == pytest.approx(stopped, abs=0.05)
    assert sim.applied_duty() == [0.0] * 6
    sim.press_estop(False)
    tick(sim, raw, full, 100)
    assert sim.joint_positions()[0] > stopped[0] + 5.0


def test_same_seed_same_raw_words_other_seed_other_glitches() -> None:
    def run(seed: int) -> tuple[list[list[int]], list[int]]:
        sim = SimBackend(UNIMATE, seed=seed, lockstep=True, glitch_scale=30.0)
        raw = [0] * 6
        words = []
        for k in range(1500):
            sim.read(raw)
            words.append(list(raw))
            sim.write([30.0 if (k // 500) % 2 else -30.0] * 6)
            sim.clock.sleep_until(sim.clock.now_ns() + MS)
        return words, sim.wrong_readings()

    words, wrong = run(1)
    assert sum(wrong) > 0
    assert run(1) == (words, wrong)
    other, other_wrong = run(2)
    assert other_wrong != wrong and other != words


def test_rig_initialise_then_positions_in_mm() -> None:
    # the rig's count starts at 0 wherever the ram is; Initialise zeroes it at the bottom
    sim = SimBackend(RIG, lockstep=True, initial=[432.1], load_kg=150.0)
    raw = [0]
    sim.read(raw)
    assert raw == [0]
    tick(sim, raw, [-30.0], 1500)
    sim.read(raw)
    assert sim.joint_positions()[0] == pytest.approx(0.0, abs=1e-9)
    bottom = raw[0]
    assert bottom == -4321
    tick(sim, raw, [40.0], 800)
    sim.read(raw)
    assert 0.1 * (raw[0] - bottom) == pytest.approx(sim.joint_positions()[0], abs=0.1)


def test_wrong_readings_at_the_default_scan_and_none_scanning_slowly() -> None:
    def wrong(**options: float) -> int:
        sim = SimBackend(UNIMATE, seed=5, lockstep=True, glitch_scale=20.0, **options)
        tick(sim, [0] * 6, [35.0, -35.0, 35.0, -35.0, 35.0, -35.0], 1000)
        return sum(sim.wrong_readings())

    assert wrong() > 5
    assert wrong(scan_period_s=6 * UNIMATE.encoder_settle_s) == 0
    assert wrong(scan_period_s=6e-3, select_to_latch_s=1e-3) > 5  # thesis: 1 ms per joint
    assert wrong(scan_period_s=36e-3, select_to_latch_s=6e-3) == 0  # 6 ms per joint
    with pytest.raises(ValueError, match="select_to_latch_s"):
        SimBackend(UNIMATE, lockstep=True, scan_period_s=6e-3, select_to_latch_s=1.5e-3)


def test_a_long_pause_is_caught_up_in_bounded_time() -> None:
    sim = SimBackend(UNIMATE, lockstep=True, initial=HOME)
    sim.clock.sleep_until(3_600 * 1_000_000_000)
    raw = [0] * 6
    sim.read(raw)
    assert readings(sim, raw)[1] == pytest.approx(0.0, abs=0.1)


def test_the_oil_holds_the_rig_load() -> None:
    # section 3.3: about 3.3 MPa on the rod side carries 300 kg; the rest balances the cap side
    sim = SimBackend(RIG, lockstep=True)
    tick(sim, [0], [0.0], 200)
    (pa, pb), = sim.chamber_pressures()
    area_a, area_b = RIG.joints[0].plant["area_a_m2"], RIG.joints[0].plant["area_b_m2"]
    assert pa * area_a - pb * area_b == pytest.approx(312.0 * 9.81, abs=100.0)
    assert -1.0 < sim.joint_velocities()[0] < 0.0  # creeping down on the valve's tare flow
