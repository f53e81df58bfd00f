"""``servodesk move KIND …``: one move from the command line, for scripts and CI.

The fields are the Moves forms' (``control.motion.fields``, ``form_plans``), checked with
the same rules and planned the same way; the move gets the approach the TUI gives
(``ControlClient.run``). It starts the control process, runs the move, saves the run in
the data directory, prints the summary (or, with ``--json``, one JSON object) and exits:

- 0: the move was followed to its end and came in position (every joint within its goal
  tolerance of the end, stopped, within the machine's goal_time: ``docs/motion.md``);
- 1: it ended otherwise (unsettled, a fault, the E-stop, the controller lost); its run is
  saved;
- 2: bad input, nothing moved (the message on stderr names the option and the fix).

Ctrl+C (SIGINT, and SIGTERM) during the move is the E-stop: latched at once, the run
recorded so far is saved, exit 1. Progress goes to stderr (``settling`` once the path is
over and the arm is coming in position), the summary and the settle to stdout.
``--lockstep`` runs the simulator as fast as the controller computes, not in real time
(scripts, tests); an I/O board keeps real time, so ``--backend serial`` refuses it.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from app.cli_options import ALL, global_options, machine_for
from app.run_text import summary_table
from control.motion import form_plans
from control.motion.fields import (
    DWELL_S,
    MAX_SEQUENCE,
    PULSE_DUTY_PCT,
    PULSE_MAX_S,
    PULSE_S,
    RAMP_TIME_S,
    SINE_DURATION_S,
    SINE_PERIOD_S,
    VIA_SPEED,
    FieldError,
    NumberRule,
    count_rule,
    duty_rule,
    fraction_rule,
    pose_rule,
    position_rule,
    seconds_rule,
)
from control.motion.plan import SETTLE_COLUMNS, MovePlan, result_records, settle_rows
from control.rt.layout import Flag
from control.timing import Timing
from hw.machine import Machine, MachineError

if TYPE_CHECKING:
    from control.client import ControlClient, MoveHandle, MoveResult

POSE_OPTIONS = (("x", "mm"), ("y", "mm"), ("z", "mm"), ("gamma", "°"), ("beta", "°"),
                ("alpha", "°"))
INITIALISE_S = 120.0  # the rig's ram from its top to the bottom stop at 20 % takes ~30 s
START_WAIT_S = 10.0  # a move the controller took is running within a few ticks
# A lockstep controller computes flat out on a core: beside it on a loaded machine this
# process's heartbeat thread may wait past the 0.25 s a real-time run allows; the simulated
# arm drives nothing, so the controller may wait longer before it holds.
LOCKSTEP_HEARTBEAT_S = 3.0

DONE, ENDED, BAD_INPUT = 0, 1, 2


class BadInput(ValueError):
    """What was given cannot make a move; the message names the option and the fix."""


@dataclass(frozen=True)
class Kind:
    """A ``servodesk move`` subcommand: its help and how it plans from the options."""

    name: str
    help: str
    plan: Callable[[argparse.Namespace, Machine, np.ndarray, float], MovePlan]


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "move", help="run one move headless, save its run, print its summary",
        description="Run one move on a new controller with the Moves forms' fields, save the "
                    "run in the data directory and print its summary. Exit 0 done, 1 ended by "
                    "a fault or the E-stop (Ctrl+C), 2 bad input.")
    kinds = p.add_subparsers(title="kinds", metavar="KIND", required=True)
    common = _common_options()
    for add in (_step, _ramp, _sine, _multistep, _endpoint, _path, _via, _goto, _pulse):
        add(kinds, common)


def _common_options() -> argparse.ArgumentParser:
    """Options every kind takes: the global ones after the kind too, and the move's own."""
    common = argparse.ArgumentParser(add_help=False, parents=[global_options(*ALL)])
    common.add_argument("--json", action="store_true",
                        help="print one JSON object: status, run files, metrics")
    common.add_argument("--initialise", action="store_true",
                        help="rig: drive the ram to the bottom stop and zero the encoder first "
                             "(every `servodesk move` starts a new controller, not zeroed)")
    common.add_argument("--lockstep", action="store_true",
                        help="simulator only: run the controller as fast as it computes, not in "
                             "real time (scripts, tests)")
    common.add_argument("--reduced", action="store_true",
                        help="reduced speed (ISO 10218-1's T1): the controller keeps the tool at "
                             "most 250 mm/s and each joint at most its jog speed (default: "
                             "automatic, full speed); a pulse, open-loop duty, is refused")
    common.add_argument("--plot", action="store_true",
                        help="after the move, draw desired, actual and duty of each joint that "
                             "moved, sized to the terminal (on stderr with --json)")
    return common


def _kind(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser, kind: Kind
          ) -> argparse.ArgumentParser:
    p = kinds.add_parser(kind.name, parents=[common], help=kind.help, description=kind.help)
    p.set_defaults(func=run, kind=kind)
    return p


def _joint_options(p: argparse.ArgumentParser, *fields: str) -> None:
    p.add_argument("--joint", help="joint key, name or number from 1 (default: the first)")
    for name in fields:
        p.add_argument(f"--{name}", default="", required=name in ("target", "end"),
                       help=f"{name} position, mm or °" + (" (default: where the joint is)"
                                                           if name == "start" else ""))


def _step(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("step", "one joint steps to a target; the others hold "
                                          "(option.c SingleStepInput)", _plan_step))
    _joint_options(p, "start", "target")
    p.add_argument("--duration", default="", help="s, the whole run (default: travel + 2 s)")


def _ramp(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("ramp", "from a start to an end at constant speed, then hold "
                                          "(function.c RampInput)", _plan_ramp))
    _joint_options(p, "start", "end")
    p.add_argument("--ramp-time", default=f"{RAMP_TIME_S:g}", help="s (default %(default)s)")
    p.add_argument("--total", default="", help="s, the whole run (default: ramp time + 2 s)")


def _sine(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("sine", "start + (end − start)/2·(1 − cos 2πt/T) "
                                          "(function.c Sinewave)", _plan_sine))
    _joint_options(p, "start", "end")
    p.add_argument("--period", default=f"{SINE_PERIOD_S:g}", help="T, s (default %(default)s)")
    p.add_argument("--duration", default=f"{SINE_DURATION_S:g}",
                   help="s (default %(default)s)")


def _multistep(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind(
        "multistep", "every joint steps to its target at once (option.c MultiStepInput); on the "
                     "rig, a sequence of positions and dwell times (function.c MultiStep)",
        _plan_multistep))
    p.add_argument("--targets", help="every joint's target, comma-separated (six-joint "
                                     "machines)")
    p.add_argument("--step", action="append", default=[], metavar="POSITION[:DWELL]",
                   help=f"rig: one step of the sequence, dwell in s (default {DWELL_S:g}); "
                        f"repeat, up to {MAX_SEQUENCE}")
    p.add_argument("--duration", default="", help="s, multi-step's whole run "
                                                  "(default: travel + 2 s)")


def _endpoint(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("endpoint", "a joint-space ramp to an end-effector pose "
                                              "(section 4.3), on the inverse solution chosen",
                                  _plan_endpoint))
    for name, unit in POSE_OPTIONS:
        p.add_argument(f"--{name}", default=None, help=f"{unit} (default: the current pose's)")
    p.add_argument("--solution", default="1",
                   help="which inverse solution, 1 = nearest the current position (default)")
    p.add_argument("--ramp-time", default="", help="s (default: at half the slowest joint's "
                                                   "max speed, at least 0.5 s)")


def _path(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("path", "a path from a file: a CSV with a header of joint "
                                          "names, or the thesis's time/position TSV; or a "
                                          "saved run's desired path, played again as the "
                                          "move it was",
                                  _plan_path))
    p.add_argument("file", metavar="FILE",
                   help="path.csv or path.tsv; or a saved run: any of its files, its stem in "
                        "--data-dir (as `servodesk runs list` names it), or latest")


def _via(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("via", "a smooth path from here through points (section "
                                         "6.4), in joint space or on the tool's x y z",
                                  _plan_via))
    p.add_argument("--point", action="append", default=[], metavar="VALUES",
                   help="one point: every joint's position (or x y z with --cartesian), "
                        "separated by spaces or commas; repeat")
    p.add_argument("--cartesian", action="store_true",
                   help="points are the tool's x y z in mm, γ and β held (Unimate)")
    p.add_argument("--speed", default=f"{VIA_SPEED:g}",
                   help="fraction of every joint's max speed (default %(default)s)")


def _goto(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("goto", "a joint-space move to a position at a fraction of "
                                          "every joint's max speed (ControlClient.go_to)",
                                  _plan_goto))
    p.add_argument("--targets", required=True, help="every joint's position, comma-separated")
    p.add_argument("--speed", default=f"{VIA_SPEED:g}",
                   help="fraction of every joint's max speed (default %(default)s)")


def _pulse(kinds: argparse._SubParsersAction, common: argparse.ArgumentParser) -> None:
    p = _kind(kinds, common, Kind("pulse", "open loop: a constant duty for a time, recorded "
                                           "(function.c SetPulse); the first joint",
                                  _plan_pulse))
    p.add_argument("--duty", default=f"{PULSE_DUTY_PCT:g}", help="%% (default %(default)s)")
    p.add_argument("--duration", default=f"{PULSE_S:g}", help="s (default %(default)s)")


# -- the fields, checked by the forms' rules ---------------------------------------------


def _value(option: str, rule: NumberRule, text: str | None) -> float | None:
    try:
        return rule.parse(text or "")
    except FieldError as exc:
        raise BadInput(f"--{option}: {exc}") from None


def _joint(args: argparse.Namespace, machine: Machine) -> int:
    text = args.joint
    if text is None:
        return 0
    if text.isdigit() and 1 <= int(text) <= machine.n_joints:
        return int(text) - 1
    try:
        return machine.joint_index(text)
    except KeyError as exc:
        raise BadInput(f"--joint: {exc.args[0]}, or a number 1…{machine.n_joints}") from None


def _joint_vector(option: str, text: str, machine: Machine, what: str) -> list[float]:
    parts = text.replace(",", " ").split()
    if len(parts) != machine.n_joints:
        names = ", ".join(j.name for j in machine.joints)
        raise BadInput(f"--{option}: {len(parts)} values; give {machine.n_joints}, "
                       f"comma-separated, in joint order ({names})")
    return [_value(option, position_rule(joint, machine, what), part)
            for joint, part in zip(machine.joints, parts, strict=True)]


def _plan_step(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
               ) -> MovePlan:
    j = _joint(args, machine)
    joint = machine.joints[j]
    start = _value("start", position_rule(joint, machine, "start", optional=True), args.start)
    target = _value("target", position_rule(joint, machine, "target"), args.target)
    duration = _value("duration", seconds_rule("duration", optional=True), args.duration)
    return form_plans.step(machine, here, j, target, start, duration, dt=dt)


def _plan_ramp(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
               ) -> MovePlan:
    j = _joint(args, machine)
    joint = machine.joints[j]
    start = _value("start", position_rule(joint, machine, "start", optional=True), args.start)
    end = _value("end", position_rule(joint, machine, "end"), args.end)
    ramp_time = _value("ramp-time", seconds_rule("ramp time"), args.ramp_time)
    total = _value("total", seconds_rule("total duration", optional=True), args.total)
    return form_plans.ramp(machine, here, j, end, ramp_time, start, total, dt=dt)


def _plan_sine(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
               ) -> MovePlan:
    j = _joint(args, machine)
    joint = machine.joints[j]
    start = _value("start", position_rule(joint, machine, "start", optional=True), args.start)
    end = _value("end", position_rule(joint, machine, "end"), args.end)
    period = _value("period", seconds_rule("period"), args.period)
    duration = _value("duration", seconds_rule("duration"), args.duration)
    return form_plans.sine(machine, here, j, end, period, duration, start, dt=dt)


def _plan_multistep(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
                    ) -> MovePlan:
    if machine.n_joints == 1:
        if args.targets is not None:
            raise BadInput("--targets: a one-joint machine runs a sequence: give --step "
                           "POSITION[:DWELL] once per step")
        return _plan_sequence(args.step, machine, here, dt)
    if args.step:
        raise BadInput(f"--step: a sequence is the rig's; on {machine.name} give --targets, "
                       "one value per joint")
    if args.targets is None:
        raise BadInput("--targets: give every joint's target, comma-separated")
    targets = _joint_vector("targets", args.targets, machine, "target")
    duration = _value("duration", seconds_rule("duration", optional=True), args.duration)
    return form_plans.multi_step(machine, here, targets, duration, dt=dt)


def _plan_sequence(texts: list[str], machine: Machine, here: np.ndarray, dt: float
                   ) -> MovePlan:
    _value("step", count_rule("number of steps", MAX_SEQUENCE), str(len(texts)))
    joint = machine.joints[0]
    steps = []
    for i, text in enumerate(texts, 1):
        position, _, dwell = text.partition(":")
        steps.append((
            _value("step", position_rule(joint, machine, f"step {i} position"), position),
            _value("step", seconds_rule(f"step {i} dwell"), dwell or f"{DWELL_S:g}")))
    return form_plans.sequence(machine, here, steps, dt=dt)


def _plan_endpoint(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
                   ) -> MovePlan:
    from control.motion.robot_model import model_of

    model = model_of(machine)
    if model is None:
        raise BadInput(f"endpoint: machine {machine.name} has no kinematic model; use step, "
                       "ramp or path")
    pose = model.pose(here)  # the form's fields start as the current pose
    for i, (name, unit) in enumerate(POSE_OPTIONS):
        if (text := getattr(args, name)) is not None:
            pose[i] = _value(name, pose_rule(name, unit), text)
    try:
        solutions = form_plans.end_point_solutions(model, pose, here,
                                                   ": leave --x … --alpha out")
    except ValueError as exc:
        raise BadInput(f"--x … --alpha: {exc}") from None
    k = int(_value("solution", count_rule("solution", len(solutions)), args.solution)) - 1
    ramp_time = _value("ramp-time", seconds_rule("ramp time", optional=True), args.ramp_time)
    return form_plans.end_point(machine, here, pose, solutions, k, ramp_time, dt=dt)


def _plan_path(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
               ) -> MovePlan:
    from control.motion.path_files import PathFileError, read_path

    try:
        points = read_path(_path_file(args), machine, tuple(here))
    except PathFileError as exc:
        raise BadInput(f"FILE: {exc}") from None
    return form_plans.path_file(machine, here, points, args.file, dt=dt)


def _path_file(args: argparse.Namespace) -> Path:
    """FILE as given, or the saved run it names as ``servodesk runs`` does: its stem in the
    data directory, or ``latest``, the newest there."""
    from control.recorder import default_data_dir, list_runs

    given = Path(args.file).expanduser()
    if given.exists():
        return given
    data_dir = Path(args.data_dir).expanduser() if args.data_dir else default_data_dir()
    if args.file == "latest":
        runs = [info for info in list_runs(data_dir) if not info.damaged]
        if not runs:
            raise BadInput(f"FILE latest: no saved run in {data_dir} (--data-dir)")
        return runs[0].files.json
    stem = data_dir / f"{args.file}.json"
    return stem if stem.is_file() else given


def _plan_via(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
              ) -> MovePlan:
    from control.motion.robot_model import has_unimate_model

    if args.cartesian and not has_unimate_model(machine):
        raise BadInput(f"--cartesian: machine {machine.name} has no kinematic model; give "
                       "joint positions")
    fraction = _value("speed", fraction_rule("speed fraction"), args.speed)
    try:
        points = form_plans.via_point_rows("\n".join(args.point), machine, args.cartesian)
    except ValueError as exc:
        raise BadInput(f"--point: {exc}") from None
    return form_plans.via_points(machine, here, points, fraction, args.cartesian, dt=dt)


def _plan_goto(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
               ) -> MovePlan:
    target = _joint_vector("targets", args.targets, machine, "target")
    speed = _value("speed", fraction_rule("speed fraction"), args.speed)
    return form_plans.go_to(machine, here, target, speed, dt=dt)


def _plan_pulse(args: argparse.Namespace, machine: Machine, here: np.ndarray, dt: float
                ) -> MovePlan:
    if machine.n_joints != 1:
        raise BadInput(f"pulse: the set pulse is the rig's open-loop test; machine "
                       f"{machine.name} has {machine.n_joints} joints")
    duty = _value("duty", duty_rule(), args.duty)
    duration = _value("duration", seconds_rule("duration", high=PULSE_MAX_S), args.duration)
    return form_plans.pulse(machine, duty, duration, dt=dt)


# -- running -------------------------------------------------------------------------------


class EStopOnSignal:
    """SIGINT and SIGTERM during the move press the E-stop (the client latches it at once,
    never waiting); the main loop says so and waits for the run to be saved."""

    def __init__(self, client: ControlClient) -> None:
        self.client = client
        self.pressed = 0
        self.previous = {sig: signal.signal(sig, self) for sig in (signal.SIGINT, signal.SIGTERM)}

    def __call__(self, signum: int, frame: object) -> None:
        self.client.estop()
        self.pressed += 1

    def restore(self) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)


def run(args: argparse.Namespace) -> int:
    try:
        return _run(args)
    except BadInput as exc:
        print(f"servodesk: {exc}", file=sys.stderr)
        return BAD_INPUT
    except KeyboardInterrupt:  # before the move was sent (starting, initialising)
        print("servodesk: interrupted before the move started: the controller is stopped, "
              "every valve closed; no run", file=sys.stderr)
        return ENDED


def _run(args: argparse.Namespace) -> int:
    from control.recorder import default_data_dir

    kind: Kind = args.kind
    try:
        machine = machine_for(args)
    except MachineError as exc:
        raise BadInput(str(exc)) from None
    check_backend(args)
    _check_fields(args, kind, machine)
    if args.reduced and kind.name == "pulse":
        raise BadInput("--reduced: a pulse is open-loop duty, which reduced speed cannot hold "
                       "to 250 mm/s; leave --reduced out to run it at full speed")
    data_dir = Path(args.data_dir).expanduser() if args.data_dir else default_data_dir()
    check_writable(data_dir)
    client = start_client(args, machine, data_dir)
    try:
        return _move(args, kind, client, machine)
    finally:
        client.close()


def _check_fields(args: argparse.Namespace, kind: Kind, machine: Machine) -> None:
    """Check the fields before a controller starts, as the forms do before it reports: from
    the middle of every joint's range. Only a field's own error counts here; the plan from
    where the joints are decides the rest."""
    middle = np.array([(j.lower + j.upper) / 2 for j in machine.joints])
    try:
        kind.plan(args, machine, middle, machine.sample_time_s)
    except BadInput:
        raise
    except ValueError:
        pass


def check_backend(args: argparse.Namespace) -> None:
    """The backend options of a command that starts a controller (``move``, ``run``)."""
    if args.backend == "serial" and not args.port:
        raise BadInput("--port: --backend serial needs the I/O board's URL (a device, the "
                       "emulator's pty path or socket://HOST:PORT)")
    if args.backend == "serial" and args.lockstep:
        raise BadInput("--lockstep: an I/O board runs in real time; leave --lockstep out, or "
                       "run the simulator (--backend sim)")


def start_client(args: argparse.Namespace, machine: Machine, data_dir: Path) -> ControlClient:
    """The controller a command runs on, as its options say (``--lockstep``, ``--reduced``…).

    In real time the command then carries the controller's heartbeat and Ctrl+C's E-stop as
    the TUI does, so it takes the TUI's priority first (its client's threads inherit it):
    at its own, a busy machine can delay the heartbeat past 250 ms, and the move is held."""
    from app.priority import raise_priority
    from control.client import ControlClient, ControllerError

    pace = ({"lockstep": True, "heartbeat_timeout_s": LOCKSTEP_HEARTBEAT_S} if args.lockstep
            else {})
    if not args.lockstep:
        notice = raise_priority(who="servodesk").notice
        if notice:
            print(f"servodesk: {notice}", file=sys.stderr)
    try:
        return ControlClient(machine, args.backend, port=args.port, seed=args.seed,
                             data_dir=data_dir, timing=Timing(args.timing, args.interrupt_ms,
                                                              tuple(args.slip)),
                             speed_mode="reduced" if args.reduced else "automatic", **pace)
    except (ControllerError, OSError, ValueError) as exc:
        raise BadInput(f"cannot start the controller: {exc}") from None


def check_writable(data_dir: Path) -> None:
    try:
        data_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BadInput(f"--data-dir: cannot create {data_dir}: {exc.strerror or exc}") from None
    if not os.access(data_dir, os.W_OK | os.X_OK):
        raise BadInput(f"--data-dir: {data_dir} is not writable: choose another directory")


def _move(args: argparse.Namespace, kind: Kind, client: ControlClient, machine: Machine) -> int:
    from control.client import ControllerError

    if kind.name != "pulse" and not client.status().flags & Flag.HOMED:
        if not args.initialise:
            raise BadInput(f"--initialise: the {machine.title}'s encoder is not zeroed (every "
                           "`servodesk move` starts a new controller); add --initialise to drive "
                           "to the bottom stop and zero it first")
        if not _initialise(client):
            return ENDED
    here = np.array(client.status().position)
    try:
        plan = kind.plan(args, machine, here, client.dt)
    except ValueError as exc:  # BadInput, or the plan's own refusal naming the field
        raise BadInput(str(exc)) from None
    estop = EStopOnSignal(client)
    try:
        try:
            handle = client.run(plan)
        except ValueError as exc:  # the acceptance rules: nothing sent
            raise BadInput(str(exc)) from None
        except ControllerError as exc:
            print(f"servodesk: {exc}", file=sys.stderr)
            return ENDED
        _announce(client, handle, estop)
        announced = settling = False
        while not handle.done.wait(0.05) or (estop.pressed and not announced):
            if not settling and _settling(client, handle):
                settling = True
                print(f"settling: holding the end until every joint is in position (at most "
                      f"{machine.goal_time_s:g} s)", file=sys.stderr, flush=True)
            if estop.pressed and not announced:
                announced = True
                print("servodesk: E-stop: every valve closed and latched; saving the run "
                      "recorded so far", file=sys.stderr, flush=True)
    finally:
        estop.restore()
    result = handle.result
    assert result is not None
    _report(args, result, machine)
    if args.plot:
        from app.plotting.terminal import print_response

        sys.stdout.flush()
        print_response(result.run, sys.stderr if args.json else sys.stdout)
    return DONE if result.complete and result.files is not None else ENDED


def _settling(client: ControlClient, handle: MoveHandle) -> bool:
    from control.client import ControllerError

    try:
        status = client.status()
    except (ControllerError, TimeoutError):
        return False
    return status.move_id == handle.move_id and status.settling


def _initialise(client: ControlClient) -> bool:
    """The rig's initialise (section 3.5); False, said on stderr, if it did not complete."""
    print("initialising: driving down to the bottom stop…", file=sys.stderr, flush=True)
    client.initialise()
    try:
        status = str(client.wait_event("initialised", INITIALISE_S).payload["status"])
    except TimeoutError:
        status = f"not finished within {INITIALISE_S:g} s"
    if status.startswith("complete"):
        return True
    print(f"servodesk: initialise: {status}", file=sys.stderr)
    return False


def _announce(client: ControlClient, handle: MoveHandle, estop: EStopOnSignal) -> None:
    """Say on stderr that the move runs, once the controller follows it (or has: in lockstep
    a short move may be over before the first look)."""
    deadline = time.monotonic() + START_WAIT_S
    while (not handle.done.is_set() and time.monotonic() < deadline
           and client.status().move_id != handle.move_id):
        time.sleep(0.005)
    if handle.done.is_set() and not (handle.result and handle.result.run.samples):
        return
    plan, dt = handle.plan, client.dt
    approach = f" (a {plan.approach * dt:.2f} s approach first)" if plan.approach else ""
    print(f"running {plan.title}: {plan.samples * dt:.2f} s{approach}; Ctrl+C is the E-stop",
          file=sys.stderr, flush=True)


def _report(args: argparse.Namespace, result: MoveResult, machine: Machine) -> None:
    summaries = result.summaries()
    plan = result.plan
    assert plan is not None
    files = result.files
    if result.save_error:
        print(f"servodesk: {result.save_error}", file=sys.stderr)
    if args.json:
        print(json.dumps({
            "status": result.status, "complete": result.complete,
            "unsettled": result.unsettled, "settle": result.settle or None, "kind": plan.kind,
            "title": plan.title, "machine": machine.name, "backend": args.backend,
            "speed_mode": result.run.meta.get("speed_mode"),
            "samples": result.run.samples, "path_samples": plan.samples,
            "duration_s": result.run.samples * result.run.sample_time_s,
            "approach_s": plan.approach * result.run.sample_time_s,
            "run": None if files is None else {
                "stem": files.stem, "json": str(files.json), "csv": str(files.csv),
                "tsv": str(files.tsv)},
            "save_error": result.save_error or None,
            "metrics": result_records(summaries),
        }, ensure_ascii=False, allow_nan=False))
        return
    print(f"{plan.title}: {result.status}")
    print(f"saved as {files.json} (and .csv.gz, .tsv.gz)" if files is not None else "not saved")
    if plan.approach:
        print(f"a {plan.approach * result.run.sample_time_s:.2f} s approach to the start came "
              "first (left out of the summary)")
    print("\n".join(summary_table(summaries)))
    print("\n".join(_settle_table(result, machine)))


def _settle_table(result: MoveResult, machine: Machine) -> list[str]:
    """When each joint came in position after the path, and its error at the end."""
    rows = settle_rows(result.settle, machine)
    if not rows:
        return []
    cells = [SETTLE_COLUMNS, *rows]
    widths = [max(len(row[c]) for row in cells) for c in range(len(SETTLE_COLUMNS))]
    ended = f"the path ended {result.settle.get('path_end_s', 0):.2f} s into the run"
    head = (f"\nin position after the path ({ended}):" if result.complete else
            f"\nUNSETTLED: not in position {result.settle.get('goal_time_s')} s after the "
            f"path ({ended}):")
    return [head, *("  ".join(cell.ljust(w) if c == 0 else cell.rjust(w)
                              for c, (cell, w) in enumerate(zip(row, widths, strict=True)))
                    .rstrip() for row in cells)]
