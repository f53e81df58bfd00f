"""The plan of a program's move-making steps (go, line, move) from where the joints are,
with the Moves forms' fields and rules (``control.motion.fields``, ``form_plans``), mapped
from the step's keys as ``servodesk move`` maps its options (``app/cli_move.py``).

``plan(step, …)`` returns the ``MovePlan`` (None for a go to where the joints are: no
move to make; the rig's initialise is a command, not a plan: ``initialises``) or raises
``StepProblem`` naming the key whose value is wrong (its file line) and the fix; the check
and the runner both plan here, so they refuse alike.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

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
from control.motion.plan import MovePlan
from control.program.model import GoTo, Line, Move, Step
from control.program.parse import keyed, parse_number
from hw.machine import Machine

POSE_KEYS = (("x", "mm"), ("y", "mm"), ("z", "mm"), ("gamma", "°"), ("beta", "°"),
             ("alpha", "°"))
THERE = 1e-6  # mm, deg: a go to a position the joints are at is no move
Positions = Callable[[str], tuple[float, ...]]  # a position's joints by name; ValueError: none


class StepProblem(ValueError):
    """A step cannot be planned; ``key`` names the step's key at fault ('' for the step)."""

    def __init__(self, key: str, text: str) -> None:
        super().__init__(text)
        self.key = key


def plan(step: Step, machine: Machine, here: np.ndarray, dt: float, positions: Positions,
         base: Path) -> MovePlan | None:
    """The move ``step`` makes from the joints ``here``; a path file's name is relative to
    ``base`` (the program's folder)."""
    if isinstance(step, GoTo):
        target = _position(positions, step.position, "go")
        return _go_to(machine, here, target, step.speed, dt, "")
    if isinstance(step, Line):
        from control.program.tool_line import tool_line

        to = _position(positions, step.position, "line") if step.position else None
        return _planned("line", lambda: tool_line(machine, here, step.pose, to, step.speed,
                                                  dt=dt))
    assert isinstance(step, Move)
    if initialises(step):
        raise StepProblem("move", "initialise is a command, not a move: see initialises()")
    return _KINDS[step.kind](_Fields(step.fields, machine), machine, here, dt, base)


def initialises(step: Step, machine: Machine | None = None) -> bool:
    """Whether ``step`` is the rig's initialise (section 3.5: down to the bottom stop, the
    encoder zeroed there); StepProblem on a machine whose encoders need none."""
    if not (isinstance(step, Move) and step.kind == "initialise"):
        return False
    if machine is not None and machine.encoder_kind != "quadrature":
        raise StepProblem("move", f"initialise zeroes the rig's incremental encoder; machine "
                                  f"{machine.name}'s encoders are absolute: remove the step")
    return True


def _go_to(machine: Machine, here: np.ndarray, target: tuple[float, ...] | list[float],
           speed: float, dt: float, key: str) -> MovePlan | None:
    """A go to, or None when the joints are there already (no move to make)."""
    start = np.clip(here, machine.lower, machine.upper)
    if np.allclose(start, np.asarray(target, dtype=float), rtol=0.0, atol=THERE):
        return None
    return _planned(key, lambda: form_plans.go_to(machine, here, target, speed, dt=dt))


def _position(positions: Positions, name: str, key: str) -> tuple[float, ...]:
    try:
        return positions(name)
    except ValueError as exc:
        raise StepProblem(key, str(exc)) from None


def _planned(key: str, make: Callable[[], MovePlan]) -> MovePlan:
    try:
        return make()
    except StepProblem:
        raise
    except ValueError as exc:
        raise StepProblem(key, str(exc)) from None


class _Fields:
    """A move step's keys, read by the forms' rules (errors name the key)."""

    def __init__(self, fields: Mapping[str, object], machine: Machine) -> None:
        self.fields = fields
        self.machine = machine

    def number(self, key: str, rule: NumberRule, default: str = "") -> float | None:
        """``key``'s value by ``rule``; absent, the form's ``default`` (text, as typed)."""
        try:
            if key not in self.fields:
                return rule.parse(default)
            return parse_number(self.fields[key], rule)
        except FieldError as exc:
            raise StepProblem(key, keyed(key, exc)) from None

    def joint(self) -> int:
        value = self.fields.get("joint")
        if value is None:
            return 0
        n = self.machine.n_joints
        if isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= n:
            return value - 1
        try:
            return self.machine.joint_index(str(value))
        except KeyError as exc:
            raise StepProblem("joint", f"joint: {exc.args[0]}, or a number 1…{n}") from None

    def vector(self, key: str, what: str) -> list[float]:
        value = self.fields.get(key)
        m = self.machine
        if not isinstance(value, list) or len(value) != m.n_joints:
            names = ", ".join(j.name for j in m.joints)
            raise StepProblem(key, f"{key}: give {m.n_joints} numbers in joint order "
                                   f"({names}), as [a, b, …]")
        return [self.number_of(key, v, position_rule(j, m, what))
                for j, v in zip(m.joints, value, strict=True)]

    def number_of(self, key: str, value: object, rule: NumberRule) -> float:
        try:
            out = parse_number(value, rule)
        except FieldError as exc:
            raise StepProblem(key, keyed(key, exc)) from None
        assert out is not None
        return out

    def given(self, key: str) -> bool:
        return key in self.fields


def _step(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path) -> MovePlan:
    j = f.joint()
    joint = machine.joints[j]
    start = f.number("start", position_rule(joint, machine, "start", optional=True))
    target = f.number("target", position_rule(joint, machine, "target"))
    duration = f.number("duration", seconds_rule("duration", optional=True))
    assert target is not None
    return _planned("", lambda: form_plans.step(machine, here, j, target, start, duration,
                                                      dt=dt))


def _ramp(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path) -> MovePlan:
    j = f.joint()
    joint = machine.joints[j]
    start = f.number("start", position_rule(joint, machine, "start", optional=True))
    end = f.number("end", position_rule(joint, machine, "end"))
    ramp_time = f.number("ramp_time", seconds_rule("ramp time"), f"{RAMP_TIME_S:g}")
    total = f.number("total", seconds_rule("total duration", optional=True))
    assert end is not None and ramp_time is not None
    return _planned("", lambda: form_plans.ramp(machine, here, j, end, ramp_time, start,
                                                   total, dt=dt))


def _sine(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path) -> MovePlan:
    j = f.joint()
    joint = machine.joints[j]
    start = f.number("start", position_rule(joint, machine, "start", optional=True))
    end = f.number("end", position_rule(joint, machine, "end"))
    period = f.number("period", seconds_rule("period"), f"{SINE_PERIOD_S:g}")
    duration = f.number("duration", seconds_rule("duration"), f"{SINE_DURATION_S:g}")
    assert end is not None and period is not None and duration is not None
    return _planned("", lambda: form_plans.sine(machine, here, j, end, period, duration,
                                                   start, dt=dt))


def _multistep(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path
               ) -> MovePlan:
    if machine.n_joints == 1:
        if f.given("targets"):
            raise StepProblem("targets", "targets: a one-joint machine runs a sequence: "
                                         "sequence = [[position, dwell s], …]")
        return _sequence(f, machine, here, dt)
    if f.given("sequence"):
        raise StepProblem("sequence", f"sequence: a sequence is the rig's; on {machine.name} "
                                      "give targets = [one per joint]")
    targets = f.vector("targets", "target")
    duration = f.number("duration", seconds_rule("duration", optional=True))
    return _planned("", lambda: form_plans.multi_step(machine, here, targets, duration,
                                                             dt=dt))


def _sequence(f: _Fields, machine: Machine, here: np.ndarray, dt: float) -> MovePlan:
    given = f.fields.get("sequence")
    if not isinstance(given, list):
        raise StepProblem("sequence", "sequence = [[position, dwell s], …] (or [position, …] "
                                      f"with the {DWELL_S:g} s dwell)")
    f.number_of("sequence", len(given), count_rule("number of steps", MAX_SEQUENCE))
    joint = machine.joints[0]
    steps = []
    for i, item in enumerate(given, 1):
        position, dwell = (item if isinstance(item, list) and len(item) == 2
                           else (item, DWELL_S))
        steps.append((f.number_of("sequence", position,
                                  position_rule(joint, machine, f"step {i} position")),
                      f.number_of("sequence", dwell, seconds_rule(f"step {i} dwell"))))
    return _planned("", lambda: form_plans.sequence(machine, here, steps, dt=dt))


def _endpoint(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path
              ) -> MovePlan:
    from control.motion.robot_model import model_of

    model = model_of(machine)
    if model is None:
        raise StepProblem("move", f"endpoint: machine {machine.name} has no kinematic model; "
                                  "use step, ramp or path")
    pose = model.pose(here)  # the form's fields start as the current pose
    for i, (key, unit) in enumerate(POSE_KEYS):
        if f.given(key):
            pose[i] = f.number(key, pose_rule(key, unit))
    try:
        solutions = form_plans.end_point_solutions(model, pose, here, ": leave x … alpha out")
    except ValueError as exc:
        raise StepProblem("x", f"x … alpha: {exc}") from None
    k = int(f.number("solution", count_rule("solution", len(solutions)), "1") or 1) - 1
    ramp_time = f.number("ramp_time", seconds_rule("ramp time", optional=True))
    return _planned("", lambda: form_plans.end_point(machine, here, pose, solutions, k,
                                                      ramp_time, dt=dt))


def _path(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path) -> MovePlan:
    from control.motion.path_files import PathFileError, read_path

    name = f.fields.get("file")
    if not isinstance(name, str) or not name:
        raise StepProblem("file", 'file = "PATH": a CSV or TSV path file, or a saved run')
    path = (base / Path(name).expanduser())
    try:
        points = read_path(path, machine, tuple(here))
    except PathFileError as exc:
        raise StepProblem("file", f"file: {exc}") from None
    return _planned("", lambda: form_plans.path_file(machine, here, points, str(path),
                                                         dt=dt))


def _via(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path) -> MovePlan:
    from control.motion.robot_model import has_unimate_model

    cartesian = f.fields.get("cartesian", False)
    if not isinstance(cartesian, bool):
        raise StepProblem("cartesian", "cartesian = true or false")
    if cartesian and not has_unimate_model(machine):
        raise StepProblem("cartesian", f"cartesian: machine {machine.name} has no kinematic "
                                       "model; give joint positions")
    fraction = f.number("speed", fraction_rule("speed fraction"), f"{VIA_SPEED:g}")
    rows = f.fields.get("points")
    if not isinstance(rows, list) or not all(isinstance(r, list) for r in rows):
        raise StepProblem("points", "points = [[…], …]: one list a point")
    text = "\n".join(" ".join(str(v) for v in row) for row in rows)
    try:
        points = form_plans.via_point_rows(text, machine, cartesian)
    except ValueError as exc:
        raise StepProblem("points", f"points: {exc}") from None
    assert fraction is not None
    return _planned("", lambda: form_plans.via_points(machine, here, points, fraction,
                                                            cartesian, dt=dt))


def _goto(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path
          ) -> MovePlan | None:
    target = f.vector("targets", "target")
    speed = f.number("speed", fraction_rule("speed fraction"), f"{VIA_SPEED:g}")
    assert speed is not None
    return _go_to(machine, here, target, speed, dt, "")


def _pulse(f: _Fields, machine: Machine, here: np.ndarray, dt: float, base: Path) -> MovePlan:
    if machine.n_joints != 1:
        raise StepProblem("move", f"pulse: the set pulse is the rig's open-loop test; machine "
                                  f"{machine.name} has {machine.n_joints} joints")
    duty = f.number("duty", duty_rule(), f"{PULSE_DUTY_PCT:g}")
    duration = f.number("duration", seconds_rule("duration", high=PULSE_MAX_S), f"{PULSE_S:g}")
    assert duty is not None and duration is not None
    return form_plans.pulse(machine, duty, duration, dt=dt)


_KINDS: Mapping[str, Callable[[_Fields, Machine, np.ndarray, float, Path],
                              MovePlan | None]] = {
    "step": _step, "ramp": _ramp, "sine": _sine, "multistep": _multistep,
    "endpoint": _endpoint, "path": _path, "via": _via, "goto": _goto, "pulse": _pulse,
}
