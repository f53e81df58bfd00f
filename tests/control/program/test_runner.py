"""The program runner on the real control subprocess (the simulated rig, in lockstep: one
controller for the module, initialised once): run to the end with every move's run tagged
with the program run, single steps, feed hold and resume, stop, start from a step, an
E-stop mid-program, the operator's wait, and a caller driving the steps itself."""

from __future__ import annotations

import json
from collections.abc import Iterator

import numpy as np
import pytest

from control import ControlClient
from control.motion.positions import PositionBook
from control.program import CheckedProgram, Runner, RunnerState, check, parse_program
from control.program.runner import (
    MoveStarted,
    ProgramEnded,
    StepDone,
    StepStarted,
    initialise_rig,
)
from tests.control.waiting import wait_until

END_S = 60.0  # a program here takes a second or two; a loaded two-core machine, more
LONG_SINE = """
[[step]]
move = "sine"
end = 500
period = 4
duration = 30
label = "long sine"
"""


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlClient]:
    client = ControlClient("rig", lockstep=True, heartbeat_timeout_s=3.0,
                           data_dir=tmp_path_factory.mktemp("runs"))
    try:
        assert initialise_rig(client)[0]
        yield client
    finally:
        client.close()


@pytest.fixture
def robot(rig: ControlClient) -> ControlClient:
    """The rig, released and holding, at full feed, whatever the test before left."""
    if rig.latched:
        rig.reset()
        wait_until(lambda: not rig.latched, 10, "the E-stop released")
    rig.hold()
    rig.feed_override(1.0)
    wait_until(lambda: not rig.status().moving and rig.status().feed_override == 1.0, 10,
               "the rig holding at full feed")
    return rig


def checked(robot: ControlClient, body: str, start: int = 1) -> CheckedProgram:
    program = parse_program('name = "test"\nmachine = "rig"\n' + body, "test.toml")
    return check(program, robot.machine, PositionBook(robot.machine),
                 np.array(robot.status().position), start=start)


def saved_meta(robot: ControlClient, stem: str) -> dict:
    return json.loads((robot.data_dir / f"{stem}.json").read_text())["meta"]


def moving_in(robot: ControlClient, runner: Runner, title: str) -> bool:
    visit = runner.current
    return (visit is not None and visit.step.title == title and robot.status().moving
            and robot.status().move_done > 100)


def test_a_program_runs_to_the_end_and_each_move_carries_the_program_run(
        robot: ControlClient) -> None:
    program = checked(robot, """
[[step]]
move = "step"
target = 300
duration = 1
[[step]]
wait = 0.2
[[step]]
feed = 50
[[step]]
move = "ramp"
end = 400
ramp_time = 0.5
total = 1
[[step]]
feed = 100
[[step]]
repeat = 2
[[step.steps]]
go = "home"
speed = 1
[[step.steps]]
go = "park"
speed = 1
""")
    reports: list[object] = []
    runner = Runner(robot, program, on_report=reports.append)
    runner.run()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.state is RunnerState.DONE, outcome
    assert [(r.visit.where, r.status) for r in outcome.results] == [
        ("step 1", "complete"), ("step 2", "ok"), ("step 3", "ok"), ("step 4", "complete"),
        ("step 5", "ok"), ("step 7, pass 1", "complete"), ("step 8, pass 1", "complete"),
        ("step 7, pass 2", "complete"), ("step 8, pass 2", "complete")]
    moved = [r.move is not None for r in outcome.results]
    assert [type(r) for r in reports] == [
        *(kind for move in moved
          for kind in ((StepStarted, MoveStarted, StepDone) if move else (StepStarted,
                                                                           StepDone))),
        ProgramEnded]
    wait, ramp = outcome.results[1], outcome.results[3]
    assert wait.seconds >= 0.2
    # at half feed the ramp's second of path took two on the controller's clock
    assert ramp.move.run.meta["feed"] == [[0.0, 0.5]] and ramp.seconds > 1.9
    assert robot.status().feed_override == 1.0
    moves = [r for r in outcome.results if r.move is not None]
    tags = [saved_meta(robot, r.move.files.stem)["program"] for r in moves]
    assert {t["run_id"] for t in tags} == {runner.run_id}
    assert [(t["step"], t["passes"]) for t in tags] == [(1, []), (4, []), (7, [1]), (8, [1]),
                                                        (7, [2]), (8, [2])]
    assert tags[-1]["name"] == "test" and tags[-1]["title"] == "go to 'park'"
    assert robot.status().position[0] == pytest.approx(10.0, abs=0.5)


def test_single_steps_hold_between_steps_and_run_goes_on_from_there(
        robot: ControlClient) -> None:
    program = checked(robot, """
[[step]]
go = "home"
[[step]]
wait = 0.1
[[step]]
go = "park"
""")
    runner = Runner(robot, program)
    runner.single_step()
    assert runner.wait_idle(END_S)
    assert runner.state is RunnerState.HELD and len(runner.results) == 1
    assert robot.status().position[0] == pytest.approx(600.0, abs=0.5)
    runner.single_step()
    assert runner.wait_idle(END_S) and runner.state is RunnerState.HELD
    assert [r.visit.where for r in runner.results] == ["step 1", "step 2"]
    runner.run()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.complete
    assert [r.visit.where for r in outcome.results] == ["step 1", "step 2", "step 3"]


def test_a_feed_hold_stands_the_move_on_its_path_and_resume_finishes_it(
        robot: ControlClient) -> None:
    runner = Runner(robot, checked(robot, LONG_SINE))
    runner.run()
    wait_until(lambda: moving_in(robot, runner, "long sine"), END_S, "the sine under way")
    runner.pause()
    assert runner.state is RunnerState.PAUSED
    wait_until(lambda: robot.status().paused and robot.status().feed_rate == 0.0, 10,
               "the feed hold")
    held = robot.status()
    wait_until(lambda: robot.status().time_s > held.time_s + 0.5, 10, "half a second held")
    assert robot.status().move_done == held.move_done  # no row further along its path
    runner.resume()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.complete
    [sine] = outcome.results
    assert sine.status == "complete" and sine.move.run.meta["pauses"]


def test_stop_holds_the_move_and_ends_the_program_there(robot: ControlClient) -> None:
    runner = Runner(robot, checked(robot, LONG_SINE + '[[step]]\ngo = "park"\n'))
    runner.run()
    wait_until(lambda: moving_in(robot, runner, "long sine"), END_S, "the sine under way")
    runner.stop()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.state is RunnerState.STOPPED
    [sine] = outcome.results  # park never ran
    assert not sine.ok and sine.status == "program stopped by the operator"
    assert sine.move.files is not None
    assert not robot.status().moving


def test_a_program_starts_from_a_chosen_step(robot: ControlClient) -> None:
    program = checked(robot, """
[[step]]
go = "home"
[[step]]
wait = 0.1
[[step]]
go = "park"
""", start=2)
    outcome = Runner(robot, program)
    outcome.run()
    result = outcome.wait(END_S)
    assert result is not None and result.complete
    assert [r.visit.where for r in result.results] == ["step 2", "step 3"]


def test_an_estop_mid_program_ends_it_with_the_run_saved(robot: ControlClient) -> None:
    runner = Runner(robot, checked(robot, LONG_SINE + '[[step]]\ngo = "park"\n'))
    runner.run()
    wait_until(lambda: moving_in(robot, runner, "long sine"), END_S, "the sine under way")
    robot.estop()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.state is RunnerState.FAILED
    [sine] = outcome.results
    assert sine.status.startswith("estop") and sine.move.files is not None
    assert outcome.reason.startswith("step 1 (long sine): estop")
    assert sine.move.files.json.is_file()


def test_the_operators_wait_lasts_until_proceed(robot: ControlClient) -> None:
    runner = Runner(robot, checked(robot, '[[step]]\nwait = "operator"\n[[step]]\nwait = 0.1\n'))
    runner.run()
    wait_until(lambda: runner.current is not None and runner.current.index == 0, 10,
               "the operator's wait")
    now = robot.status().time_s
    wait_until(lambda: robot.status().time_s > now + 1.0, 10, "a second of waiting")
    assert runner.results == [] and runner.state is RunnerState.RUNNING
    runner.proceed()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.complete and len(outcome.results) == 2


def test_an_answer_as_fast_as_the_prompt_is_not_lost(robot: ControlClient) -> None:
    """The operator's go-on given the moment the wait is announced (a key typed ahead of a
    slow runner thread, as a terminal's line can be) ends the wait."""
    runner = Runner(robot, checked(robot, '[[step]]\nwait = "operator"\n[[step]]\nwait = 0.1\n'))

    def answer(report: object) -> None:
        if isinstance(report, StepStarted) and report.visit.index == 0:
            runner.proceed()

    runner.on_report = answer
    runner.run()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.complete and len(outcome.results) == 2


def test_a_caller_drives_the_steps_itself(robot: ControlClient) -> None:
    runner = Runner(robot, checked(robot, '[[step]]\ngo = "home"\n[[step]]\nwait = 0.1\n'))
    first = runner.run_next()
    assert first is not None and first.status == "complete"
    assert runner.state is RunnerState.RUNNING and runner.current.index == 1
    assert runner.run_next() is not None and runner.state is RunnerState.DONE
    assert runner.run_next() is None


def test_no_step_starts_during_a_feed_hold(robot: ControlClient) -> None:
    """Held during the operator's wait, which the operator then ends: the go to after it
    waits for resume."""
    runner = Runner(robot, checked(robot, '[[step]]\nwait = "operator"\n[[step]]\ngo = "home"\n'
                                          'speed = 1\n[[step]]\ngo = "park"\nspeed = 1\n'))
    runner.run()
    wait_until(lambda: runner.current is not None and runner.current.index == 0, 10,
               "the operator's wait")
    runner.pause()
    runner.proceed()
    wait_until(lambda: len(runner.results) == 1, 10, "the wait's end")
    now = robot.status().time_s
    wait_until(lambda: robot.status().time_s > now + 1.0, 10, "a second held")
    assert runner.state is RunnerState.PAUSED and len(runner.results) == 1
    assert not robot.status().moving
    runner.resume()
    outcome = runner.wait(END_S)
    assert outcome is not None and outcome.complete and len(outcome.results) == 3
