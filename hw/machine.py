"""Machine descriptions: TOML files loaded into frozen dataclasses.

A machine file describes joints (names, kinds, units, limits), encoder kind and
calibration, minimum PWM, valve polarity, the DH table and the controller
coefficient sets. The schema is documented in ``docs/machines.md``. Every error
names the file, the key and what is wrong, so a user adding a third machine
with ``--machine PATH`` can fix it from the message alone.
"""

from __future__ import annotations

import math
import re
import reprlib
import tomllib
import unicodedata
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

from hw.user_files import TEXT_ENCODING, NotRegularFile, open_regular

BUILTIN = {"unimate2000b": "unimate2000b.toml", "unimate": "unimate2000b.toml", "rig": "rig.toml"}
JOINT_KINDS = {"prismatic": "mm", "revolute": "deg"}
ENCODER_KINDS = ("gray", "quadrature")
KINEMATICS_MODELS = ("unimate2000b",)  # closed-form models control.motion.robot_model solves
MIN_FERROR_DIVISOR = 10.0  # min_following_error defaults to following_error / 10
JOG_SPEED_FRACTION = 0.25  # jog_speed defaults to a quarter of max_speed
MAX_FILE_BYTES = 1 << 20  # the Unimate's description is 8 kB; a file this large is not one
MAX_TAPS = 8  # taps per kp, w or filter list that the controller's shared memory holds
MAX_JOINTS = 16  # joints the I/O board's protocol drives (docs/protocol.md, CONFIG)
# Characters refused in a file's strings and path: controls (ESC, newline, DEL, C1), format
# characters (bidi overrides, zero-width), line and paragraph separators, lone surrogates
# (an undecodable file name). Names are printed as they are, so they must print as text.
UNPRINTABLE = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})

# The physical range of every number (docs/machines.md gives each its reason).
SAMPLE_TIME_MS = (0.1, 100.0)
VALVE_PERIOD_US = (100.0, 10_000.0)
VALVE_RESOLUTION_PCT = (0.01, 10.0)  # the I/O board's protocol carries it in 0.01 % units
ENCODER_BITS = (1, 32)
SETTLE_MS = 65.0  # the I/O board's protocol carries it in µs, 16 bits
GRAY_SETTLE_MS = 0.001  # a multiplexed encoder's lamp needs time to light: at least 1 µs
ENCODER_THRESHOLD = (0.01, 0.99)  # a lit cell's line switches between dark and full light
GRADIENT = (1e-6, 10.0)  # |joint units per count|
COUPLING = 10.0  # |coupling|
DOWN_SCALE = (0.01, 1.0)
GAIN_UNIT = (1e-3, 1e3)
COEFFICIENT = 1e6  # |any gain, weight, tap or limit of eq. 5.1|
FILTER_DIVISOR = (1e-3, 1e6)
DH_LENGTHS = (-10_000.0, 10_000.0)  # a and d, mm
DH_ANGLES = (-360.0, 360.0)  # alpha and theta, degrees
# Cartesian jog (control/motion/cartesian_jog.py), [mm, deg] per s and per s²: defaults an
# operator can follow by eye, and the ranges a hand-guided tool could need.
CARTESIAN_JOG_SPEED = (25.0, 10.0)
CARTESIAN_JOG_ACCEL = (100.0, 40.0)
CARTESIAN_JOG_SPEED_RANGE = (0.1, 1000.0)
CARTESIAN_JOG_ACCEL_RANGE = (1.0, 10_000.0)
# In position (ros2_control's joint_trajectory_controller goal tolerances, LinuxCNC's
# in-position): a joint's speed is judged over this window, so a one-count step of the
# encoder is count / window; goal_time is the longest a move may take to settle.
GOAL_WINDOW_S = 0.1
GOAL_TIME_S = (0.5, 600.0)  # at least two windows and the samples the path ends on
GOAL_TIME_DEFAULT_S = 2.0
# the last part of each period in which the control process warms its code (a shadow tick,
# control/rt/warmup.py): past half the period a core would spin more than it rests
WARM_UP_PCT = (0.0, 50.0)
STOPPED_SPEED_FRACTION = 0.02  # stopped_speed defaults to 2 % of max_speed


@dataclass(frozen=True)
class KindRanges:
    """Ranges that depend on a joint's kind, in its units (mm or degrees)."""

    position: float  # |limits| and |encoder constant|
    speed: tuple[float, float]  # max_speed, units/s
    accel: tuple[float, float]  # max_accel, units/s²


KIND_RANGES = {"prismatic": KindRanges(100_000.0, (0.1, 10_000.0), (1.0, 1e6)),
               "revolute": KindRanges(3_600.0, (0.1, 3_600.0), (1.0, 1e6))}


class MachineError(ValueError):
    """A machine description is malformed or inconsistent."""


@dataclass(frozen=True)
class EncoderCal:
    """Raw encoder count to joint units: ``q = gradient * n + constant + coupling * q[coupled_to]``.

    The Gray-code calibration is rtshare.h's metric_gradient/metric_constant;
    ``coupled_to`` is rtshare.h's joint_dep (the Yaw reading includes Bend).
    """

    gradient: float
    constant: float
    coupled_to: int | None = None
    coupling: float = 0.0


@dataclass(frozen=True)
class Joint:
    """One actuated joint. Lengths in mm, angles in degrees, duty in percent."""

    key: str
    name: str
    kind: str
    unit: str
    lower: float
    upper: float
    min_pwm_pos: float
    min_pwm_neg: float
    polarity: int
    max_speed: float
    max_accel: float
    tolerance: float
    following_error: float  # LinuxCNC's FERROR: the limit at max_speed (units)
    encoder: EncoderCal
    down_scale: float = 1.0
    gain_unit: float = 1.0
    plant: Mapping[str, float] = field(default_factory=lambda: MappingProxyType({}))
    min_following_error: float = 0.0  # MIN_FERROR: the limit at standstill (units)
    jog_speed: float = 0.0  # how fast a position jog moves the hold target (units/s)
    full_duty_speed: float = 0.0  # fastest the joint moves at 100 % duty (units/s); glitch filter
    goal_tolerance: float = 0.0  # in position: this close to a move's end (units)
    stopped_speed: float = 0.0  # and slower than this (units/s), judged over GOAL_WINDOW_S

    def __post_init__(self) -> None:
        if not self.full_duty_speed:  # not given: the path rules' speed
            object.__setattr__(self, "full_duty_speed", self.max_speed)
        if not self.goal_tolerance:  # not given: the settle band
            object.__setattr__(self, "goal_tolerance", self.tolerance)
        if not self.stopped_speed:
            object.__setattr__(self, "stopped_speed", STOPPED_SPEED_FRACTION * self.max_speed)

    @property
    def symbol(self) -> str:
        return "mm" if self.unit == "mm" else "°"

    def limit_text(self) -> str:
        return f"{self.lower:g}…{self.upper:g}{self.symbol}"

    def check_target(self, value: float, machine: str) -> float:
        """Return ``value`` if it is a finite position inside the limits, else raise ValueError."""
        if not math.isfinite(value):
            raise ValueError(f"{self.name} target {value} is not a number (machine {machine})")
        if not self.lower <= value <= self.upper:
            raise ValueError(
                f"{self.name} target {value:g}{self.symbol} is outside "
                f"{self.limit_text()} (machine {machine})"
            )
        return value


@dataclass(frozen=True)
class Coefficients:
    """One coefficient set of the difference equation, eq. 5.1, per joint.

    Taps are newest first: ``kp[j][0]`` multiplies e(k), ``w[j][0]`` multiplies
    u(k), ``filter[0]`` multiplies e(k). The derivative is
    ``kd * sum(filter[i] * e(k-i)) / (filter_divisor * dt)``; eq. 3.3 is
    filter (11, -18, 9, -2) with divisor 6. ``kv`` is the velocity feed-forward
    (% per joint unit/s of desired velocity, chapter 6's "feed-forward"); empty
    means none.
    """

    name: str
    note: str
    kp: tuple[tuple[float, ...], ...]
    ki: tuple[float, ...]
    kd: tuple[float, ...]
    w: tuple[tuple[float, ...], ...]
    filter: tuple[float, ...]
    filter_divisor: float
    integral_limit: float
    duty_limit: float = 100.0
    kv: tuple[float, ...] = ()
    deadband: tuple[float, ...] = ()
    integral_separation: float = 0.0


@dataclass(frozen=True)
class Supervision:
    """How the controller's supervisor judges the joints (``docs/supervisor.md``).

    ``window_s``: a joint is judged over this much time (closing, moving, still).
    ``closing_fraction``: beyond its following-error limit a joint must close on its
    target at least this fraction of the speed its duty should give.
    ``open_margin_pct``: a valve counts as well open at its minimum PWM plus this.
    ``range_margin_counts``: a believed position this far past a limit is implausible.
    ``glitch_limit``: this many rejected readings in a row are a feedback fault.
    ``overrun_fraction``: more than this fraction of ticks late over a second holds.
    ``stall_s``: a gap this long in a move's record is a stall, listed in the run.
    ``max_pause_s``: a move held (feed hold) longer than this is ended, and the robot holds.
    """

    window_s: float = 0.2
    closing_fraction: float = 0.25
    open_margin_pct: float = 10.0
    range_margin_counts: float = 20.0
    glitch_limit: int = 5
    overrun_fraction: float = 0.2
    stall_s: float = 0.05
    max_pause_s: float = 600.0


@dataclass(frozen=True)
class DHRow:
    """A standard DH link, eq. 4.02; the variable of joint ``joint`` adds to theta or d."""

    joint: int
    alpha: float
    a: float
    d: float
    theta: float


@dataclass(frozen=True)
class Machine:
    name: str
    title: str
    path: Path
    sample_time_s: float
    valve_period_us: float
    valve_resolution_pct: float
    encoder_kind: str
    encoder_bits: int
    encoder_settle_s: float
    joints: tuple[Joint, ...]
    coefficients: Mapping[str, Coefficients]
    kinematics_model: str | None
    dh: tuple[DHRow, ...]
    plant: Mapping[str, float]
    supervision: Supervision = field(default_factory=Supervision)
    home: tuple[float, ...] | None = None  # (J,) mm, deg: where the machine works from
    park: tuple[float, ...] | None = None  # (J,) mm, deg: where it rests, power off
    cartesian_jog_speed: tuple[float, float] = CARTESIAN_JOG_SPEED  # mm/s, deg/s
    cartesian_jog_accel: tuple[float, float] = CARTESIAN_JOG_ACCEL  # mm/s², deg/s²
    encoder_threshold: float = 0.5
    goal_time_s: float = GOAL_TIME_DEFAULT_S  # after a path's end, to come in position
    warm_up_pct: float = 0.0  # of the period, before each deadline: a shadow tick's window

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def lower(self) -> tuple[float, ...]:
        return tuple(j.lower for j in self.joints)

    @property
    def upper(self) -> tuple[float, ...]:
        return tuple(j.upper for j in self.joints)

    @property
    def hold(self) -> Coefficients:
        return self.coefficients["hold"]

    @property
    def track(self) -> Coefficients:
        return self.coefficients["track"]

    @property
    def describes_plant(self) -> bool:
        """The file describes the simulator's plant (``[plant]``, ``[joints.plant]``); a
        machine for real hardware only need not."""
        return bool(self.plant) or any(j.plant for j in self.joints)

    def joint_index(self, key: str) -> int:
        """Index of a joint by key (``"updown"``) or display name (``"Up/Down"``)."""
        for i, j in enumerate(self.joints):
            if key in (j.key, j.name) or key.lower() in (j.key, j.name.lower()):
                return i
        names = ", ".join(j.key for j in self.joints)
        raise KeyError(f"no joint {key!r} on machine {self.name} (joints: {names})")

    def check_targets(self, q: tuple[float, ...] | list[float]) -> tuple[float, ...]:
        """Validate a full joint vector against the limits; the error names the joint."""
        if len(q) != self.n_joints:
            raise ValueError(f"expected {self.n_joints} joint values for {self.name}, got {len(q)}")
        pairs = zip(self.joints, q, strict=True)
        return tuple(j.check_target(float(v), self.name) for j, v in pairs)


def builtin_names() -> list[str]:
    return sorted(set(BUILTIN) - {"unimate"})


def load_machine(spec: str | Path) -> Machine:
    """Load a built-in machine by name (``unimate2000b``, ``rig``) or a TOML file by path.

    Every failure is a MachineError naming the file: missing, unreadable, not a regular
    file, too large, not UTF-8, not TOML, or a value out of its range.
    """
    text_spec = str(spec)
    if text_spec in BUILTIN:
        ref = resources.files("hw.machines").joinpath(BUILTIN[text_spec])
        return parse_machine(ref.read_text(encoding="utf-8"), Path(str(ref)))
    path = Path(spec)
    _check_path(path)
    return parse_machine(read_text(path, "machine file"), path)


def parse_machine(text: str, path: Path) -> Machine:
    """Parse and validate the text of a machine file; ``path`` is used in messages.

    The simulator's plant (``[plant]``, ``[joints.plant]``) is read as named numbers; what
    the simulator makes of them is its own to check (``hw.sim.check_plant``), as it is built.
    """
    _check_path(path)
    return _Reader(path.name).machine(parse_toml(text, path.name), path)


def _check_path(path: Path) -> None:
    """Refuse a path that would not print as text: every message names the file."""
    where = _unprintable(str(path))
    if where is not None:
        raise MachineError(f"{str(path)!r}: a machine file's path must print as text, and "
                           f"character {where} is {str(path)[where]!r}: rename the file")


def read_text(path: Path, kind: str) -> str:
    """The text of a ``kind`` (a machine file, a coefficient file, a positions file) at
    ``path``, a byte-order mark dropped (``hw.user_files``); MachineError naming it if it has
    none to give: missing, not a regular file (a FIFO is refused at once), unreadable, too
    large, not UTF-8."""
    try:
        with open_regular(path) as file:
            data = file.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        builtin = (f" (built-in machines: {', '.join(builtin_names())})"
                   if kind == "machine file" else "")
        raise MachineError(f"{path}: no such {kind}{builtin}") from None
    except NotRegularFile as exc:
        if exc.kind == "a directory":
            raise MachineError(f"{path}: is a directory: give the {kind} inside it") from None
        raise MachineError(f"{path}: {exc.strerror}: give a {kind} (TOML)") from None
    except OSError as exc:
        raise MachineError(f"{path}: cannot read it: {exc.strerror or exc}") from None
    if len(data) > MAX_FILE_BYTES:
        raise MachineError(f"{path}: larger than {MAX_FILE_BYTES >> 10} kB, so not a {kind} "
                           f"(the Unimate's machine file is 8 kB)")
    try:
        return data.decode(TEXT_ENCODING)
    except UnicodeDecodeError as exc:  # its object: the bytes after a byte-order mark
        line = exc.object.count(b"\n", 0, exc.start) + 1
        raise MachineError(f"{path}: line {line}: byte {exc.object[exc.start]:#04x} is not "
                           f"UTF-8 text: save the file as UTF-8") from None


def parse_toml(text: str, filename: str) -> dict[str, Any]:
    """TOML ``text`` of a file of ours; MachineError naming ``filename`` (and the line) if it
    is not TOML, nests too deep or holds an integer of thousands of digits."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MachineError(f"{filename}: not valid TOML: {exc}") from None
    except RecursionError:
        raise MachineError(f"{filename}: arrays or tables nested too deeply to be one of "
                           f"servodesk's files") from None
    except ValueError as exc:  # an integer literal past int's 4300-digit conversion limit
        match = re.search(r"[0-9_]{4300,}", text)
        if match is None:
            raise MachineError(f"{filename}: not valid TOML: {exc}") from None
        line = text.count("\n", 0, match.start()) + 1
        raise MachineError(f"{filename}: line {line}: an integer of thousands of digits: no "
                           f"machine value is larger than a float holds (1.8e308)") from None


def parse_coefficient_tables(doc: Mapping[str, Any], filename: str,
                             n_joints: int) -> Mapping[str, Coefficients]:
    """The ``[coefficients.NAME]`` sets of a parsed coefficient file (nothing else allowed),
    validated as a machine file's are; errors name ``filename`` and the key."""
    reader = _Reader(filename)
    reader.only(doc, "", {"coefficients"})
    return reader.coefficient_sets(doc, n_joints, required=())


class _Reader:
    """Typed access to a parsed TOML document that reports file and key on every error."""

    def __init__(self, filename: str) -> None:
        self.filename = filename

    def fail(self, key: str, what: str) -> MachineError:
        return MachineError(f"{self.filename}: {key}: {what}")

    def table(self, doc: Mapping[str, Any], key: str, name: str, optional: bool = False) -> dict:
        value = doc.get(name, {} if optional else None)
        if value is None:
            raise self.fail(_join(key, name), "missing table")
        if not isinstance(value, dict):
            raise self.fail(_join(key, name), f"must be a table, got {type(value).__name__}")
        return value

    def only(self, doc: Mapping[str, Any], key: str, allowed: set[str]) -> None:
        unknown = sorted(set(doc) - allowed)
        if unknown:
            raise self.fail(key or "top level", f"unknown key(s) {', '.join(map(_key, unknown))}; "
                            f"allowed: {', '.join(sorted(allowed))}")

    def number(self, doc: Mapping[str, Any], key: str, name: str, default: float | None = None,
               low: float = -math.inf, high: float = math.inf, strict_low: bool = False) -> float:
        full = _join(key, name)
        if name not in doc:
            if default is None:
                raise self.fail(full, "missing number")
            return default
        return self.check_number(doc[name], full, low, high, strict_low)

    def whole(self, doc: Mapping[str, Any], key: str, name: str, default: int | None,
              low: int, high: int) -> int:
        value = self.number(doc, key, name, default, low, high)
        if value != int(value):
            raise self.fail(_join(key, name), f"must be a whole number, got {value:g}")
        return int(value)

    def check_number(self, value: Any, full: str, low: float = -math.inf, high: float = math.inf,
                     strict_low: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(full, f"must be a number, got {_shown(value)}")
        try:
            number = float(value)
        except OverflowError:
            raise self.fail(full, f"{_shown(value)} is larger than any machine value (a float "
                                  f"holds 1.8e308)") from None
        if not math.isfinite(number):
            raise self.fail(full, f"must be finite, got {number}")
        too_low = number <= low if strict_low else number < low
        if too_low or number > high:
            bound = f"> {low:g}" if strict_low else f">= {low:g}"
            rng = bound if high == math.inf else f"in {low:g}…{high:g}"
            raise self.fail(full, f"{number:.10g} out of range (must be {rng})")
        return number

    def numbers(self, value: Any, full: str, length: int | None = None,
                low: float = -math.inf, high: float = math.inf) -> tuple[float, ...]:
        if not isinstance(value, list):
            raise self.fail(full, f"must be a list of numbers, got {_shown(value)}")
        if length is not None and len(value) != length:
            raise self.fail(full, f"must have {length} entries, got {len(value)}")
        return tuple(self.check_number(v, f"{full}[{i}]", low, high) for i, v in enumerate(value))

    def coefficient_list(self, value: Any, full: str, length: int | None = None
                         ) -> tuple[float, ...]:
        """Numbers of eq. 5.1: at most ``MAX_TAPS`` of them unless ``length`` says how many."""
        if length is None and isinstance(value, list) and len(value) > MAX_TAPS:
            raise self.fail(full, f"{len(value)} taps; the controller takes at most {MAX_TAPS}")
        return self.numbers(value, full, length, -COEFFICIENT, COEFFICIENT)

    def string(self, doc: Mapping[str, Any], key: str, name: str, default: str | None = None,
               choices: tuple[str, ...] | None = None) -> str:
        full = _join(key, name)
        value = doc.get(name, default)
        if value is None:
            raise self.fail(full, "missing string")
        if not isinstance(value, str) or not value:
            raise self.fail(full, f"must be a non-empty string, got {_shown(value)}")
        self.check_text(value, full)
        if choices is not None and value not in choices:
            raise self.fail(full, f"{_shown(value)} is not one of {', '.join(choices)}")
        return value

    def check_text(self, value: str, full: str) -> None:
        """Refuse text that does not print as itself (docs/machines.md: strings)."""
        where = _unprintable(value)
        if where is not None:
            raise self.fail(full, f"{_shown(value)}: character {where} is {value[where]!r}, which "
                                  f"does not print: names, titles and notes are shown as they "
                                  f"are, so remove it")

    def plant(self, doc: Mapping[str, Any], key: str) -> Mapping[str, float]:
        table = self.table(doc, key, "plant", optional=True)
        for name in table:
            self.check_text(name, _join(key, "plant"))
        return MappingProxyType(
            {name: self.check_number(v, _join(key, f"plant.{name}")) for name, v in table.items()}
        )

    def machine(self, doc: Mapping[str, Any], path: Path) -> Machine:
        self.only(doc, "", {"machine", "valve", "encoder", "kinematics", "joints",
                            "coefficients", "plant", "supervisor"})
        head = self.table(doc, "", "machine")
        self.only(head, "machine", {"name", "title", "sample_time_ms", "home", "park",
                                    "goal_time", "warm_up_pct"})
        valve = self.table(doc, "", "valve")
        self.only(valve, "valve", {"period_us", "resolution_pct"})
        enc = self.table(doc, "", "encoder")
        self.only(enc, "encoder", {"kind", "bits", "settle_ms", "threshold"})
        raw_joints = doc.get("joints")
        if not isinstance(raw_joints, list) or not raw_joints:
            raise self.fail("joints", "missing: at least one [[joints]] table is required")
        if len(raw_joints) > MAX_JOINTS:
            raise self.fail("joints", f"{len(raw_joints)} [[joints]] tables; the I/O board "
                                      f"drives at most {MAX_JOINTS}")
        keys = [self.string(j, f"joints[{i}]", "key") if isinstance(j, dict) else ""
                for i, j in enumerate(raw_joints)]
        for i, k in enumerate(keys):
            if keys.index(k) != i:
                raise self.fail(f"joints[{i}].key", f"duplicate joint key {k!r}")
        joints = tuple(self.joint(j, i, keys) for i, j in enumerate(raw_joints))
        encoder_kind = self.string(enc, "encoder", "kind", choices=ENCODER_KINDS)
        bits = self.whole(enc, "encoder", "bits", 16 if encoder_kind == "quadrature" else None,
                          *ENCODER_BITS)
        self.encoder_words(joints, encoder_kind, bits)
        return Machine(
            name=self.string(head, "machine", "name"),
            title=self.string(head, "machine", "title"),
            path=path,
            sample_time_s=self.number(head, "machine", "sample_time_ms", None,
                                      *SAMPLE_TIME_MS) / 1e3,
            valve_period_us=self.number(valve, "valve", "period_us", None, *VALVE_PERIOD_US),
            valve_resolution_pct=self.number(valve, "valve", "resolution_pct", None,
                                             *VALVE_RESOLUTION_PCT),
            encoder_kind=encoder_kind,
            encoder_bits=bits,
            encoder_settle_s=self.number(enc, "encoder", "settle_ms", 0.0,
                                         GRAY_SETTLE_MS if encoder_kind == "gray" else 0.0,
                                         SETTLE_MS) / 1e3,
            encoder_threshold=self.number(enc, "encoder", "threshold", 0.5, *ENCODER_THRESHOLD),
            joints=joints,
            coefficients=self.coefficient_sets(doc, len(joints)),
            kinematics_model=self.kinematics_model(doc),
            dh=self.dh(doc, keys),
            plant=self.plant(doc, ""),
            supervision=self.supervision(doc),
            home=self.joint_vector(head, "home", joints),
            park=self.joint_vector(head, "park", joints),
            cartesian_jog_speed=self.jog_pair(doc, "cartesian_jog_speed", CARTESIAN_JOG_SPEED,
                                              CARTESIAN_JOG_SPEED_RANGE),
            cartesian_jog_accel=self.jog_pair(doc, "cartesian_jog_accel", CARTESIAN_JOG_ACCEL,
                                              CARTESIAN_JOG_ACCEL_RANGE),
            goal_time_s=self.number(head, "machine", "goal_time", GOAL_TIME_DEFAULT_S,
                                    *GOAL_TIME_S),
            warm_up_pct=self.number(head, "machine", "warm_up_pct", 0.0, *WARM_UP_PCT),
        )

    def joint_vector(self, head: Mapping[str, Any], name: str, joints: tuple[Joint, ...]
                     ) -> tuple[float, ...] | None:
        """A named position of the machine (``home``, ``park``): one number per joint, in
        joint order and units, inside the joint's limits; None when the file has none."""
        if name not in head:
            return None
        full = f"machine.{name}"
        q = self.numbers(head[name], full, len(joints))
        for i, (joint, v) in enumerate(zip(joints, q, strict=True)):
            if not joint.lower <= v <= joint.upper:
                raise self.fail(f"{full}[{i}]", f"{joint.name} at {v:g}{joint.symbol} is outside "
                                                f"its limits {joint.limit_text()}")
        return q

    def encoder_words(self, joints: tuple[Joint, ...], kind: str, bits: int) -> None:
        """Refuse limits the encoders' words cannot cover. A Gray word reads counts
        0…2^bits − 1 absolutely; a quadrature count is signed (two's complement), so it
        covers 2^(bits − 1) − 1 counts either way from wherever the joint powered up."""
        top = (1 << bits) - 1
        for i, j in enumerate(joints):
            gradient, constant = j.encoder.gradient, j.encoder.constant
            counts = math.ceil((j.upper - j.lower) / abs(gradient))
            need = counts.bit_length() + (kind == "quadrature")
            if need > bits:
                raise self.fail(f"joints[{i}].limits",
                                f"{j.name}'s {j.limit_text()} is {counts} counts of "
                                f"{abs(gradient):g} {j.unit}, more than {bits}-bit {kind} "
                                f"words cover: it needs encoder.bits = {need} or a coarser "
                                f"encoder.gradient")
            ends = sorted(round((q - constant) / gradient) for q in (j.lower, j.upper))
            if kind == "gray" and (ends[0] < 0 or ends[1] > top):
                raise self.fail(f"joints[{i}].encoder.constant",
                                f"{j.name}'s limits {j.limit_text()} read counts "
                                f"{ends[0]}…{ends[1]}, outside the {bits}-bit words' 0…{top}: "
                                f"the constant is the position at count 0")

    def supervision(self, doc: Mapping[str, Any]) -> Supervision:
        table = self.table(doc, "", "supervisor", optional=True)
        key = "supervisor"
        self.only(table, key, {"window_ms", "closing_fraction", "open_margin_pct",
                               "range_margin_counts", "glitch_limit", "overrun_fraction",
                               "stall_ms", "max_pause_s"})
        d = Supervision()
        return Supervision(
            window_s=self.number(table, key, "window_ms", d.window_s * 1e3, low=10,
                                 high=1000) / 1e3,
            closing_fraction=self.number(table, key, "closing_fraction", d.closing_fraction,
                                         low=0, high=1, strict_low=True),
            open_margin_pct=self.number(table, key, "open_margin_pct", d.open_margin_pct,
                                        low=0, high=100),
            range_margin_counts=self.number(table, key, "range_margin_counts",
                                            d.range_margin_counts, low=1, high=1e6),
            glitch_limit=self.whole(table, key, "glitch_limit", d.glitch_limit, 1, 1000),
            overrun_fraction=self.number(table, key, "overrun_fraction", d.overrun_fraction,
                                         low=0, high=1, strict_low=True),
            stall_s=self.number(table, key, "stall_ms", d.stall_s * 1e3, low=2,
                                high=10_000) / 1e3,
            max_pause_s=self.number(table, key, "max_pause_s", d.max_pause_s, low=1,
                                    high=86_400),
        )

    def joint(self, doc: Any, index: int, keys: list[str]) -> Joint:
        key = f"joints[{index}]"
        if not isinstance(doc, dict):
            raise self.fail(key, "must be a table")
        self.only(doc, key, {"key", "name", "kind", "unit", "limits", "min_pwm", "polarity",
                             "max_speed", "max_accel", "tolerance", "following_error",
                             "min_following_error", "jog_speed", "encoder", "down_scale",
                             "gain_unit", "full_duty_speed", "goal_tolerance",
                             "stopped_speed", "plant"})
        name = self.string(doc, key, "name")
        kind = self.string(doc, key, "kind", choices=tuple(JOINT_KINDS))
        unit = self.string(doc, key, "unit", choices=(JOINT_KINDS[kind],))
        ranges = KIND_RANGES[kind]
        lower, upper = self.numbers(doc.get("limits"), f"{key}.limits", 2,
                                    -ranges.position, ranges.position)
        if lower >= upper:
            raise self.fail(f"{key}.limits", f"lower {lower:g} must be below upper {upper:g}")
        pos, neg = self.numbers(doc.get("min_pwm"), f"{key}.min_pwm", 2)
        for label, v in (("positive", pos), ("negative", neg)):
            if not 0 <= v < 100:
                raise self.fail(f"{key}.min_pwm", f"{label} minimum {v:g} must be in 0…100 %")
        polarity = self.number(doc, key, "polarity")
        if polarity not in (1.0, -1.0):
            raise self.fail(f"{key}.polarity", f"must be 1 or -1, got {polarity:g}")
        encoder = self.encoder_cal(doc, index, keys, ranges.position)
        tolerance = self.tolerance(doc, key, abs(encoder.gradient), upper - lower, unit)
        ferror = self.number(doc, key, "following_error", None, tolerance, upper - lower)
        max_speed = self.number(doc, key, "max_speed", None, *ranges.speed)
        return Joint(
            key=keys[index], name=name, kind=kind, unit=unit, lower=lower, upper=upper,
            min_pwm_pos=pos, min_pwm_neg=neg, polarity=int(polarity),
            max_speed=max_speed,
            max_accel=self.number(doc, key, "max_accel", None, *ranges.accel),
            tolerance=tolerance,
            following_error=ferror,
            min_following_error=self.number(
                doc, key, "min_following_error", max(ferror / MIN_FERROR_DIVISOR, tolerance),
                tolerance, ferror),
            jog_speed=self.number(doc, key, "jog_speed", JOG_SPEED_FRACTION * max_speed, 0.0,
                                  max_speed, strict_low=True),
            # a path at max_speed must be within what full duty gives
            full_duty_speed=self.number(doc, key, "full_duty_speed", max_speed, max_speed,
                                        ranges.speed[1]),
            encoder=encoder,
            down_scale=self.number(doc, key, "down_scale", 1.0, *DOWN_SCALE),
            gain_unit=self.number(doc, key, "gain_unit", 1.0, *GAIN_UNIT),
            plant=self.plant(doc, key),
            goal_tolerance=self.goal_tolerance(doc, key, abs(encoder.gradient), tolerance,
                                               upper - lower, unit),
            stopped_speed=self.stopped_speed(doc, key, abs(encoder.gradient), max_speed, unit),
        )

    def goal_tolerance(self, doc: Mapping[str, Any], key: str, count: float, tolerance: float,
                       span: float, unit: str) -> float:
        """In position: at least one encoder count, at most the joint's range; by default
        the settle band (``tolerance``)."""
        goal = self.number(doc, key, "goal_tolerance", tolerance, 0.0, span, strict_low=True)
        if goal < count:
            raise self.fail(f"{key}.goal_tolerance",
                            f"{goal:g} {unit} is less than one encoder count ({count:g} "
                            f"{unit}): a move could never end in position; give at least "
                            f"{count:g}")
        return goal

    def stopped_speed(self, doc: Mapping[str, Any], key: str, count: float, max_speed: float,
                      unit: str) -> float:
        """Stopped: slower than this, judged over ``GOAL_WINDOW_S``; one encoder count in
        the window must pass (a joint dithering by a count is at rest), at most max_speed."""
        least = count / GOAL_WINDOW_S
        speed = self.number(doc, key, "stopped_speed", max(STOPPED_SPEED_FRACTION * max_speed,
                                                           least), 0.0, max_speed,
                            strict_low=True)
        if speed < least:
            raise self.fail(f"{key}.stopped_speed",
                            f"{speed:g} {unit}/s is less than one encoder count in "
                            f"{GOAL_WINDOW_S * 1e3:g} ms ({least:.3g} {unit}/s): a joint at "
                            f"rest could never be judged stopped; give at least {least:.3g}")
        return speed

    def tolerance(self, doc: Mapping[str, Any], key: str, count: float, span: float,
                  unit: str) -> float:
        """The settle band: at least one encoder count, at most the joint's range."""
        tolerance = self.number(doc, key, "tolerance", None, 0.0, span, strict_low=True)
        if tolerance < count:
            raise self.fail(f"{key}.tolerance", f"{tolerance:g} {unit} is less than one encoder "
                                                f"count ({count:g} {unit}): a move could never "
                                                f"be seen to settle")
        return tolerance

    def encoder_cal(self, joint: Mapping[str, Any], index: int, keys: list[str],
                    position: float) -> EncoderCal:
        key = f"joints[{index}].encoder"
        doc = self.table(joint, f"joints[{index}]", "encoder")
        self.only(doc, key, {"gradient", "constant", "coupled_to", "coupling"})
        gradient = self.number(doc, key, "gradient")
        low, high = GRADIENT
        if not low <= abs(gradient) <= high:
            raise self.fail(f"{key}.gradient", f"{gradient:g} out of range (its size must be in "
                                               f"{low:g}…{high:g} units a count, its sign is "
                                               f"the direction)")
        coupled = doc.get("coupled_to")
        if coupled is not None and coupled not in keys:
            raise self.fail(f"{key}.coupled_to", f"{_shown(coupled)} is not a joint key "
                            f"(joints: {', '.join(keys)})")
        if coupled is not None and keys.index(coupled) == index:
            raise self.fail(f"{key}.coupled_to", "a joint cannot be coupled to itself")
        return EncoderCal(
            gradient=gradient,
            constant=self.number(doc, key, "constant", None, -position, position),
            coupled_to=None if coupled is None else keys.index(coupled),
            coupling=self.number(doc, key, "coupling", 0.0 if coupled is None else None,
                                 -COUPLING, COUPLING),
        )

    def coefficient_sets(self, doc: Mapping[str, Any], n: int,
                         required: tuple[str, ...] = ("hold", "track")
                         ) -> Mapping[str, Coefficients]:
        sets = self.table(doc, "", "coefficients")
        if not sets:
            raise self.fail("coefficients", "no [coefficients.NAME] table")
        for name in sets:
            self.check_text(name, "coefficients")
        for name in required:
            if name not in sets:
                raise self.fail(f"coefficients.{name}", "missing coefficient set")
        return MappingProxyType(
            {name: self.coefficients(body, f"coefficients.{name}", name, n)
             for name, body in sets.items()}
        )

    def coefficients(self, doc: Any, key: str, name: str, n: int) -> Coefficients:
        if not isinstance(doc, dict):
            raise self.fail(key, "must be a table")
        self.only(doc, key, {"note", "kp", "ki", "kd", "w", "filter", "filter_divisor",
                             "integral_limit", "duty_limit", "kv", "deadband",
                             "integral_separation"})
        return Coefficients(
            name=name,
            note=self.string(doc, key, "note", default=name),
            kp=self.taps(doc.get("kp"), f"{key}.kp", n),
            ki=self.coefficient_list(doc.get("ki"), f"{key}.ki", n),
            kd=self.coefficient_list(doc.get("kd"), f"{key}.kd", n),
            w=self.taps(doc.get("w"), f"{key}.w", n),
            filter=self.coefficient_list(doc.get("filter"), f"{key}.filter"),
            filter_divisor=self.number(doc, key, "filter_divisor", None, *FILTER_DIVISOR),
            integral_limit=self.number(doc, key, "integral_limit", None, 0, COEFFICIENT),
            duty_limit=self.number(doc, key, "duty_limit", 100.0, low=0, high=100,
                                   strict_low=True),
            kv=self.coefficient_list(doc["kv"], f"{key}.kv", n) if "kv" in doc else (),
            deadband=(self.numbers(doc["deadband"], f"{key}.deadband", n, 0.0, COEFFICIENT)
                      if "deadband" in doc else ()),
            integral_separation=self.number(doc, key, "integral_separation", 0.0, 0.0, 100.0),
        )

    def taps(self, value: Any, full: str, n: int) -> tuple[tuple[float, ...], ...]:
        if not isinstance(value, list) or len(value) != n:
            raise self.fail(full, f"must be a list of {n} tap lists (one per joint), "
                                  f"got {_shown(value)}")
        return tuple(self.coefficient_list(v, f"{full}[{i}]") for i, v in enumerate(value))

    def kinematics_model(self, doc: Mapping[str, Any]) -> str | None:
        kin = self.table(doc, "", "kinematics", optional=True)
        self.only(kin, "kinematics", {"model", "dh", "cartesian_jog_speed",
                                      "cartesian_jog_accel"})
        if "model" not in kin:
            return None
        return self.string(kin, "kinematics", "model", choices=KINEMATICS_MODELS)

    def jog_pair(self, doc: Mapping[str, Any], name: str, default: tuple[float, float],
                 bounds: tuple[float, float]) -> tuple[float, float]:
        """``[kinematics] name = [mm, deg]``: the Cartesian jog's translation and rotation."""
        kin = self.table(doc, "", "kinematics", optional=True)
        if name not in kin:
            return default
        mm, deg = self.numbers(kin[name], f"kinematics.{name}", 2, *bounds)
        return mm, deg

    def dh(self, doc: Mapping[str, Any], keys: list[str]) -> tuple[DHRow, ...]:
        rows = self.table(doc, "", "kinematics", optional=True).get("dh", [])
        if not isinstance(rows, list):
            raise self.fail("kinematics.dh", "must be a list of tables")
        out: list[DHRow] = []
        for i, row in enumerate(rows):
            key = f"kinematics.dh[{i}]"
            if not isinstance(row, dict):
                raise self.fail(key, "must be a table")
            self.only(row, key, {"joint", "alpha", "a", "d", "theta"})
            joint = self.string(row, key, "joint", choices=tuple(keys))
            if any(r.joint == keys.index(joint) for r in out):
                raise self.fail(f"{key}.joint", f"joint {joint!r} drives more than one DH row")
            out.append(DHRow(keys.index(joint),
                             alpha=self.number(row, key, "alpha", None, *DH_ANGLES),
                             a=self.number(row, key, "a", None, *DH_LENGTHS),
                             d=self.number(row, key, "d", None, *DH_LENGTHS),
                             theta=self.number(row, key, "theta", None, *DH_ANGLES)))
        return tuple(out)


class _Brief(reprlib.Repr):
    """``repr`` cut to a length a message can carry; an integer too long for ``repr`` (over
    4300 digits) is given by its size."""

    def __init__(self) -> None:
        super().__init__()
        self.maxstring = self.maxother = 60

    def repr_int(self, x: int, level: int) -> str:
        if x.bit_length() > 64:
            return f"<an integer of {x.bit_length()} bits>"
        return repr(x)


_BRIEF = _Brief()


def _shown(value: Any) -> str:
    """A file's value as a message shows it: repr-escaped, at most a line long."""
    return _BRIEF.repr(value)


def _key(name: str) -> str:
    """A TOML key as a message shows it: as it is when it prints, else escaped."""
    return name if _unprintable(name) is None and len(name) <= 60 else _shown(name)


def _unprintable(text: str) -> int | None:
    """Index of the first character of ``text`` that does not print as itself, or None."""
    return next((i for i, c in enumerate(text) if unicodedata.category(c) in UNPRINTABLE), None)


def _join(key: str, name: str) -> str:
    return f"{key}.{name}" if key else name
