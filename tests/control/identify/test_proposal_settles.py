"""Issue 24 item 3 on the real control process (lockstep): identification of one joint from a
PRBS proposes gains (``tuning.propose`` with its feed-forward, as the Identify tab applies
them) that, over the thesis's sets, make that joint's fast minimum-jerk move (0.5 and 1.0 of
its max speed) overshoot at most 10 % of its travel (or 1 unit) and settle within its
goal_tolerance 0.5 s after the path arrives; the prediction on the identified model
(``tuning.predict_move``) says so too, and is close to what the robot does."""

from __future__ import annotations

import numpy as np
import pytest

from control import ControlClient
from control.identify import excitation, sysid, tuning
from control.rt.law import start_sets
from hw.machine import load_machine
from tests.control.waiting import wait_until

SETTLE_S = 0.5
RIG_START = 600.0
REST_S = 0.3  # of the controller's time, within the goal tolerance of the hold target


def at_rest(robot: ControlClient, joint: int, tolerance: float) -> None:
    """Until ``joint`` has stayed within ``tolerance`` of its hold target for ``REST_S``."""
    since: list[float | None] = [None]

    def still() -> bool:
        status = robot.status()
        if abs(status.position[joint] - status.desired[joint]) > tolerance:
            since[0] = None
        elif since[0] is None:
            since[0] = status.time_s
        return since[0] is not None and status.time_s - since[0] >= REST_S

    wait_until(still, 60.0, "the joint at rest", every=0.001)


@pytest.mark.parametrize(("name", "joint"), [("rig", 0), ("unimate2000b", 4)],
                         ids=["rig-ram", "unimate2000b-yaw"])
def test_an_identified_joint_gets_gains_whose_fast_move_settles(tmp_path, name: str,
                                                                joint: int) -> None:
    machine = load_machine(name)
    spec = machine.joints[joint]
    with ControlClient(name, lockstep=True, data_dir=tmp_path, heartbeat_timeout_s=5.0) as robot:
        if machine.encoder_kind != "gray":
            robot.initialise()
            robot.wait_event("initialised", 120.0)
            assert robot.wait(robot.go_to([RIG_START], 0.5), timeout=60).complete
        start = np.array(robot.status().position)
        profile = excitation.prbs(machine, joint, start)
        run = robot.wait(robot.actuate(profile.duty, meta=dict(profile.meta)), timeout=120).run
        models: list[sysid.DeadbandModel | None] = [None] * machine.n_joints
        models[joint] = sysid.identify(run, machine, joint).deadband
        thesis_hold, thesis_track = start_sets(machine, thesis_timing=True)
        ffs = [None if m is None else tuning.feed_forward(m, s)
               for m, s in zip(models, machine.joints, strict=True)]
        for which, base in (("hold", thesis_hold), ("track", thesis_track)):
            proposed = tuning.with_feed_forward(tuning.propose(models, machine, base).coefficients,
                                                ffs)
            robot.set_coefficients(which, proposed, models)
        for speed in (0.5, 1.0):
            # from rest, as an operator checks a move: the PRBS (or the move before) may leave
            # the joint swinging while the sets change, and a move started from a swing is
            # judged on the swing too (settle 0.81-1.13 s seen now and then, on two workers)
            at_rest(robot, joint, spec.goal_tolerance)
            here = np.array(robot.status().position)
            prediction = tuning.predict_move(models, machine, proposed, joint, here, speed)
            result = robot.wait(robot.move(prediction.desired), timeout=60)
            assert result.run is not None, result.status
            measured = tuning.move_figures(result.run.t, result.run.desired[:, joint],
                                           result.run.actual[:, joint], prediction.arrives, spec)
            travel = abs(prediction.desired[-1, joint] - prediction.desired[0, joint])
            bound = max(0.1 * travel, 1.0)
            for label, figures in (("predicted", prediction.figures), ("measured", measured)):
                assert figures.overshoot <= bound, (label, speed, figures)
                assert figures.settle_s <= SETTLE_S, (label, speed, figures)
            assert abs(measured.overshoot - prediction.figures.overshoot) <= 0.5 * bound, \
                (speed, measured, prediction.figures)
