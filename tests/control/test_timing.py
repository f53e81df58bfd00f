"""The thesis's timing (control/timing.py): one joint serviced per interrupt, a sample every
six, as RT.o ran; servodesk's timing serves every joint every tick. Real controllers."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient
from control.motion import moves
from control.recorder import load_run
from control.timing import Timing
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")


def test_a_timing_is_checked_when_built() -> None:
    with pytest.raises(ValueError, match="timing must be one of"):
        Timing("rtai")
    with pytest.raises(ValueError, match="interrupt_ms"):
        Timing.thesis(float("nan"))
    with pytest.raises(ValueError, match="unknown slip"):
        Timing.thesis(1.0, ("derivativ",))
    with pytest.raises(ValueError, match="only in the thesis"):
        Timing("servodesk", slips=("min_pwm",))
    thesis = Timing.thesis(6.0)
    assert thesis.slots(UNIMATE) == 6 and thesis.sample_time_s(UNIMATE) == pytest.approx(0.036)
    assert Timing().sample_time_s(UNIMATE) == UNIMATE.sample_time_s


@pytest.mark.parametrize("interrupt_ms", [1.0, 6.0])
def test_a_step_in_thesis_timing_runs_a_sample_every_six_interrupts(
        tmp_path: Path, interrupt_ms: float) -> None:
    timing = Timing.thesis(interrupt_ms)
    with ControlClient("unimate2000b", lockstep=True, data_dir=tmp_path, timing=timing,
                       heartbeat_timeout_s=3.0) as client:
        assert client.dt == pytest.approx(6 * interrupt_ms / 1e3)
        start = np.array(client.status().position)
        path = moves.step(start, "rotate", start[1] + 20.0, duration=4.0, machine=UNIMATE,
                          dt=client.dt)
        result = client.wait(client.move(path, kind="step"), timeout=120)
        assert result.complete, result.status
        run = load_run(result.files.json)
        assert run.sample_time_s == pytest.approx(client.dt)
        assert np.diff(run.t) == pytest.approx(client.dt, abs=1e-9)  # a row a sample
        assert run.meta["timing"].startswith(f"thesis: one joint per {interrupt_ms:g} ms")
        assert abs(run.actual[-1, 1] - path[-1, 1]) < 3 * UNIMATE.joints[1].tolerance


def test_each_interrupt_changes_only_its_own_joints_valve(tmp_path: Path) -> None:
    """In real time at 6 ms an interrupt, every tick is seen: between two consecutive ticks
    only the valve of joint (tick mod 6) may change."""
    with ControlClient("unimate2000b", data_dir=tmp_path, timing=Timing.thesis(6.0)) as client:
        start = np.array(client.status().position)
        goal = start + np.array([0.0, 15.0, 4.0, -15.0, 15.0, 20.0])  # In/Out's dead band
        # is wide for a 36 ms loop: the supervisor's following error is not this test's
        handle = client.go_to(goal, speed=0.2)
        seen: dict[int, tuple[float, ...]] = {}
        deadline = time.monotonic() + 60.0
        while not handle.done.is_set() and time.monotonic() < deadline:
            status = client.status()
            seen[status.tick] = status.valve
        pairs = changed = 0
        for tick, valve in seen.items():
            before = seen.get(tick - 1)
            if before is None:
                continue
            pairs += 1
            moved = {j for j in range(6) if valve[j] != before[j]}
            assert moved <= {tick % 6}, f"tick {tick} changed the valves of {sorted(moved)}"
            changed += bool(moved)
        assert pairs > 30 and changed > 10, (pairs, changed)
        result = client.wait(handle, timeout=60)  # followed to its end; at 36 ms a loop a
        assert result.complete or result.unsettled, result.status  # joint may not settle in 2 s


@pytest.mark.parametrize("interrupt_ms", [1.0, 6.0])
def test_wrong_readings_as_figure_6_1_at_the_thesis_timing(tmp_path: Path,
                                                            interrupt_ms: float) -> None:
    """Section 6.2: at 1 ms per axis 2-3 wrong readings a joint in a 12 s stepping run, none
    at 6 ms per axis; the controller's glitch filter rejects them and the run completes."""
    with ControlClient("unimate2000b", lockstep=True, data_dir=tmp_path, seed=1,
                       timing=Timing.thesis(interrupt_ms), heartbeat_timeout_s=3.0) as client:
        start = np.array(client.status().position)
        target = start + np.array([100.0, 15.0, 8.0, 20.0, 20.0, 30.0])
        path = moves.multi_step(start, target, duration=12.0, machine=UNIMATE, dt=client.dt)
        result = client.wait(client.move(path, kind="multi_step"), timeout=300)
        assert result.complete or result.unsettled, result.status  # followed to its end
        wrong = client.status().glitches
    if interrupt_ms == 1.0:  # 4-19 over six seeds, mean 11.5 (the thesis: 9)
        assert 3 <= sum(wrong) <= 40, wrong
    else:
        assert wrong == (0,) * 6
