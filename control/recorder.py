"""Saving runs, so nothing the operator ran is lost: atomically, never overwriting.

A run is three files with one stem, ``YYYYMMDD-HHMMSS-<machine>-<kind>`` (start
time in UTC; ``-2``, ``-3``… when the stem is taken):

- ``.tsv.gz`` — the thesis's layout (option.c SaveData): sample number, then
  desired, actual and duty of every joint, tab-separated, no header.
- ``.csv.gz`` — a time column in seconds and the same columns, under a header
  that names joints and units: ``t [s],Ram desired [mm],Ram actual [mm],Ram duty [%]``.
- ``.json`` — machine, kind, status, start time, sample time, coefficients,
  joints (with each one's encoder resolution and max_accel), sample count, the
  decimals the numbers were written with, file names and free-form ``meta`` (a move's
  result metrics among them, ``control/motion/plan.py``).

Numbers are written at the precision that matters (``decimals``), trailing zeros
dropped: time to the µs, duty to 0.01 %, an actual position (an encoder reading)
to a tenth of its joint's encoder count (the rig's 0.1 mm to 0.01 mm; the
listing's ``%.1f`` was too coarse for it). A desired position is a command whose
second difference at the sample time is an acceleration: it is written to the decimals
at which rounding adds at most ``DESIRED_ACCEL_SHARE`` (0.2 %) of its joint's max_accel
to one (``Run.desired_decimals``: 10⁻⁶ mm for In/Out and the rig's Ram, 10⁻⁷° for the
Unimate's angles at 1 ms), so a saved run plays again within the path rules' 1 %
(``control/motion/replay.py``). At a tenth of an encoder count, as the actual, a ramp at
max_accel would read back at 13 times it. The numbers of the JSON (its ``meta`` and
coefficients) are written to ``JSON_DIGITS`` significant digits: 0.0055, not
0.005500000000012051. A run that does not know its encoders (or its max_accel) writes
its actual (desired) positions in full. ``as_written`` is a run as it reads back.

The two tables are gzipped (``gzip -d`` or ``servodesk runs export --format csv`` gives
the plain text; numpy, pandas and servodesk's path files read them as they are): a 3.4 s
six-joint run is 0.10 MB in all instead of 1.6 MB in 17 digits, with every digit that
matters kept (``test_the_tables_are_a_tenth_of_what_they_were``). Their
text is written by numpy a block of rows at a time (``control/decimal_text.py``: the
same text, byte for byte, as a %-format per row wrote) and packed as it is made, each file
on a thread of its own (``GZIP_LEVEL``): a 60 s run is saved in a few tenths of a second.
Runs saved before (version 2 and older, plain ``.tsv`` and ``.csv``) read as they were:
a run's JSON names its files. A run is read within bounds (``load_run``): its JSON at most
``MAX_JSON_BYTES``, its CSV at most what its JSON says it holds (``table_bound``: a header
and one row per sample, no more samples than the longest move has), checked as it is
unpacked, so a damaged or hostile file (a gzip bomb, a FIFO in its place) is an error
naming it, never a MemoryError or a hang.

Each file is written to a temporary file in the same directory (named for the
saving process, ``.<pid>-<random>.tmp``), fsynced, then hard-linked to its name,
which fails if the name exists (errata #14): a crash never leaves half a file
and no run is ever overwritten, even by a concurrent save. The JSON is placed
last, and only then is the run's move segment unlinked, so at every instant a
run is either listed complete or still whole in its segment; a saver killed in
between leaves a TSV or CSV without a JSON, and temporary files, which
``remove_incomplete`` and ``remove_stale_temps`` clear when the run is saved
again from its segment (``control/recovery.py``). ``find_run`` tells, by the
run's id, whether that already happened.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import glob
import io
import json
import math
import os
import queue
import re
import sys
import threading
import uuid
import zlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import platformdirs

from control import decimal_text
from control.decimal_text import Block, Cells, Spell, counting, fixed, shortest, slots
from hw.machine import SAMPLE_TIME_MS, Coefficients, Machine
from hw.user_files import TEXT_ENCODING, NotRegularFile, open_regular

if TYPE_CHECKING:
    from control.motion.file_fields import FileBound

FORMAT = "servodesk-run"
VERSION = 4  # 2: numbers at their precision (``decimals``), joints' encoder resolution;
#              3: the TSV and CSV gzipped; 4: desired at its joint's max_accel's decimals
TIME_DECIMALS = 6  # µs
# A number of a run's table written in full, -2.2250738585072014e-308, and its separator
BYTES_PER_NUMBER = 26
MAX_JSON_BYTES = 64 << 20  # a run's metadata; a 600 s move's lists are under 1 MB
DUTY_DECIMALS = 2  # 0.01 %
# rounding a desired position may change a second difference at the sample time by this
# share of its joint's max_accel: a fifth of the path rules' 1 % (acceptance.SAMPLING_TOLERANCE)
DESIRED_ACCEL_SHARE = 0.002
JSON_DIGITS = 10  # significant digits of a JSON number: past any measurement, short of float noise
GZIP_LEVEL = 1  # 14-16 % larger than level 9, packed ten times as fast (benchmarks/run_io.py)
ROWS_AT_ONCE = 32_768  # rows written as one block (~10 MB of text): few steps, each without the GIL
MAX_SUFFIX = 10_000  # stems tried before giving up: far beyond same-second saves
_NO_HARD_LINKS = {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.ENOSYS, errno.EINVAL}
_SUFFIX = re.compile(r"\.(?:json|csv|tsv)(?:\.gz)?$")  # a run's file name less its stem


class RecorderError(OSError):
    """A run could not be saved or read; the message names the place and the reason."""


@dataclass(frozen=True, eq=False)
class Run:
    """One recorded move. Positions in mm/deg, duty in %, times in s.

    ``kind`` names the move (``step``, ``multi_step``, ``ramp``, ``sine``, ``path``,
    ``end_point``, ``tracking_actuate``, ``set_pulse``, …); ``status`` is
    ``complete``, ``estop``, ``fault: <why>`` or ``interrupted: <why>``.
    ``t (N,)`` seconds from the start of the move; ``desired``, ``actual``,
    ``duty`` ``(N, J)`` in joint order (float64 arrays are kept, not copied).
    ``coefficients`` and ``meta`` are kept as JSON-compatible copies (a
    ``Coefficients`` set, numpy scalars, arrays and paths converted). Equality
    compares every field, arrays by value (NaN equal to NaN).
    ``joint_resolution`` is each joint's encoder count in its unit (the machine
    file's ``encoder.gradient``, its size), which sets the decimals actual positions
    are saved with; empty when unknown (then every digit is saved). ``joint_max_accel``
    is each joint's max_accel (unit/s²), which sets the decimals desired positions are
    saved with (``desired_decimals``); empty when unknown (every digit).
    """

    machine: str
    kind: str
    status: str
    start_time: str  # ISO 8601, UTC
    sample_time_s: float
    coefficients: Mapping[str, Any]
    joint_names: tuple[str, ...]
    joint_units: tuple[str, ...]
    t: np.ndarray
    desired: np.ndarray
    actual: np.ndarray
    duty: np.ndarray
    meta: Mapping[str, Any] = field(default_factory=dict)
    joint_resolution: tuple[float, ...] = ()
    joint_max_accel: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "joint_names", tuple(map(str, self.joint_names)))
        put(self, "joint_units", tuple(map(str, self.joint_units)))
        put(self, "joint_resolution", tuple(map(float, self.joint_resolution)))
        put(self, "joint_max_accel", tuple(map(float, self.joint_max_accel)))
        put(self, "start_time", _utc(self.start_time).isoformat())
        coefficients = self.coefficients
        if isinstance(coefficients, Coefficients):
            coefficients = coefficients_record(coefficients)
        put(self, "coefficients", _jsonable(dict(coefficients)))
        put(self, "meta", _jsonable(dict(self.meta)))
        for name in ("t", "desired", "actual", "duty"):
            put(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        self._check()

    def _check(self) -> None:
        if not self.machine or not self.kind:
            raise ValueError("a run needs a machine name and a kind")
        if not (math.isfinite(self.sample_time_s) and self.sample_time_s > 0):
            raise ValueError(f"sample time must be positive seconds, got {self.sample_time_s}")
        n, j = len(self.t), len(self.joint_names)
        if len(self.joint_units) != j:
            raise ValueError(f"{j} joint names but {len(self.joint_units)} units")
        if self.joint_resolution and (
                len(self.joint_resolution) != j
                or not all(math.isfinite(r) and r > 0 for r in self.joint_resolution)):
            raise ValueError(f"joint_resolution must be {j} positive numbers (each joint's "
                             f"encoder count), got {self.joint_resolution}")
        if self.joint_max_accel and (
                len(self.joint_max_accel) != j
                or not all(math.isfinite(a) and a > 0 for a in self.joint_max_accel)):
            raise ValueError(f"joint_max_accel must be {j} positive numbers (each joint's "
                             f"max_accel), got {self.joint_max_accel}")
        if self.t.ndim != 1:
            raise ValueError(f"t must be (N,) seconds, got shape {self.t.shape}")
        for name in ("desired", "actual", "duty"):
            shape = getattr(self, name).shape
            if shape != (n, j):
                raise ValueError(f"{name} must be (N, J) = ({n}, {j}), got {shape}")

    @classmethod
    def from_machine(cls, machine: Machine, kind: str, status: str,
                     coefficients: Coefficients | Mapping[str, Any], t: np.ndarray,
                     desired: np.ndarray, actual: np.ndarray, duty: np.ndarray, *,
                     start_time: str | datetime | None = None,
                     meta: Mapping[str, Any] | None = None) -> Run:
        """A run of ``machine``: names, units and sample time from its description."""
        start = datetime.now(UTC) if start_time is None else start_time
        return cls(machine.name, kind, status, _utc(start).isoformat(), machine.sample_time_s,
                   coefficients, tuple(j.name for j in machine.joints),
                   tuple(j.unit for j in machine.joints), t, desired, actual, duty, meta or {},
                   resolution(machine), tuple(j.max_accel for j in machine.joints))

    @property
    def samples(self) -> int:
        return len(self.t)

    def decimals(self) -> tuple[int | None, ...]:
        """Decimals each joint's actual positions are saved with: a tenth of its encoder
        count (None: every digit, for a run that does not know its encoders)."""
        if not self.joint_resolution:
            return (None,) * len(self.joint_names)
        return tuple(max(0, math.ceil(-math.log10(r / 10) - 1e-9))
                     for r in self.joint_resolution)

    def desired_decimals(self) -> tuple[int | None, ...]:
        """Decimals each joint's desired positions are saved with: the fewest at which
        rounding (by at most half their last digit a row) changes a second difference at the
        sample time by at most ``DESIRED_ACCEL_SHARE`` of its max_accel, ``2·10⁻ᵈ/Δt²``
        (None: every digit, for a run that does not know its max_accel)."""
        if not self.joint_max_accel:
            return (None,) * len(self.joint_names)
        dt2 = self.sample_time_s ** 2
        return tuple(max(0, math.ceil(-math.log10(DESIRED_ACCEL_SHARE * a * dt2 / 2) - 1e-9))
                     for a in self.joint_max_accel)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Run):
            return NotImplemented
        arrays = ("t", "desired", "actual", "duty")
        return all(
            np.array_equal(getattr(self, f), getattr(other, f), equal_nan=True) if f in arrays
            else getattr(self, f) == getattr(other, f)
            for f in self.__dataclass_fields__
        )


@dataclass(frozen=True)
class RunFiles:
    """Where one run was saved: three paths sharing ``stem``."""

    stem: str
    tsv: Path
    csv: Path
    json: Path

    @classmethod
    def at(cls, directory: Path, stem: str) -> RunFiles:
        return cls(stem, directory / f"{stem}.tsv.gz", directory / f"{stem}.csv.gz",
                   directory / f"{stem}.json")

    @classmethod
    def from_json(cls, path: Path) -> RunFiles:
        """The files of a run from its JSON's (or any of its files', or its stem's) path."""
        path = Path(path)
        return cls.at(path.parent, _SUFFIX.sub("", path.name))

    def named_in(self, doc: Mapping[str, Any]) -> RunFiles:
        """The files as the run's JSON names them (a run saved before version 3: plain)."""
        names = doc.get("files", {})
        directory = self.json.parent
        return replace(self, **{part: directory / names[part] for part in ("tsv", "csv")
                                if isinstance(names.get(part), str)})


@dataclass(frozen=True)
class RunInfo:
    """A saved run as listed: its metadata, or why it could not be read (``problem``)."""

    files: RunFiles
    machine: str = ""
    kind: str = ""
    status: str = ""
    start_time: str = ""
    samples: int = 0
    problem: str = ""

    @property
    def damaged(self) -> bool:
        return bool(self.problem)


def default_data_dir() -> Path:
    """The user's run directory: ``<user data dir>/servodesk/runs``."""
    return Path(platformdirs.user_data_dir("servodesk", appauthor=False)) / "runs"


def resolution(machine: Machine) -> tuple[float, ...]:
    """Each joint's encoder count in its unit (mm, deg): the size of its calibration
    gradient, rtshare.h's metric_gradient."""
    return tuple(abs(j.encoder.gradient) for j in machine.joints)


def coefficients_record(c: Coefficients) -> dict[str, Any]:
    """A coefficient set as JSON-compatible data (taps newest first, as in the machine file)."""
    return _jsonable(asdict(c))


def save_run(run: Run, data_dir: Path) -> RunFiles:
    """Save ``run`` in ``data_dir`` (created if missing) under a new stem; return the files.

    Raises RecorderError naming the directory and the reason (unwritable, disk
    full, …); then nothing of this run is left in the directory and the caller
    still holds ``run``.
    """
    data_dir = Path(data_dir)
    tsv, table = _packed(run)
    base = stem_base(run)
    placed: list[Path] = []
    try:
        data_dir.mkdir(parents=True, exist_ok=True)
        for n in range(1, MAX_SUFFIX + 1):
            files = RunFiles.at(data_dir, base if n == 1 else f"{base}-{n}")
            if _place_all(((files.tsv, tsv), (files.csv, table), (files.json, _json(run, files))),
                          placed):
                _sync_dir(data_dir)
                return files
        raise OSError(errno.EEXIST, f"stems {base} to {base}-{MAX_SUFFIX} are all taken")
    except OSError as exc:
        _remove(placed)
        reason = exc.strerror or str(exc)
        raise RecorderError(f"cannot save the {run.kind} run in {data_dir}: {reason}") from exc


def stem_base(run: Run) -> str:
    """A run's stem before any ``-2``: ``YYYYMMDD-HHMMSS-<machine>-<kind>``."""
    return f"{_utc(run.start_time):%Y%m%d-%H%M%S}-{_safe(run.machine)}-{_safe(run.kind)}"


def _stems(data_dir: Path, base: str) -> list[RunFiles]:
    """The runs (or parts of runs) in ``data_dir`` under ``base`` or ``base-N``."""
    pattern = re.compile(re.escape(base) + r"(-\d+)?")
    stems = {stem for p in data_dir.glob(f"{glob.escape(base)}*")
             if _SUFFIX.search(p.name) and pattern.fullmatch(stem := _SUFFIX.sub("", p.name))}
    return [RunFiles.at(data_dir, stem) for stem in sorted(stems)]


def find_run(data_dir: Path, run: Run) -> RunFiles | None:
    """The saved copy of ``run`` (same ``run_id`` in its metadata), if one is listed."""
    run_id = run.meta.get("run_id")
    if not run_id or not Path(data_dir).is_dir():
        return None
    for files in _stems(Path(data_dir), stem_base(run)):
        with contextlib.suppress(RecorderError, OSError):
            if _read_json(files.json).get("meta", {}).get("run_id") == run_id:
                return files
    return None


def remove_incomplete(data_dir: Path, run: Run) -> list[Path]:
    """Remove the parts of a save of ``run`` that stopped before its JSON (a TSV or a CSV
    without one); the paths removed."""
    if not Path(data_dir).is_dir():
        return []
    removed = []
    for files in _stems(Path(data_dir), stem_base(run)):
        if files.json.exists():
            continue
        for part in (files.tsv, files.csv):
            with contextlib.suppress(FileNotFoundError):
                part.unlink()
                removed.append(part)
    return removed


def remove_stale_temps(data_dir: Path, alive: Callable[[int], bool]) -> list[Path]:
    """Remove temporary files left by savers that died (``alive(pid)`` says which live)."""
    if not Path(data_dir).is_dir():
        return []
    removed = []
    for tmp in Path(data_dir).glob(".*.tmp"):
        pid = tmp.name[1:].split("-", 1)[0]
        if pid.isdigit() and not alive(int(pid)):
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
                removed.append(tmp)
    return removed


def load_run(path: Path) -> Run:
    """Read a run back from its JSON and CSV; ``path`` may be any of its files or the stem.
    The CSV is read within what the JSON says it holds (``table_bound``), so a damaged or
    hostile table (a gzip bomb) is a RecorderError naming it, however much it unpacks to."""
    files = RunFiles.from_json(Path(path))
    doc = _read_json(files.json)
    files = files.named_in(doc)
    try:
        joints = doc["joints"]
        names = tuple(j["name"] for j in joints)
        columns, samples = 1 + 3 * len(names), int(doc["samples"])
        header = _csv_header(names, tuple(j["unit"] for j in joints))
        bound = table_bound(samples, columns, header, float(doc["sample_time_s"]))
        table = _read_table(files.csv, columns, samples, bound)
        resolutions = tuple(j["resolution"] for j in joints if "resolution" in j)  # version 2
        accels = tuple(j["max_accel"] for j in joints if "max_accel" in j)  # version 4
        return _run_of(doc, table, resolutions, accels)
    except (KeyError, TypeError, ValueError) as exc:
        raise RecorderError(f"{files.json}: damaged run ({type(exc).__name__}: {exc})") from exc


def as_written(run: Run) -> Run:
    """``run`` as ``load_run`` reads it back: its numbers at the precision they are saved
    with (what a saved run is compared with)."""
    table = _parse_table(csv_text(run).splitlines()[1:], 1 + 3 * len(run.joint_names))
    by_joint = table[:, 1:].reshape(len(table), len(run.joint_names), 3)
    return replace(run, t=table[:, 0], desired=by_joint[:, :, 0], actual=by_joint[:, :, 1],
                   duty=by_joint[:, :, 2], coefficients=json_numbers(run.coefficients),
                   meta=json_numbers(run.meta))


def json_numbers(value: Any) -> Any:
    """``value`` (JSON-compatible) with every float at ``JSON_DIGITS`` significant digits,
    as a run's JSON holds it: the noise of float arithmetic (0.005500000000012051) gone."""
    if isinstance(value, float):
        return float(f"{value:.{JSON_DIGITS}g}") if math.isfinite(value) else value
    if isinstance(value, Mapping):
        return {k: json_numbers(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_numbers(v) for v in value]
    return value


def _run_of(doc: Mapping[str, Any], table: np.ndarray, resolutions: tuple[float, ...],
            accels: tuple[float, ...]) -> Run:
    joints = doc["joints"]
    by_joint = table[:, 1:].reshape(len(table), len(joints), 3)
    return Run(
        machine=doc["machine"], kind=doc["kind"], status=doc["status"],
        start_time=doc["start_time"], sample_time_s=float(doc["sample_time_s"]),
        coefficients=doc["coefficients"], joint_names=tuple(j["name"] for j in joints),
        joint_units=tuple(j["unit"] for j in joints), t=table[:, 0],
        desired=by_joint[:, :, 0], actual=by_joint[:, :, 1], duty=by_joint[:, :, 2],
        meta=doc.get("meta", {}), joint_resolution=resolutions, joint_max_accel=accels,
    )


def list_runs(data_dir: Path) -> list[RunInfo]:
    """The runs saved in ``data_dir``, newest first; unreadable ones are listed as damaged."""
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        return []
    found = [(_info(p), p) for p in data_dir.glob("*.json") if not p.name.startswith(".")]
    found.sort(key=lambda item: (_sort_time(item[0], item[1]), _suffix(item[1].stem),
                                 _mtime_ns(item[1])), reverse=True)
    return [info for info, _ in found]


def _info(path: Path) -> RunInfo:
    files = RunFiles.from_json(path)
    try:
        doc = _read_json(path)
        files = files.named_in(doc)
        return RunInfo(files, str(doc["machine"]), str(doc["kind"]), str(doc["status"]),
                       _utc(doc["start_time"]).isoformat(), int(doc["samples"]))
    except (RecorderError, KeyError, TypeError, ValueError) as exc:
        return RunInfo(files, problem=str(exc))


def _sort_time(info: RunInfo, path: Path) -> datetime:
    if info.start_time:
        return _utc(info.start_time)
    with contextlib.suppress(ValueError):
        return datetime.strptime(path.name[:15], "%Y%m%d-%H%M%S").replace(tzinfo=UTC)
    return datetime.fromtimestamp(_mtime_ns(path) / 1e9, UTC)


def _suffix(stem: str) -> int:
    """The ``-2``, ``-3``… a stem got because the name was taken; 1 without one."""
    match = re.search(r"-(\d+)$", stem)
    return int(match.group(1)) if match else 1


def _mtime_ns(path: Path) -> int:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return 0


def _read_json(path: Path) -> dict[str, Any]:
    try:
        with open_regular(path) as file:  # a FIFO or a device is refused, not waited on
            data = file.read(MAX_JSON_BYTES + 1)
    except NotRegularFile as exc:
        raise RecorderError(f"{path}: {exc.strerror}, so no saved run") from exc
    except OSError as exc:
        raise RecorderError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    if len(data) > MAX_JSON_BYTES:
        raise RecorderError(f"{path}: larger than {MAX_JSON_BYTES >> 20} MB, so not a run's "
                            "metadata (a 600 s move's is under 1 MB): remove it")
    try:
        doc = json.loads(data.decode(TEXT_ENCODING))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RecorderError(f"{path}: damaged run metadata ({exc})") from exc
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise RecorderError(f"{path}: not a servodesk run (no \"format\": \"{FORMAT}\")")
    return doc


def _read_table(path: Path, columns: int, rows: int, bound: FileBound) -> np.ndarray:
    lines = table_text(path, bound).splitlines()[1:]
    table = _parse_table(lines, columns)
    if table.shape != (rows, columns):
        raise ValueError(f"{path.name} holds {table.shape[0]}×{table.shape[1]} numbers, "
                         f"the metadata says {rows}×{columns}")
    return table


def table_bound(samples: int, columns: int, header: str, sample_time_s: float) -> FileBound:
    """The most a run's CSV of ``samples`` rows of ``columns`` numbers under ``header`` may
    hold: that header and a row per sample, every number written in full
    (``BYTES_PER_NUMBER``). ValueError for more samples than the longest move has at
    ``sample_time_s`` (``acceptance.MAX_MOVE_S``; taken as no shorter than a machine's
    shortest sample time, ``SAMPLE_TIME_MS``)."""
    # the client's side: the control process only saves runs, and never imports control.motion
    from control.motion.acceptance import MAX_MOVE_S, longest_samples
    from control.motion.file_fields import FileBound

    most = longest_samples(max(sample_time_s, SAMPLE_TIME_MS[0] / 1e3))
    if not 0 <= samples <= most:
        raise ValueError(f"{samples:,} samples; a run holds at most {most:,} at its sample "
                         f"time (a move lasts at most {MAX_MOVE_S:g} s)")
    return FileBound(f"the table of a run of {samples:,} samples", samples + 1,
                     len(header.encode()) + 1 + samples * (columns * BYTES_PER_NUMBER + 1),
                     "its header and a row per sample its metadata lists, every number in "
                     "full", "the table is damaged or not this run's: remove the run")


def table_text(path: Path, bound: FileBound | None = None) -> str:
    """The text of a run's TSV or CSV, gzipped (``.gz``) or plain (version 2 and older),
    within ``bound`` (``table_bound``: a file past it is refused as soon as it passes); with
    none, whole (a table this process saved). RecorderError naming the file if it cannot
    be read, is not a regular file or is past the bound."""
    from control.motion.file_fields import FileBound, read_text_file  # as in table_bound

    whole = FileBound("a run's table", sys.maxsize, sys.maxsize, "", "")
    try:
        return read_text_file(path, bound or whole)[1]
    except ValueError as exc:  # its message names the file and why
        raise RecorderError(str(exc)) from None


def _parse_table(lines: list[str], columns: int) -> np.ndarray:
    return (np.loadtxt(lines, delimiter=",", ndmin=2, dtype=np.float64) if lines
            else np.empty((0, columns)))


def csv_text(run: Run) -> str:
    """The run's CSV: ``t [s]`` then desired, actual, duty per joint, under a header with
    names and units."""
    return (_csv_header(run.joint_names, run.joint_units) + "\n"
            + b"".join(table for _, table in _tables(run, tsv=False)).decode())


def _packed(run: Run) -> tuple[bytes, bytes]:
    """The run's TSV and CSV, gzipped (``GZIP_LEVEL``) as their text is made, a block of
    rows at a time, each on a thread of its own (zlib runs without the GIL), so a block is
    packed while the next is written."""
    tsv, table = _Gzip(), _Gzip()
    try:
        table.add((_csv_header(run.joint_names, run.joint_units) + "\n").encode())
        for tsv_text, csv_text_ in _tables(run):
            tsv.add(tsv_text)
            table.add(csv_text_)
    finally:  # the packers end, whatever happened
        packed = tsv.done(), table.done()
    return packed


_NONE = np.empty(0, dtype=np.uint8)


class _Gzip:
    """A gzip stream (a member with mtime 0) made as its text comes, packed on a thread of
    its own while the caller makes the next piece (at most ``AHEAD`` pieces wait)."""

    AHEAD = 2

    def __init__(self) -> None:
        self._packer = zlib.compressobj(GZIP_LEVEL, zlib.DEFLATED, 31)
        self._out: list[bytes] = []
        self._pieces: queue.Queue[bytes | np.ndarray | None] = queue.Queue(self.AHEAD)
        self._thread = threading.Thread(target=self._pack, name="servodesk-gzip", daemon=True)
        self._thread.start()

    def add(self, text: bytes | np.ndarray) -> None:
        self._pieces.put(text)

    def _pack(self) -> None:
        while (text := self._pieces.get()) is not None:
            self._out.append(self._packer.compress(text))
        self._out.append(self._packer.flush())

    def done(self) -> bytes:
        self._pieces.put(None)
        self._thread.join()
        return b"".join(self._out)


def _tables(run: Run, *, tsv: bool = True) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The rows of the TSV (if ``tsv``; else none) and of the CSV (no header) as ASCII
    bytes, a block of ``ROWS_AT_ONCE`` at a time: the joints' columns written once for
    both."""
    desired, actual, duty = joint_cells(run)
    for a in range(0, run.samples, ROWS_AT_ONCE):
        rows = slice(a, a + ROWS_AT_ONCE)
        joints = Block.of(*(slots(cells(rows)) for cells in (desired, actual, duty)))
        time = fixed(run.t[rows], TIME_DECIMALS, _spell(f".{TIME_DECIMALS}f", first=True),
                     negative_zero=True)
        count = slots(counting(a, a + len(run.t[rows])))
        yield (decimal_text.lines([Block.of(count), joints], b"\t") if tsv else _NONE,
               decimal_text.lines([Block.of(slots(time)), joints], b","))


def joint_cells(run: Run, spell: Callable[[str], Spell] | None = None
                ) -> tuple[Callable[[slice], Cells], ...]:
    """How the desired, actual and duty columns of a block of rows become text: desired at
    each joint's ``Run.desired_decimals``, actual at its ``Run.decimals`` (in full,
    ``repr``, where a run has none), duty to ``DUTY_DECIMALS``. ``spell`` makes the text
    of the few numbers left to Python from a %-format (the tables': ``_spell``)."""
    spell = spell or _spell
    duty = spell(f".{DUTY_DECIMALS}f")
    return (_positions(run.desired, run.desired_decimals(), spell),
            _positions(run.actual, run.decimals(), spell),
            lambda rows: fixed(run.duty[rows], DUTY_DECIMALS, duty))


def _positions(values: np.ndarray, decimals: tuple[int | None, ...],
               spell: Callable[[str], Spell]) -> Callable[[slice], Cells]:
    """A column block of positions ``values (N, J)`` at each joint's ``decimals`` (in full
    if any is None)."""
    if None in decimals:
        whole = spell("r")
        return lambda rows: shortest(values[rows], whole)
    places = np.array(decimals)
    by_joint = [spell(f".{d}f") for d in decimals]
    return lambda rows: fixed(values[rows], places, lambda v, j: by_joint[j](v, j))


def _csv_header(names: tuple[str, ...], units: tuple[str, ...]) -> str:
    """The CSV's header line (no line end): ``t [s]``, then desired, actual, duty per joint."""
    header = ["t [s]"]
    for name, unit in zip(names, units, strict=True):
        header += [f"{name} desired [{unit}]", f"{name} actual [{unit}]", f"{name} duty [%]"]
    out = io.StringIO()
    csv.writer(out, lineterminator="").writerow(header)
    return out.getvalue()


# trailing zeros of a fraction, and a fraction of zeros with its point: 1.500 → 1.5, 2.000 → 2
_TRAILING = re.compile(r"(\.\d*?)0+(?=[,\t\n])")
_BARE_POINT = re.compile(r"\.(?=[,\t\n])")
_NEGATIVE_ZERO = re.compile(r"(?<=[,\t])-0(?=[,\t\n])")


def _spell(fmt: str, *, first: bool = False) -> Spell:
    """A number's text in %-format ``fmt`` (``r``: the shortest that reads back), trailing
    zeros dropped, and ``-0`` as ``0`` unless it starts the line (``first``): for the few
    numbers ``control/decimal_text.py`` leaves to Python (NaN, ±inf, near a rounding tie,
    written with an exponent)."""
    def spell(value: float, _: int) -> str:
        text = ("," if not first else "") + ("%r" if fmt == "r" else f"%{fmt}") % value + "\n"
        text = _NEGATIVE_ZERO.sub("0", _BARE_POINT.sub("", _TRAILING.sub(r"\1", text)))
        return text[0 if first else 1:-1]
    return spell


def _json(run: Run, files: RunFiles) -> bytes:
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "machine": run.machine,
        "kind": run.kind,
        "status": run.status,
        "start_time": run.start_time,
        "sample_time_s": run.sample_time_s,
        "samples": run.samples,
        "joints": _joints(run),
        "decimals": {"t": TIME_DECIMALS, "desired": _listed(run.desired_decimals()),
                     "actual": _listed(run.decimals()), "duty": DUTY_DECIMALS},
        "coefficients": json_numbers(run.coefficients),
        "meta": json_numbers(run.meta),
        "files": {"tsv": files.tsv.name, "csv": files.csv.name, "json": files.json.name},
        "tsv_columns": "sample, then desired, actual, duty of each joint (option.c SaveData)",
    }
    return (json.dumps(doc, indent=2, ensure_ascii=False) + "\n").encode()


def _joints(run: Run) -> list[dict[str, Any]]:
    joints: list[dict[str, Any]] = [
        {"name": n, "unit": u} for n, u in zip(run.joint_names, run.joint_units, strict=True)]
    for joint, r in zip(joints, run.joint_resolution, strict=False):
        joint["resolution"] = r
    for joint, a in zip(joints, run.joint_max_accel, strict=False):
        joint["max_accel"] = a
    return joints


def _listed(decimals: tuple[int | None, ...]) -> list[int] | None:
    """Decimals as the JSON lists them: None for a column written in full."""
    return None if None in decimals else list(decimals)


def _place_all(contents: tuple[tuple[Path, bytes], ...], placed: list[Path]) -> bool:
    """Place every file, in order; if a name is taken, remove what was placed and say False."""
    for path, data in contents:
        if not _place(data, path):
            _remove(placed)
            return False
        placed.append(path)
    return True


def replace_file(data: bytes, target: Path) -> None:
    """Replace ``target`` (or create it) with exactly ``data``, complete or not at all: the
    temporary file is renamed over it, so a reader sees the old file or the new one, and a
    writer killed before the rename leaves the old one and a temporary file that
    ``remove_stale_temps`` clears. OSError if it cannot be written (then ``target`` is as
    it was)."""
    tmp = _temp_file(data, target.parent)
    try:
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    _sync_dir(target.parent)


def _place(data: bytes, target: Path) -> bool:
    """Give ``target`` exactly ``data``, complete or not at all; False if ``target`` exists."""
    if target.exists():
        return False
    tmp = _temp_file(data, target.parent)
    try:
        return _link(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def _temp_file(data: bytes, directory: Path) -> Path:
    """A new temporary file in ``directory`` named for this process, holding ``data`` on
    disk (fsynced); nothing is left behind if writing it fails."""
    tmp = directory / f".{os.getpid()}-{uuid.uuid4().hex}.tmp"
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def _link(tmp: Path, target: Path) -> bool:
    try:
        os.link(tmp, target)  # atomic, and fails if target exists: no overwrite, no race
        return True
    except FileExistsError:
        return False
    except OSError as exc:
        if exc.errno not in _NO_HARD_LINKS:
            raise
    try:  # no hard links here (FAT, some shares): reserve the name, then replace it
        os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    except FileExistsError:
        return False
    os.replace(tmp, target)
    return True


def _remove(paths: list[Path]) -> None:
    for p in paths:
        with contextlib.suppress(OSError):
            p.unlink()
    paths.clear()


def _sync_dir(directory: Path) -> None:
    """Make the new names durable; not every platform can open a directory."""
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _utc(value: str | datetime) -> datetime:
    """An aware UTC datetime from ISO text or a datetime; naive times are taken as UTC."""
    when = datetime.fromisoformat(value) if isinstance(value, str) else value
    if when.tzinfo is None:
        return when.replace(tzinfo=UTC)
    return when.astimezone(UTC)


def _safe(name: str) -> str:
    """A file-name-safe part of a stem: letters, digits, ``_`` and ``-`` only."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_")[:48] or "run"


def _jsonable(value: Any) -> Any:
    """A JSON-compatible deep copy: tuples to lists, numpy to Python, anything else to str."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)
