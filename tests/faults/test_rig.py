"""The rig as the thesis drove it (sections 3.5, 3.6): its own multi-step 200 → 600 → 200 mm
and a step given a start position complete with the default settings; before Initialise
the rig refuses closed-loop commands with the reason and limits open-loop duty."""

from __future__ import annotations

import numpy as np

from control import Mode
from control.motion import moves
from control.motion.plan import MovePlan
from control.rt.law import start_sets
from hw.machine import load_machine

RIG = load_machine("rig")


def initialised(client) -> None:
    client.initialise()
    done = client.wait_event("initialised", 120.0)
    assert done.payload["status"].startswith("complete"), done.payload


def test_function_c_multistep_200_600_200_completes(controller, measured) -> None:
    """function.c MultiStep: 200 mm, 600 mm, 200 mm with dwells, from the bottom stop; a
    400 mm step is far beyond any fixed following-error distance, and closes as fast as
    the valve lets it, so every step completes and settles."""
    client = controller("rig", lockstep=True, sim_options={"initial": [100.0]})
    initialised(client)
    here = client.status().position
    path = moves.rig_sequence(here, [(200.0, 3.0), (600.0, 3.0), (200.0, 3.0)], machine=RIG)
    plan = MovePlan("multi_step", "sequence of 3 steps", path,
                    meta={"steps": [[200, 3], [600, 3], [200, 3]]}, moving=(0,))
    result = client.wait(client.run(plan), timeout=120)
    assert result.complete, result.status
    rows = result.summaries()
    assert [label for label, _ in rows] == ["Ram step 1", "Ram step 2", "Ram step 3"]
    for label, summary in rows[1:]:  # the ram rides on its oil column near each target
        assert abs(summary.steady_state_error) < 5.0, (label, summary)  # (Figures 3.7-3.10)
        measured(f"{label.replace(' ', '_')}_steady_error_mm", summary.steady_state_error, "mm")
    assert abs(result.run.actual[-1, 0] - 200.0) < 5.0


def test_a_step_given_a_start_position_completes(controller) -> None:
    """The Moves tab's Step with a start: 200 mm, then 600 mm: the approach to 200 mm comes
    first, and the 400 mm step itself completes."""
    client = controller("rig", lockstep=True, sim_options={"initial": [100.0]})
    initialised(client)
    here = np.array(client.status().position)
    path = moves.step([200.0], 0, 600.0, duration=4.0, machine=RIG)
    plan = MovePlan("step", "step Ram to 600mm", path, moving=(0,))
    result = client.wait(client.run(plan), timeout=120)
    assert result.complete, result.status
    assert result.plan.approach > 0 and abs(result.run.desired[0, 0] - here[0]) < 1.0
    assert abs(result.run.actual[-1, 0] - 600.0) < 5.0


def test_before_initialise_closed_loop_is_refused_and_open_loop_is_limited(
        controller, until) -> None:
    client = controller("rig", lockstep=True, sim_options={"initial": [300.0]})
    assert not client.status().homed
    client.jog_position(0, 5000.0)  # would push the ram into its stop
    refused = client.wait_event("refused", 5.0)
    assert "not initialised" in refused.message and "run Initialise" in refused.message
    assert client.status().mode == Mode.HOLD
    path = moves.step(client.status().position, 0, 100.0, duration=2.0, machine=RIG)
    assert client.wait(client.move(path, kind="step"), 10).status.startswith(
        "refused: not initialised")
    client.jog([60.0])
    notice = client.wait_event("notice", 5.0, lambda e: "limited" in e.message)
    assert "±20 %" in notice.message
    until(lambda: client.status().duty[0] == 20.0, 5.0, "the duty limited to 20 %")


def test_gravity_leaves_the_ram_below_each_target(controller, measured) -> None:
    """Figures 3.8 and 3.10: small negative steady offsets from gravity, under the thesis's
    PID (eq. 3.3, {Kp, Kd, Ki} = {0.75, 0.002, 0.01}). The centred servo valve's tare flow
    lets the weight creep down until the error opens the valve upward; the integrator does
    not wind up while the valve is saturated on the way (section 3.6.1's intent, errata
    #31), and at Ki 0.01 it takes Kp/Ki = 75 s to remove the offset, so within the dwell the
    ram rests below 600 mm and below 200 mm. Tolerance −1.0…−0.05 mm: the thesis's text
    gives the offsets' sign, not their size. The thesis's sets are presets since issue 24
    made an identified P.I. with feed-forward the default (control.rt.law.start_sets)."""
    client = controller("rig", lockstep=True, sim_options={"initial": [100.0]})
    for which, c in zip(("hold", "track"), start_sets(RIG, thesis_timing=True), strict=True):
        client.set_coefficients(which, c)
    initialised(client)
    here = client.status().position
    path = moves.rig_sequence(here, [(200.0, 3.0), (600.0, 3.0), (200.0, 3.0)], machine=RIG)
    plan = MovePlan("multi_step", "sequence of 3 steps", path,
                    meta={"steps": [[200, 3], [600, 3], [200, 3]]}, moving=(0,))
    result = client.wait(client.run(plan), timeout=120)
    assert result.complete, result.status
    for label, summary in result.summaries()[1:]:
        offset = -summary.steady_state_error  # actual - target, mm
        measured(f"{label.replace(' ', '_')}_offset_mm", offset, "mm")
        assert -1.0 < offset < -0.05, (label, summary)
