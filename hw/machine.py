"""Machine descriptions: TOML files loaded into frozen dataclasses.

A machine file describes joints (names, kinds, units, limits), encoder kind and
calibration, minimum PWM, valve polarity, the DH table and the controller
coefficient sets. The schema is documented in ``docs/machines.md``. Every error
names the file, the key and what is wrong, so a user adding a third machine
with ``--machine PATH`` can fix it from the message alone.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any

BUILTIN = {"unimate2000b": "unimate2000b.toml", "unimate": "unimate2000b.toml", "rig": "rig.toml"}
JOINT_KINDS = {"prismatic": "mm", "revolute": "deg"}
ENCODER_KINDS = ("gray", "quadrature")
MIN_FERROR_DIVISOR = 10.0  # min_following_error defaults to following_error / 10


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
    """

    window_s: float = 0.2
    closing_fraction: float = 0.25
    open_margin_pct: float = 10.0
    range_margin_counts: float = 20.0
    glitch_limit: int = 5
    overrun_fraction: float = 0.2
    stall_s: float = 0.05


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
    """Load a built-in machine by name (``unimate2000b``, ``rig``) or a TOML file by path."""
    text_spec = str(spec)
    if text_spec in BUILTIN:
        ref = resources.files("hw.machines").joinpath(BUILTIN[text_spec])
        return parse_machine(ref.read_text(encoding="utf-8"), Path(str(ref)))
    path = Path(spec)
    if not path.is_file():
        raise MachineError(
            f"{path}: no such machine file (built-in machines: {', '.join(builtin_names())})"
        )
    return parse_machine(path.read_text(encoding="utf-8"), path)


def parse_machine(text: str, path: Path) -> Machine:
    """Parse and validate the text of a machine file; ``path`` is used in messages."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MachineError(f"{path.name}: not valid TOML: {exc}") from None
    return _Reader(path.name).machine(doc, path)


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
            raise self.fail(key or "top level", f"unknown key(s) {', '.join(unknown)}; "
                            f"allowed: {', '.join(sorted(allowed))}")

    def number(self, doc: Mapping[str, Any], key: str, name: str, default: float | None = None,
               low: float = -math.inf, high: float = math.inf, strict_low: bool = False) -> float:
        full = _join(key, name)
        if name not in doc:
            if default is None:
                raise self.fail(full, "missing number")
            return default
        return self.check_number(doc[name], full, low, high, strict_low)

    def check_number(self, value: Any, full: str, low: float = -math.inf, high: float = math.inf,
                     strict_low: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(full, f"must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(full, f"must be finite, got {value}")
        too_low = value <= low if strict_low else value < low
        if too_low or value > high:
            bound = f"> {low:g}" if strict_low else f">= {low:g}"
            rng = bound if high == math.inf else f"in {low:g}…{high:g}"
            raise self.fail(full, f"{value:g} out of range (must be {rng})")
        return value

    def numbers(self, value: Any, full: str, length: int | None = None) -> tuple[float, ...]:
        if not isinstance(value, list):
            raise self.fail(full, f"must be a list of numbers, got {value!r}")
        if length is not None and len(value) != length:
            raise self.fail(full, f"must have {length} entries, got {len(value)}")
        return tuple(self.check_number(v, f"{full}[{i}]") for i, v in enumerate(value))

    def string(self, doc: Mapping[str, Any], key: str, name: str, default: str | None = None,
               choices: tuple[str, ...] | None = None) -> str:
        full = _join(key, name)
        value = doc.get(name, default)
        if value is None:
            raise self.fail(full, "missing string")
        if not isinstance(value, str) or not value:
            raise self.fail(full, f"must be a non-empty string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.fail(full, f"{value!r} is not one of {', '.join(choices)}")
        return value

    def plant(self, doc: Mapping[str, Any], key: str) -> Mapping[str, float]:
        table = self.table(doc, key, "plant", optional=True)
        return MappingProxyType(
            {name: self.check_number(v, _join(key, f"plant.{name}")) for name, v in table.items()}
        )

    def machine(self, doc: Mapping[str, Any], path: Path) -> Machine:
        self.only(doc, "", {"machine", "valve", "encoder", "kinematics", "joints",
                            "coefficients", "plant", "supervisor"})
        head = self.table(doc, "", "machine")
        self.only(head, "machine", {"name", "title", "sample_time_ms"})
        valve = self.table(doc, "", "valve")
        self.only(valve, "valve", {"period_us", "resolution_pct"})
        enc = self.table(doc, "", "encoder")
        self.only(enc, "encoder", {"kind", "bits", "settle_ms"})
        raw_joints = doc.get("joints")
        if not isinstance(raw_joints, list) or not raw_joints:
            raise self.fail("joints", "missing: at least one [[joints]] table is required")
        keys = [self.string(j, f"joints[{i}]", "key") if isinstance(j, dict) else ""
                for i, j in enumerate(raw_joints)]
        for i, k in enumerate(keys):
            if keys.index(k) != i:
                raise self.fail(f"joints[{i}].key", f"duplicate joint key {k!r}")
        joints = tuple(self.joint(j, i, keys) for i, j in enumerate(raw_joints))
        encoder_kind = self.string(enc, "encoder", "kind", choices=ENCODER_KINDS)
        bits = self.number(enc, "encoder", "bits", 16.0 if encoder_kind == "quadrature" else None,
                           low=1, high=32)
        if bits != int(bits):
            raise self.fail("encoder.bits", f"must be a whole number, got {bits:g}")
        return Machine(
            name=self.string(head, "machine", "name"),
            title=self.string(head, "machine", "title"),
            path=path,
            sample_time_s=self.number(head, "machine", "sample_time_ms", low=0.05, high=100) / 1e3,
            valve_period_us=self.number(valve, "valve", "period_us", low=0, strict_low=True),
            valve_resolution_pct=self.number(valve, "valve", "resolution_pct", low=0, high=100,
                                             strict_low=True),
            encoder_kind=encoder_kind,
            encoder_bits=int(bits),
            encoder_settle_s=self.number(enc, "encoder", "settle_ms", 0.0, low=0) / 1e3,
            joints=joints,
            coefficients=self.coefficient_sets(doc, len(joints)),
            kinematics_model=self.kinematics_model(doc),
            dh=self.dh(doc, keys),
            plant=self.plant(doc, ""),
            supervision=self.supervision(doc),
        )

    def supervision(self, doc: Mapping[str, Any]) -> Supervision:
        table = self.table(doc, "", "supervisor", optional=True)
        key = "supervisor"
        self.only(table, key, {"window_ms", "closing_fraction", "open_margin_pct",
                               "range_margin_counts", "glitch_limit", "overrun_fraction",
                               "stall_ms"})
        d = Supervision()
        glitch_limit = self.number(table, key, "glitch_limit", d.glitch_limit, low=1, high=1000)
        if glitch_limit != int(glitch_limit):
            raise self.fail(f"{key}.glitch_limit", f"must be a whole number, got {glitch_limit:g}")
        return Supervision(
            window_s=self.number(table, key, "window_ms", d.window_s * 1e3, low=10,
                                 high=1000) / 1e3,
            closing_fraction=self.number(table, key, "closing_fraction", d.closing_fraction,
                                         low=0, high=1, strict_low=True),
            open_margin_pct=self.number(table, key, "open_margin_pct", d.open_margin_pct,
                                        low=0, high=100),
            range_margin_counts=self.number(table, key, "range_margin_counts",
                                            d.range_margin_counts, low=1, high=1e6),
            glitch_limit=int(glitch_limit),
            overrun_fraction=self.number(table, key, "overrun_fraction", d.overrun_fraction,
                                         low=0, high=1, strict_low=True),
            stall_s=self.number(table, key, "stall_ms", d.stall_s * 1e3, low=2,
                                high=10_000) / 1e3,
        )

    def joint(self, doc: Any, index: int, keys: list[str]) -> Joint:
        key = f"joints[{index}]"
        if not isinstance(doc, dict):
            raise self.fail(key, "must be a table")
        self.only(doc, key, {"key", "name", "kind", "unit", "limits", "min_pwm", "polarity",
                             "max_speed", "max_accel", "tolerance", "following_error",
                             "min_following_error", "encoder", "down_scale", "gain_unit",
                             "plant"})
        name = self.string(doc, key, "name")
        kind = self.string(doc, key, "kind", choices=tuple(JOINT_KINDS))
        unit = self.string(doc, key, "unit", choices=(JOINT_KINDS[kind],))
        lower, upper = self.numbers(doc.get("limits"), f"{key}.limits", 2)
        if lower >= upper:
            raise self.fail(f"{key}.limits", f"lower {lower:g} must be below upper {upper:g}")
        pos, neg = self.numbers(doc.get("min_pwm"), f"{key}.min_pwm", 2)
        for label, v in (("positive", pos), ("negative", neg)):
            if not 0 <= v < 100:
                raise self.fail(f"{key}.min_pwm", f"{label} minimum {v:g} must be in 0…100 %")
        polarity = self.number(doc, key, "polarity")
        if polarity not in (1.0, -1.0):
            raise self.fail(f"{key}.polarity", f"must be 1 or -1, got {polarity:g}")
        return Joint(
            key=keys[index], name=name, kind=kind, unit=unit, lower=lower, upper=upper,
            min_pwm_pos=pos, min_pwm_neg=neg, polarity=int(polarity),
            max_speed=self.number(doc, key, "max_speed", low=0, strict_low=True),
            max_accel=self.number(doc, key, "max_accel", low=0, strict_low=True),
            tolerance=self.number(doc, key, "tolerance", low=0, strict_low=True),
            following_error=(ferror := self.number(doc, key, "following_error", low=0,
                                                   strict_low=True)),
            min_following_error=self.number(doc, key, "min_following_error",
                                            ferror / MIN_FERROR_DIVISOR, low=0,
                                            high=ferror, strict_low=True),
            encoder=self.encoder_cal(doc, index, keys),
            down_scale=self.number(doc, key, "down_scale", 1.0, low=0, high=1, strict_low=True),
            gain_unit=self.number(doc, key, "gain_unit", 1.0, low=0, strict_low=True),
            plant=self.plant(doc, key),
        )

    def encoder_cal(self, joint: Mapping[str, Any], index: int, keys: list[str]) -> EncoderCal:
        key = f"joints[{index}].encoder"
        doc = self.table(joint, f"joints[{index}]", "encoder")
        self.only(doc, key, {"gradient", "constant", "coupled_to", "coupling"})
        gradient = self.number(doc, key, "gradient")
        if gradient == 0:
            raise self.fail(f"{key}.gradient", "must not be zero")
        coupled = doc.get("coupled_to")
        if coupled is not None and coupled not in keys:
            raise self.fail(f"{key}.coupled_to", f"{coupled!r} is not a joint key "
                            f"(joints: {', '.join(keys)})")
        if coupled is not None and keys.index(coupled) == index:
            raise self.fail(f"{key}.coupled_to", "a joint cannot be coupled to itself")
        return EncoderCal(
            gradient=gradient,
            constant=self.number(doc, key, "constant"),
            coupled_to=None if coupled is None else keys.index(coupled),
            coupling=self.number(doc, key, "coupling", 0.0 if coupled is None else None),
        )

    def coefficient_sets(self, doc: Mapping[str, Any], n: int,
                         required: tuple[str, ...] = ("hold", "track")
                         ) -> Mapping[str, Coefficients]:
        sets = self.table(doc, "", "coefficients")
        if not sets:
            raise self.fail("coefficients", "no [coefficients.NAME] table")
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
                             "integral_limit", "duty_limit", "kv"})
        return Coefficients(
            name=name,
            note=self.string(doc, key, "note", default=name),
            kp=self.taps(doc.get("kp"), f"{key}.kp", n),
            ki=self.numbers(doc.get("ki"), f"{key}.ki", n),
            kd=self.numbers(doc.get("kd"), f"{key}.kd", n),
            w=self.taps(doc.get("w"), f"{key}.w", n),
            filter=self.numbers(doc.get("filter"), f"{key}.filter"),
            filter_divisor=self.number(doc, key, "filter_divisor", low=0, strict_low=True),
            integral_limit=self.number(doc, key, "integral_limit", low=0),
            duty_limit=self.number(doc, key, "duty_limit", 100.0, low=0, high=100,
                                   strict_low=True),
            kv=self.numbers(doc["kv"], f"{key}.kv", n) if "kv" in doc else (),
        )

    def taps(self, value: Any, full: str, n: int) -> tuple[tuple[float, ...], ...]:
        if not isinstance(value, list) or len(value) != n:
            raise self.fail(full, f"must be a list of {n} tap lists (one per joint), got {value!r}")
        return tuple(self.numbers(v, f"{full}[{i}]") for i, v in enumerate(value))

    def kinematics_model(self, doc: Mapping[str, Any]) -> str | None:
        kin = self.table(doc, "", "kinematics", optional=True)
        self.only(kin, "kinematics", {"model", "dh"})
        return self.string(kin, "kinematics", "model") if "model" in kin else None

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
            out.append(DHRow(keys.index(joint), *(self.number(row, key, f)
                                                   for f in ("alpha", "a", "d", "theta"))))
        return tuple(out)


def _join(key: str, name: str) -> str:
    return f"{key}.{name}" if key else name
