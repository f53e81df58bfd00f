"""Saved runs play again (issue 26 item 6), on a real lockstep controller of each machine:
a run of every kind is recorded and saved, then replayed through ``read_path`` and
``form_plans.path_file``, what ``servodesk move path RUN`` and the Moves tab's path form
call, by any of its files or its stem; the replayed run's desired path is the original's
within the encoder resolution, after the approach it needs. One replay runs through the
command itself. A duty run (the PRBS of the identification, a pulse) is refused, saying why.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient
from control.client import MoveResult
from control.identify.excitation import prbs
from control.motion import form_plans, moves
from control.motion.acceptance import accept
from control.motion.path_files import PathFileError, read_path
from control.motion.plan import MovePlan
from control.motion.robot_model import model_of
from control.recorder import Run, RunFiles, load_run, resolution, save_run
from hw.machine import Machine, load_machine

ROOT = Path(__file__).resolve().parents[2]
Planner = Callable[[ControlClient, Machine, np.ndarray, Path], MovePlan | None]


def _path_file(client: ControlClient, m: Machine, here: np.ndarray, data_dir: Path) -> MovePlan:
    """A CSV path file of two points on the first joint, read as the path form reads it."""
    file = data_dir.parent / f"{m.name}-path.csv"
    name, span = m.joints[0].name, 0.2 * (m.joints[0].upper - m.joints[0].lower)
    file.write_text(f"t,{name}\n0,{here[0]:.4f}\n0.6,{here[0] + span:.4f}\n")
    return form_plans.path_file(m, here, read_path(file, m, tuple(here)), str(file), dt=client.dt)


def _via(cartesian: bool) -> Planner:
    def plan(client: ControlClient, m: Machine, here: np.ndarray, _: Path) -> MovePlan:
        if cartesian:
            x, y, z = model_of(m).pose(here)[:3]
            points = np.array([[x + 20.0, y, z], [x + 20.0, y + 20.0, z]])
        else:
            points = np.array([here + 2.0, here - 1.0])
        return form_plans.via_points(m, here, points, 1.0, cartesian, dt=client.dt)
    return plan


def _cartesian_jog(client: ControlClient, *_: object) -> None:
    return None  # recorded by the client itself (``record``)


def _prbs(client: ControlClient, m: Machine, here: np.ndarray, _: Path) -> MovePlan:
    duty = prbs(m, 1, here, duration=0.4, dt=client.dt).duty
    return MovePlan("tracking_actuate", "PRBS", profile=duty, moving=(1,))


KINDS: dict[str, dict[str, Planner]] = {
    "unimate2000b": {
        "step": lambda c, m, q, _: form_plans.step(m, q, 1, q[1] + 3.0, duration=0.3, dt=c.dt),
        "multi_step": lambda c, m, q, _: form_plans.multi_step(
            m, q, [None, q[1] - 2.0, q[2] + 2.0, None, None, None], duration=0.3, dt=c.dt),
        "ramp": lambda c, m, q, _: form_plans.ramp(m, q, 2, q[2] + 3.0, 0.3, dt=c.dt),
        "sine": lambda c, m, q, _: form_plans.sine(m, q, 3, q[3] + 3.0, 0.4, 0.4, dt=c.dt),
        "end_point": lambda c, m, q, _: form_plans.end_point(
            m, q, *_pose_and_solutions(m, q), 0, 0.4, dt=c.dt),
        "go_to": lambda c, m, q, _: form_plans.go_to(m, q, q + 2.0, 1.0, dt=c.dt),
        "via_points": _via(cartesian=False),
        "cartesian": _via(cartesian=True),
        "path": _path_file,
        "cartesian_jog": _cartesian_jog,
        "tracking_actuate": _prbs,
    },
    "rig": {
        "step": lambda c, m, q, _: form_plans.step(m, q, 0, q[0] + 20.0, duration=0.3, dt=c.dt),
        "multi_step": lambda c, m, q, _: form_plans.sequence(
            m, q, [(q[0] + 20.0, 0.2), (q[0] + 5.0, 0.2)], dt=c.dt),
        "ramp": lambda c, m, q, _: form_plans.ramp(m, q, 0, q[0] + 30.0, 0.3, dt=c.dt),
        "sine": lambda c, m, q, _: form_plans.sine(m, q, 0, q[0] + 20.0, 0.4, 0.4, dt=c.dt),
        "go_to": lambda c, m, q, _: form_plans.go_to(m, q, q + 15.0, 1.0, dt=c.dt),
        "path": _path_file,
        "set_pulse": lambda c, m, q, _: form_plans.pulse(m, 30.0, 0.1, dt=c.dt),
    },
}
DUTY_KINDS = ("tracking_actuate", "set_pulse")


def _pose_and_solutions(m: Machine, here: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    model = model_of(m)
    pose = model.pose(here)
    pose[0] += 30.0
    return pose, form_plans.end_point_solutions(model, pose, here)


@pytest.fixture(scope="module", params=list(KINDS))
def lockstep(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
             ) -> Iterator[ControlClient]:
    """One lockstep controller of each machine for the module, its runs in a fresh directory."""
    client = ControlClient(request.param, lockstep=True, heartbeat_timeout_s=3.0,
                           data_dir=tmp_path_factory.mktemp(request.param) / "runs")
    if request.param == "rig":  # a move needs the encoder zeroed on the bottom stop
        client.initialise()
        assert str(client.wait_event("initialised", 60.0).payload["status"]).startswith(
            "complete")
    yield client
    client.close()


@pytest.fixture(scope="module")
def recorded(lockstep: ControlClient) -> dict[str, MoveResult]:
    """A saved run of every kind the machine has, one after the other."""
    client, m = lockstep, lockstep.machine
    runs = {}
    for kind, planner in KINDS[m.name].items():
        here = np.array(client.status().position)
        plan = planner(client, m, here, client.data_dir)
        handle = (client.jog_cartesian([0.0, 15.0, 0.0, 0.0, 0.0, 0.0]) if plan is None
                  else client.run(plan))
        result = client.wait(handle, 60.0)
        assert result.files is not None and result.run.kind == kind, (kind, result.status)
        runs[kind] = result
    return runs


def replays(result: MoveResult) -> list[str]:
    """Every name of a saved run the path form and ``servodesk move path`` take."""
    files = result.files
    assert files is not None
    return [str(files.json), str(files.csv), str(files.tsv), str(files.json.with_suffix(""))]


def original_path(result: MoveResult) -> np.ndarray:
    """The run's desired path as saved: the rows of its path, not its settle's."""
    assert result.files is not None
    run = load_run(result.files.json)
    return run.desired[:run.meta["path_samples"]]


def test_every_run_with_a_desired_path_plays_again_as_it_was(
        lockstep: ControlClient, recorded: dict[str, MoveResult]) -> None:
    client, m = lockstep, lockstep.machine
    counts = np.array(resolution(m))
    for kind, result in recorded.items():
        if kind in DUTY_KINDS:
            continue
        here = np.array(client.status().position)
        read = [read_path(name, m, tuple(here)) for name in replays(result)]
        for points in read[1:]:  # a table, the stem: the run, through its JSON
            np.testing.assert_array_equal(points.q, read[0].q)
        plan = form_plans.path_file(m, here, read[0], replays(result)[0], dt=client.dt)
        assert plan.kind == (kind if kind in ("step", "multi_step") else "path"), kind
        again = client.wait(client.run(plan), 60.0)
        assert again.files is not None, (kind, again.status)
        replayed = load_run(again.files.json)
        approach = replayed.meta["approach_samples"]
        want = original_path(result)
        played = replayed.desired[approach:approach + len(want)]
        assert played.shape == want.shape, kind
        assert np.all(np.abs(played - want) <= counts), (kind, np.abs(played - want).max(0))
        moved_away = np.any(np.abs(here - want[0]) > [j.tolerance for j in m.joints])
        assert (approach > 0) == moved_away, (kind, approach)  # the approach a path file gets
        assert replayed.meta["replays"].startswith(f"the {kind} run ")


def test_a_runs_tables_alone_play_as_a_path_on_the_sample_grid(
        lockstep: ControlClient, recorded: dict[str, MoveResult], tmp_path: Path) -> None:
    """Copied without its JSON, a smooth run's CSV (its jittered times ignored) and its TSV
    (19 or 4 fields a line) are its desired rows, one a sample; a step run's are refused as a
    path, naming the JSON that plays it as a step."""
    m = lockstep.machine
    for kind in ("ramp", "step"):
        files = recorded[kind].files
        assert files is not None
        run = load_run(files.json)
        for table in (files.csv, files.tsv):
            alone = tmp_path / table.name
            alone.write_bytes(table.read_bytes())
            if kind == "step":
                with pytest.raises(PathFileError, match=r"give the run's \.json"):
                    read_path(alone, m, tuple(run.desired[0]))
                continue
            points = read_path(alone, m, tuple(run.desired[0]))
            np.testing.assert_array_equal(points.q, run.desired)
            np.testing.assert_allclose(points.t, np.arange(run.samples) * m.sample_time_s)


def test_a_duty_run_is_refused_saying_it_has_no_desired_path(
        lockstep: ControlClient, recorded: dict[str, MoveResult]) -> None:
    m = lockstep.machine
    (kind,) = set(recorded) & set(DUTY_KINDS)
    for name in replays(recorded[kind]):
        with pytest.raises(PathFileError, match=f"the {kind} run .* has no desired path to "
                                                "play: .* open loop"):
            read_path(name, m, tuple(np.zeros(m.n_joints)))


def test_servodesk_move_path_plays_a_run_again(lockstep: ControlClient,
                                               recorded: dict[str, MoveResult]) -> None:
    """The command itself, a real process, given the run by its stem in --data-dir."""
    m = lockstep.machine
    files = recorded["ramp"].files
    assert files is not None
    done = subprocess.run(
        [sys.executable, "-m", "app", "move", "path", files.stem, "--lockstep", "--json",
         "--data-dir", str(files.json.parent), "--machine", m.name,
         *(["--initialise"] if m.encoder_kind != "gray" else [])],  # the rig zeroes first
        capture_output=True, text=True, timeout=120, cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    assert out["kind"] == "path" and out["title"].startswith("replay of the ramp run")
    replayed = load_run(RunFiles.from_json(Path(out["run"]["json"])).json)
    approach = replayed.meta["approach_samples"]
    want = original_path(recorded["ramp"])
    played = replayed.desired[approach:approach + len(want)]
    assert np.all(np.abs(played - want) <= np.array(resolution(m)))


def test_a_run_with_jittered_times_plays_at_max_accel_on_its_sample_grid(tmp_path: Path
                                                                         ) -> None:
    """A real-time run's times are when each sample was taken (±0.3 ms here); its desired
    rows, a ramp of every joint at max_accel, play on the grid its JSON names, not at those
    times, which would read as accelerations far past max_accel (fast: no controller)."""
    m = load_machine("unimate2000b")
    here = np.array([1508.4405000000002, 0.0055000000000120, 6.4968, -0.00488, 2.49876, 0.1])
    end = here + np.array([300.0, 40.0, 15.0, 30.0, 20.0, 10.0])
    path = moves.ramp(here, end, moves.min_ramp_time(here, end, m), machine=m)
    grid = np.arange(len(path)) * m.sample_time_s
    jitter = np.random.default_rng(5).uniform(-3e-4, 3e-4, len(path))
    run = Run.from_machine(m, "ramp", "complete", m.track, grid + jitter, path, path,
                           np.zeros_like(path), meta={"path_samples": len(path)})
    files = save_run(run, tmp_path)
    for name in (files.csv, files.tsv, files.json):
        points = read_path(name, m, tuple(here))
        np.testing.assert_array_equal(points.t, grid)
        assert np.all(np.abs(points.q - path) <= 0.5 * 10.0 ** -np.array(
            run.desired_decimals()) + 1e-9)
        plan = form_plans.path_file(m, here, points, str(name), dt=m.sample_time_s)
        accept(plan, here, m, m.sample_time_s)  # the rules a move is sent under
