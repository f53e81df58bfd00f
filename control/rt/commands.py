"""Commands to the controller: frozen records, validated when built and again on arrival.

The thesis's ``option`` program wrote commands into an rtf FIFO; ours are
records sent through the command channel and dispatched by type. Each checks
what it can alone when built (every number finite, kinds and sets known); the
ones that name a joint are built with ``of(machine, ...)``, which accepts a
joint index or name and refuses one the machine does not have. The controller
calls ``check(n_joints)`` on everything it receives, so a record that bypassed
the builders is refused with a reason, never acted on.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

from control.rt.speed_cap import MODES, TOOL_SPEED
from hw.machine import Coefficients, Machine

COEFFICIENT_SETS = ("hold", "track")
# What a move of each kind may ask of the joints (control/motion/acceptance.py applies it,
# docs/motion.md): a smooth kind keeps every joint's max_speed and max_accel; a step kind may
# jump, as the thesis's step inputs did (function.c SingleStep, MultiStep), but every row is
# finite and inside the limits; a duty kind plays open-loop duty, finite and in -100…100 %.
SMOOTH_KINDS = frozenset({"path", "ramp", "sine", "cartesian", "via_points", "end_point",
                          "go_to", "cartesian_jog"})
STEP_KINDS = frozenset({"step", "multi_step"})
DUTY_KINDS = frozenset({"tracking_actuate", "set_pulse"})
MOVE_KINDS = SMOOTH_KINDS | STEP_KINDS | DUTY_KINDS
REASON_TEXT = 200
INJECTABLE = ("press_estop", "jam_valve", "freeze_encoder", "stick_bit")  # simulator faults


class CommandError(ValueError):
    """A command that cannot be carried out as given; the message says why."""


def joint_index(machine: Machine, joint: int | str) -> int:
    """The index of ``joint``, given by index (0…n-1) or by key or name (``"updown"``)."""
    n = machine.n_joints
    if isinstance(joint, str):
        try:
            return machine.joint_index(joint)
        except KeyError as exc:
            raise CommandError(exc.args[0]) from None
    if isinstance(joint, bool) or not isinstance(joint, int) or not 0 <= joint < n:
        names = ", ".join(f"{i} {j.name}" for i, j in enumerate(machine.joints))
        raise CommandError(f"no joint {joint!r} on machine {machine.name} (joints: {names})")
    return joint


def finite(what: str, value: object) -> float:
    """``value`` as a float, or a CommandError naming ``what`` if it is not a finite number."""
    if isinstance(value, bool):
        raise CommandError(f"{what} must be a number, got {value!r}")
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise CommandError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise CommandError(f"{what} must be a finite number, got {number}")
    return number


@dataclass(frozen=True)
class Command:
    """Something the client asks of the controller."""

    NAME: ClassVar[str] = "command"

    def __post_init__(self) -> None:
        """Check what the record can check alone (numbers, kinds); CommandError if not."""

    def check(self, n_joints: int) -> None:
        """Raise CommandError unless this record, as it arrived, fits ``n_joints`` joints.

        A decoded message is built through its constructor (``control/rt/wire.py``); the
        controller still re-runs every check here, for a record made any other way.
        """
        self.__post_init__()
        self.fits(n_joints)

    def fits(self, n_joints: int) -> None:
        """Raise CommandError if a joint this record names is not one of ``n_joints``."""


@dataclass(frozen=True)
class Shutdown(Command):
    """End any move, close the valves and exit."""

    NAME: ClassVar[str] = "shutdown"


@dataclass(frozen=True)
class Hold(Command):
    """Abort any move and hold every joint where it is (the thesis's default mode); ``reason``
    is how the move ended when it is not the operator's hold (the commander gone, say)."""

    NAME: ClassVar[str] = "hold"
    reason: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.reason, str) or len(self.reason) > REASON_TEXT:
            raise CommandError(f"a hold's reason is a text of at most {REASON_TEXT} characters")


@dataclass(frozen=True)
class EmergencyStop(Command):
    """Latch every valve closed until a reset."""

    NAME: ClassVar[str] = "E-stop"


@dataclass(frozen=True)
class Reset(Command):
    """Release a latched E-stop (reconnecting a lost link first)."""

    NAME: ClassVar[str] = "reset"


@dataclass(frozen=True)
class FeedOverride(Command):
    """The feed override: the path being followed advances at ``value`` (0…1) of its speed."""

    NAME: ClassVar[str] = "feed override"
    value: float

    def __post_init__(self) -> None:
        value = finite("feed override", self.value)
        if not 0.0 <= value <= 1.0:
            raise CommandError(f"feed override must be in 0…1 (0…100 %), got {value:g}")
        object.__setattr__(self, "value", value)


@dataclass(frozen=True)
class Pause(Command):
    """Feed hold: decelerate along the path to a stop and hold there (``Resume`` goes on)."""

    NAME: ClassVar[str] = "feed hold"


@dataclass(frozen=True)
class Resume(Command):
    """End a feed hold: the path goes on from where it stopped, with no jump."""

    NAME: ClassVar[str] = "resume"


@dataclass(frozen=True)
class SetSpeedMode(Command):
    """Reduced speed (ISO 10218-1's T1: the tool at most 250 mm/s, each joint at most its
    jog_speed, open-loop duty refused) or automatic (full speed). To reduced takes effect at
    once (a running path slows to it along the path); to automatic only at rest."""

    NAME: ClassVar[str] = "speed mode"
    mode: str

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise CommandError(f"speed mode {self.mode!r} is not one of {', '.join(MODES)} "
                               f"(reduced: the tool at most {TOOL_SPEED:g} mm/s)")


@dataclass(frozen=True)
class Initialise(Command):
    """Rig: drive the ram to the bottom stop and zero the encoder (section 3.5)."""

    NAME: ClassVar[str] = "initialise"


@dataclass(frozen=True)
class Manual(Command):
    """manual_actuate: open-loop duty per joint, % in each joint's positive sense."""

    NAME: ClassVar[str] = "manual actuation"
    duty: tuple[float, ...]

    def __post_init__(self) -> None:
        duty = tuple(finite(f"manual duty {i}", d) for i, d in enumerate(self.duty))
        object.__setattr__(self, "duty", tuple(max(-100.0, min(100.0, d)) for d in duty))

    @classmethod
    def of(cls, machine: Machine, duty: Sequence[float]) -> Manual:
        command = cls(tuple(duty))
        command.fits(machine.n_joints)
        return command

    def fits(self, n_joints: int) -> None:
        if len(self.duty) != n_joints:
            raise CommandError(f"manual actuation needs {n_joints} duties, got {len(self.duty)}")


@dataclass(frozen=True)
class JogPosition(Command):
    """Closed-loop jog: move one joint's hold target by ``delta`` (mm or deg)."""

    NAME: ClassVar[str] = "position jog"
    joint: int
    delta: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "delta", finite("position jog step", self.delta))

    @classmethod
    def of(cls, machine: Machine, joint: int | str, delta: float) -> JogPosition:
        return cls(joint_index(machine, joint), delta)

    def fits(self, n_joints: int) -> None:
        _check_joint(self.joint, n_joints)


@dataclass(frozen=True)
class JogVelocity(Command):
    """Streamed closed-loop jog (MoveIt Servo's): each joint's hold target moves at
    ``velocity`` (mm/s or deg/s, capped at its jog_speed) until the next one; not renewed
    within 150 ms, it brakes to a stop (``control/rt/jog.py``)."""

    NAME: ClassVar[str] = "velocity jog"
    velocity: tuple[float, ...]

    def __post_init__(self) -> None:
        if not isinstance(self.velocity, tuple):
            raise CommandError(f"velocity jog needs a tuple of velocities, got {self.velocity!r}")
        velocity = tuple(finite(f"velocity jog {i}", v) for i, v in enumerate(self.velocity))
        object.__setattr__(self, "velocity", velocity)

    @classmethod
    def of(cls, machine: Machine, velocity: Sequence[float]) -> JogVelocity:
        command = cls(tuple(velocity))
        command.fits(machine.n_joints)
        return command

    def fits(self, n_joints: int) -> None:
        if len(self.velocity) != n_joints:
            raise CommandError(f"velocity jog needs {n_joints} velocities (one a joint, units/s), "
                               f"got {len(self.velocity)}")


@dataclass(frozen=True)
class SetCoefficients(Command):
    """The hold or track set in shared memory changed: apply it (section 6.3)."""

    NAME: ClassVar[str] = "coefficient change"
    which: str

    def __post_init__(self) -> None:
        if self.which not in COEFFICIENT_SETS:
            raise CommandError(f"coefficient set {self.which!r} is not one of "
                               f"{', '.join(COEFFICIENT_SETS)}")


@dataclass(frozen=True)
class StartMove(Command):
    """follow_track (a desired path) or tracking_actuate (a duty profile): the path sealed in
    the memory file sent with this command, the run recorded into the move segment named
    ``segment`` (which also holds the run's metadata, ``control/runs.py``)."""

    NAME: ClassVar[str] = "move"
    move_id: int
    segment: str
    kind: str
    tracking: bool
    samples: int  # rows of the sealed path sent with it (control/rt/sealed.py)

    def __post_init__(self) -> None:
        for name in ("move_id", "samples"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise CommandError(f"move {name.replace('_', ' ')} must be a positive integer, "
                                   f"got {value!r}")
        if self.kind not in MOVE_KINDS:
            raise CommandError(f"unknown move kind {self.kind!r} (kinds: "
                               f"{', '.join(sorted(MOVE_KINDS))})")
        if self.tracking != (self.kind in DUTY_KINDS):
            what = "a duty profile" if self.kind in DUTY_KINDS else "a desired path"
            raise CommandError(f"move {self.move_id}: a {self.kind} move plays {what}")
        if not isinstance(self.segment, str) or not self.segment:
            raise CommandError(f"move {self.move_id}: no segment name")


@dataclass(frozen=True)
class Inject(Command):
    """Simulator only: drive a simulated input or fault from a test (``press_estop``,
    ``jam_valve``, ``freeze_encoder``, ``stick_bit``)."""

    NAME: ClassVar[str] = "inject"
    method: str
    args: tuple[object, ...] = ()

    def __post_init__(self) -> None:
        if self.method not in INJECTABLE:
            raise CommandError(f"{self.method!r} cannot be injected (only "
                               f"{', '.join(INJECTABLE)})")


def _check_joint(joint: object, n_joints: int) -> None:
    if isinstance(joint, bool) or not isinstance(joint, int) or not 0 <= joint < n_joints:
        raise CommandError(f"no joint {joint!r}: joints are 0…{n_joints - 1}")


def check_coefficients(coefficients: Coefficients, n_joints: int) -> None:
    """Raise CommandError unless the set has every joint's taps and every number is finite."""
    c = coefficients
    for name in ("kp", "w", "ki", "kd"):
        if len(getattr(c, name)) != n_joints:
            raise CommandError(f"coefficient set {c.name!r}: {name} has "
                               f"{len(getattr(c, name))} joints, the machine {n_joints}")
    if c.kv and len(c.kv) != n_joints:
        raise CommandError(f"coefficient set {c.name!r}: kv has {len(c.kv)} joints, the "
                           f"machine {n_joints}")
    if c.deadband and len(c.deadband) != n_joints:
        raise CommandError(f"coefficient set {c.name!r}: deadband has {len(c.deadband)} "
                           f"joints, the machine {n_joints}")
    if any(not 0.0 <= d < math.inf for d in c.deadband):
        raise CommandError(f"coefficient set {c.name!r}: deadband {list(c.deadband)} must be "
                           "finite and not negative (joint units)")
    numbers = {"ki": c.ki, "kd": c.kd, "kv": c.kv, "filter": c.filter,
               "filter_divisor": (c.filter_divisor,), "integral_limit": (c.integral_limit,),
               "duty_limit": (c.duty_limit,), "integral_separation": (c.integral_separation,)}
    numbers.update({f"kp[{j}]": taps for j, taps in enumerate(c.kp)})
    numbers.update({f"w[{j}]": taps for j, taps in enumerate(c.w)})
    for name, values in numbers.items():
        for value in values:
            finite(f"coefficient set {c.name!r}: {name}", value)


COMMANDS = (Shutdown, Hold, EmergencyStop, Reset, FeedOverride, Pause, Resume, Initialise, Manual,
            JogPosition, JogVelocity, SetCoefficients, StartMove, Inject,
            SetSpeedMode)  # what a channel carries
