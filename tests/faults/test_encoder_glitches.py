"""Wrong encoder readings (thesis section 6.2, Figure 6.1) during a six-joint move.

The simulator's multiplexed Gray-code board reads wrong words the way the
thesis's lamps did (a lamp too dim at the latch darkens the weakest clear
tracks). Here all six encoders are scanned every 1 ms tick, servodesk's own
scan, where the lamp model gives about 1 % of readings wrong: an 8 s move sees
hundreds. The same move, same
seed, in lockstep (so both runs see the same plant) is run clean and glitchy:
the glitch filter must reject the wrong readings, count them per joint, and
keep them out of the law, so the valve commands stay in the clean run's range.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from control import ControlClient
from control.motion import moves
from control.recorder import Run, as_written, load_run
from control.rt.encoder_input import EARLIER
from control.rt.loop import LoopConfig
from hw.machine import load_machine
from hw.transmission import Transmission

UNIMATE = load_machine("unimate2000b")
GLITCH_SCALE = 1.0
# A wrong low bit within a step the joint could make passes the filter (it cannot be told
# from motion) and kicks the valve by Kp times its size: up to about 20 % on In/Out at the
# lamp model's rate. An accepted wrong high bit would saturate the valve (100 %).
SPIKE_MARGIN_PCT = 25.0


def run_sine(controller: Callable[..., ControlClient], glitch_scale: float
             ) -> tuple[Run, tuple[int, ...]]:
    client = controller(lockstep=True, seed=4, sim_options={"glitch_scale": glitch_scale})
    start = client.status().position
    end = np.array(start) + np.array([60.0, 20.0, 5.0, 20.0, 20.0, 30.0])
    path = moves.sine(start, end, period=4.0, duration=8.0, machine=UNIMATE)
    result = client.wait(client.move(path, kind="sine"), timeout=60)
    glitches = client.status().glitches
    client.close()  # one controller per client process at a time: the segment carries our pid
    assert result.complete, result.status
    assert load_run(result.files.json) == as_written(result.run)
    return result.run, glitches


def implausible_steps(actual: np.ndarray, dt: float) -> int:
    """Recorded steps larger than an actuator can move since each of its last three readings.

    A rejected reading leaves the actuator's position unchanged, so a step after ``k``
    unchanged samples may cover ``k + 1`` samples of motion; and a wrong reading within
    reach is believed, after which the filter believes readings within reach of the two
    beliefs before it (its ``EARLIER``). Per actuator (the Yaw reading includes Bend's),
    at the controller's margin on the joints' full-duty speed.
    """
    margin = LoopConfig(period_ns=1).glitch_margin  # the controller's own judgement
    speed = np.array([margin * j.full_duty_speed * dt for j in UNIMATE.joints])
    floor = np.array([3 * abs(j.encoder.gradient) for j in UNIMATE.joints])
    a = Transmission(UNIMATE).actuators_of(actual)
    seen = [a[0].copy() for _ in range(1 + EARLIER)]  # newest first, and the sample of each
    at = [np.zeros(a.shape[1]) for _ in range(1 + EARLIER)]
    bad = 0
    for i, now in enumerate(a[1:], start=1):
        moved = now != seen[0]
        far = np.ones(a.shape[1], dtype=bool)
        for value, when in zip(seen, at, strict=True):
            far &= np.abs(now - value) > speed * (i - when) + floor
        bad += int(np.sum(moved & far))
        for k in range(EARLIER, 0, -1):
            seen[k] = np.where(moved, seen[k - 1], seen[k])
            at[k] = np.where(moved, at[k - 1], at[k])
        seen[0], at[0] = np.where(moved, now, seen[0]), np.where(moved, i, at[0])
    return bad


def test_wrong_readings_are_rejected_counted_and_never_reach_the_valves(
        controller, measured) -> None:
    """At 1 ms, six encoders a tick, the lamp model's own rate (about 1 %): every joint
    counts rejected readings, no recorded reading jumps further than the joint can move,
    and no valve command exceeds the clean run's peak by more than 25 % (an accepted
    wrong high bit would be a jump of tens of degrees and a saturated valve)."""
    clean, clean_glitches = run_sine(controller, 0.0)
    glitchy, glitches = run_sine(controller, GLITCH_SCALE)

    assert clean_glitches == (0,) * 6
    measured("rejected_readings", sum(glitches))
    assert all(g > 0 for g in glitches), glitches
    assert implausible_steps(clean.actual, clean.sample_time_s) == 0
    assert implausible_steps(glitchy.actual, glitchy.sample_time_s) == 0
    clean_peak = np.abs(clean.duty).max(axis=0)
    peak = np.abs(glitchy.duty).max(axis=0)
    measured("peak_duty_clean_pct", clean_peak.max(), "%")
    measured("peak_duty_glitchy_pct", peak.max(), "%")
    assert np.all(peak <= clean_peak + SPIKE_MARGIN_PCT), (clean_peak.round(1), peak.round(1))
    tracking = np.abs(glitchy.desired - glitchy.actual).max(axis=0)
    assert np.all(tracking < [j.following_error for j in UNIMATE.joints])
