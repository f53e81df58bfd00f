"""Bad input everywhere an operator or a file can give it: no crash, a clear message,
nothing started.

Property-based (hypothesis) over every parser and form: path files (TSV, CSV,
raw bytes), machine TOML files, coefficient files, the command line's numbers,
serial frames reaching the I/O board, pose inputs (the End point form's fields,
the inverse kinematics, pose files) and paths handed to a running controller.
Each property either gets a clear, one-line error of the parser's own type
that names its source (and, for a file, only lines it has), or a value that
satisfies the parser's promises (inside the limits, finite, increasing
times…). The examples tried are counted per test (``measured.example``) and
reported in the terminal summary. The file parsers also have deep variants,
ten thousand examples each (``deep_fuzz``), listed as slow in tests/conftest.py.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import dataclasses
import functools
import io
import math
import os
import re
import string
import subprocess
import sys
import tomllib
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from app import cli
from app.coefficient_files import (
    CoefficientFileError,
    dump_coefficients,
    load_coefficients,
    parse_coefficients,
)
from app.widgets.fields import FieldError, NumberCheck, position_check
from control import ControlClient
from control.motion import file_fields
from control.motion.acceptance import SAMPLING_TOLERANCE, check_path
from control.motion.cartesian import PoseFileError, PosePoints, parse_poses, read_poses
from control.motion.file_fields import FileBound, read_text_file
from control.motion.path_files import (
    PathFileError,
    PathPoints,
    parse_csv,
    parse_tsv,
    read_path,
    resample,
)
from control.motion.robot_model import builtin_unimate
from control.rt.layout import MAX_TAPS
from hw.machine import Machine, MachineError, load_machine, parse_machine
from hw.serial.emulator import EmulatedBoard
from hw.serial.messages import BoardConfig, Config, Duty, Heartbeat, MessageWriter
from hw.sim.backend import SimBackend
from kinematics import Unreachable, xyz_fixed

UNIMATE = load_machine("unimate2000b")
MACHINE_TEXT = Path(UNIMATE.path).read_text()
HOLD = (1500.0, 0.0, 0.0, 0.0, 0.0, 0.0)
DT = UNIMATE.sample_time_s
LOWER, UPPER = np.array(UNIMATE.lower), np.array(UNIMATE.upper)
MAX_SPEED = np.array([j.max_speed for j in UNIMATE.joints])


def fuzz(examples: int) -> settings:
    """Settings sized to keep the suite fast; ``measured`` is deliberately shared across
    examples (it counts them), so the function-scoped-fixture health check is off."""
    return settings(max_examples=examples, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])


def one_line(message: str, prefix: str) -> None:
    """A clear message: one line, naming its source first."""
    assert message.startswith(prefix), message
    assert "\n" not in message and "Traceback" not in message, message


# -- strategies ---------------------------------------------------------------------------

NASTY_NUMBERS = st.sampled_from(["nan", "NaN", "inf", "-inf", "1e999", "-1e999", "1e308",
                                 "", " ", "x", "1,5", "--1", "0x10", "½", "1_000", "١٢", "1e",
                                 ".", "-", "+", "٣.٥", "1e-400", "∞"])
NUMBER_TEXT = st.one_of(
    NASTY_NUMBERS,
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(-3000, 3000).map(lambda v: f"{v:.4g}"),
    st.integers(-10**6, 10**6).map(str),
    st.text(max_size=6),
)


@st.composite
def path_rows(draw: st.DrawFn) -> list[list[float]]:
    """Mostly sensible points near HOLD (so speed and limit checks are reached)."""
    n = draw(st.integers(1, 12))
    times = np.cumsum(draw(st.lists(st.floats(-0.5, 5.0), min_size=n, max_size=n)))
    rows = []
    for t in times:
        offsets = draw(st.lists(st.floats(-600.0, 600.0), min_size=6, max_size=6))
        rows.append([float(t), *(h + o * s for h, o, s in zip(
            HOLD, offsets, (1.0, 0.2, 0.05, 0.2, 0.3, 0.3), strict=True))])
    return rows


@st.composite
def mutated_table(draw: st.DrawFn, separator: str) -> tuple[list[list[str]], str]:
    """A table of number texts with some fields replaced by nasty ones."""
    rows = [[repr(v) for v in row] for row in draw(path_rows())]
    for _ in range(draw(st.integers(0, 3))):
        r = draw(st.integers(0, len(rows) - 1))
        if rows[r] and draw(st.booleans()):
            c = draw(st.integers(0, len(rows[r]) - 1))
            rows[r][c] = draw(NUMBER_TEXT)
        else:
            rows[r] = rows[r][:draw(st.integers(0, len(rows[r])))]
    extra = draw(st.sampled_from(["", "# a comment\n", "\n\n", "  # indented comment\n"]))
    return rows, extra


def tsv_text(rows: list[list[str]], extra: str) -> str:
    return extra + "".join("\t".join(row) + "\n" for row in rows)


HEADER_NAMES = st.sampled_from(["t", "time", "t [s]", "In/Out", "inout", "Rotate [deg]",
                                "Up/Down desired [deg]", "Bend actual [deg]", "Yaw duty [%]",
                                "swivel", "elbow", "", "Rotate", "x", "t"])


# -- path files ---------------------------------------------------------------------------

LINE_NUMBERS = re.compile(r"\blines? (\d+)(?:(?: and |–)(\d+))?")
QUOTED = re.compile(r"'[^']*'|\"[^\"]*\"")  # a field or a column as the file has it


def names_its_lines(message: str, source: str, text: str | None) -> None:
    """A clear message naming ``source`` first, whose every line number (``line 3``, ``lines
    3 and 4``, ``lines 3–4``) is a line of ``text``, counted as the parsers count them
    (``str.splitlines``); ``text`` None: the file is not UTF-8, it has no lines."""
    one_line(message, f"{source}: ")
    count = len(text.splitlines()) if text is not None else 0
    for match in LINE_NUMBERS.finditer(QUOTED.sub("", message)):
        assert all(1 <= int(n) <= count for n in match.groups() if n), (message, count)


def from_lines(lines: tuple[int, ...], text: str) -> None:
    """Parsed points' line numbers: one per point, increasing, each a line of ``text``."""
    assert len(lines) >= 1 and list(lines) == sorted(set(lines))
    assert lines[0] >= 1 and lines[-1] <= len(text.splitlines())


def check_points(points: PathPoints, text: str) -> None:
    """What a parsed path file promises: a point per line of ``text`` it names; times from 0,
    increasing; finite; in limits; speeds (the acceptance rules' tolerance); and a resampled
    path the smooth rules accept."""
    from_lines(points.lines, text)
    t, q = points.t, points.q
    assert len(t) >= 1 and t[0] == 0.0 and np.all(np.diff(t) > 0)
    assert np.isfinite(q).all() and np.all(q >= LOWER) and np.all(q <= UPPER)
    if len(t) > 1:
        speed = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
        assert np.all(speed <= MAX_SPEED * (1 + SAMPLING_TOLERANCE))
    check_path(resample(points, DT), "path", UNIMATE, DT)


def expect_path(read: Callable[[], PathPoints], source: str, text: str | None) -> None:
    """``read()`` raises a PathFileError naming ``source`` and only lines ``text`` has, or
    returns points that keep every promise (``check_points``)."""
    try:
        points = read()
    except PathFileError as exc:
        names_its_lines(str(exc), source, text)
    else:
        assert text is not None, "a file that is not UTF-8 was read"
        check_points(points, text)


def csv_text(header: list[str], table: tuple[list[list[str]], str]) -> str:
    """A path CSV: ``header``, then the table's rows cut to its width."""
    rows, extra = table
    return extra + ",".join(header) + "\n" + "".join(",".join(r[:len(header)]) + "\n"
                                                    for r in rows)


@fuzz(400)
@given(text=st.text(max_size=300))
def test_any_text_as_a_tsv_path_file(measured, text: str) -> None:
    """Arbitrary text read as a TSV path: PathFileError naming the file and only lines it
    has, or a valid path."""
    measured.example()
    expect_path(lambda: parse_tsv(text, UNIMATE, HOLD, "fuzz.tsv"), "fuzz.tsv", text)


@fuzz(400)
@given(table=mutated_table("\t"))
def test_damaged_tsv_path_files(measured, table: tuple[list[list[str]], str]) -> None:
    """Plausible TSV paths with damaged fields, short lines, bad times, fast or out-of-limit
    points: PathFileError naming the file and line, or a path that resamples into limits."""
    measured.example()
    text = tsv_text(*table)
    try:
        points = parse_tsv(text, UNIMATE, HOLD, "fuzz.tsv")
    except PathFileError as exc:
        names_its_lines(str(exc), "fuzz.tsv", text)
    else:
        check_points(points, text)
        path = resample(points, UNIMATE.sample_time_s)
        assert path.shape[1] == 6 and np.all(path >= LOWER) and np.all(path <= UPPER)


@fuzz(300)
@given(header=st.lists(HEADER_NAMES, min_size=0, max_size=5),
       table=mutated_table(","))
def test_damaged_csv_path_files(measured, header: list[str],
                                table: tuple[list[list[str]], str]) -> None:
    """CSV paths with any header (unknown joints, duplicates, saved-run columns) and damaged
    rows: PathFileError naming the file and line, or a valid path."""
    measured.example()
    text = csv_text(header, table)
    expect_path(lambda: parse_csv(text, UNIMATE, HOLD, "fuzz.csv"), "fuzz.csv", text)


@fuzz(150)
@given(data=st.binary(max_size=200), suffix=st.sampled_from([".tsv", ".csv", ".txt"]))
def test_any_bytes_as_a_path_file(measured, tmp_path_factory, data: bytes,
                                  suffix: str) -> None:
    """Any bytes in a path file (not UTF-8, NULs, control characters): PathFileError naming
    the file, or a valid path; never a crash."""
    measured.example()
    path, text = written(tmp_path_factory, f"bytes{suffix}", data)
    expect_path(lambda: read_path(path, UNIMATE, HOLD), str(path), text)


def written(tmp_path_factory: pytest.TempPathFactory, name: str,
            data: bytes) -> tuple[Path, str | None]:
    """A file of ``data``, and its text (None when it is not UTF-8)."""
    path = tmp_path_factory.getbasetemp() / name
    path.write_bytes(data)
    try:
        return path, data.decode("utf-8")
    except UnicodeDecodeError:
        return path, None


LINE_PIECES = st.sampled_from(["a", "1\t2", "é", "\n", "\r", "\r\n", "\x0b", "\x0c", "\x1c",
                               "\x1d", "\x1e", "\x85", "\u2028", "\u2029"])


@st.composite
def bounded_bytes(draw: st.DrawFn) -> tuple[bytes, int, int]:
    """Bytes (text of every kind of line end, or any bytes) and a bound of lines and bytes
    near what they hold, so that one line or byte either way decides."""
    data = draw(st.one_of(st.lists(LINE_PIECES, max_size=40).map(lambda p: "".join(p).encode()),
                          st.binary(max_size=60)))
    lines = len(data.decode("utf-8", "replace").splitlines())
    return (data, max(0, lines + draw(st.integers(-2, 2))),
            max(0, len(data) + draw(st.integers(-2, 2))))


@fuzz(500)
@given(case=bounded_bytes(), chunk=st.integers(1, 8))
def test_any_bytes_within_or_past_a_bound(measured, tmp_path_factory, monkeypatch,
                                          case: tuple[bytes, int, int], chunk: int) -> None:
    """Any bytes, read a few at a time, against any bound: refused naming the bound exactly
    when they pass it (in bytes, or in lines as the parsers count them: every kind of line
    end, split between two reads or not, counted once), else read whole."""
    measured.example()
    data, lines, size = case
    monkeypatch.setattr(file_fields, "CHUNK_BYTES", chunk)
    path, text = written(tmp_path_factory, "bound.txt", data)
    past = len(data) > size or (text is not None and len(text.splitlines()) > lines)
    bound = f"a fuzzed file may hold at most {lines:,} lines and {size:,} bytes (why): fix"
    try:
        _, read = read_text_file(path, FileBound("a fuzzed file", lines, size, "why", "fix"),
                                 PathFileError)
    except PathFileError as exc:
        one_line(str(exc), f"{path}: ")
        assert str(exc).endswith(bound) if past else text is None
    else:
        assert not past and read == text


def test_what_csv_itself_cannot_split_is_a_line_numbered_error() -> None:
    """A field past csv's size limit, in a path CSV and a pose CSV: the error names the file
    and the line, it is not csv's own exception."""
    huge = "1" * (csv.field_size_limit() + 1)
    with pytest.raises(PathFileError, match=r"^fuzz\.csv: line 3: field larger than"):
        parse_csv(f"t,inout\n0,1500\n1,{huge}\n", UNIMATE, HOLD, "fuzz.csv")
    with pytest.raises(PoseFileError, match=r"^fuzz\.csv: line 2: field larger than"):
        parse_poses(f"x,y,z\n{huge},0,0\n", "fuzz.csv")


def test_a_path_file_lasting_ages_is_refused_with_a_message() -> None:
    """A two-point path whose second point is at t = 1e15 s: slow enough for every joint,
    but no move can last that long; the file must be refused with a PathFileError that
    says so, not crash the Moves tab with MemoryError when it is run."""
    text = "0\t1500\t0\t0\t0\t0\t0\n1e15\t1600\t0\t0\t0\t0\t0\n"
    with pytest.raises(PathFileError, match=r"fuzz\.tsv: "):
        resample(parse_tsv(text, UNIMATE, HOLD, "fuzz.tsv"), UNIMATE.sample_time_s)


# -- machine files ------------------------------------------------------------------------

VALUE_SPANS = [m.span() for m in re.finditer(r'-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?|"[^"\n]*"',
                                             MACHINE_TEXT)]
TOML_VALUES = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "-1", "0", "1e9", "true", '"x"', "[]", "[1, 2]",
                     "{}", "-0.0", "1e-9", "300", "-300", '"deg"', '"mm"', '"gray"']),
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.integers(-10**9, 10**9).map(str),
)


def check_machine(machine: Machine) -> None:
    """What a loaded machine promises the controller."""
    assert machine.sample_time_s > 0 and machine.n_joints >= 1
    for j in machine.joints:
        assert math.isfinite(j.lower) and math.isfinite(j.upper) and j.lower < j.upper
        assert 0 <= j.min_pwm_pos <= 100 and 0 <= j.min_pwm_neg <= 100
        assert j.polarity in (1, -1) and j.max_speed > 0
    assert {"hold", "track"} <= set(machine.coefficients)


@fuzz(400)
@given(which=st.integers(0, len(VALUE_SPANS) - 1), value=TOML_VALUES)
def test_machine_files_with_a_wrong_value(measured, which: int, value: str) -> None:
    """Any one value of the Unimate's file replaced (NaN, inf, a string for a number, an
    empty list…): MachineError as ``FILE: KEY: what is wrong``, or a machine that keeps
    its promises (finite limits in order, minimum PWM in 0…100 %, polarity ±1…)."""
    measured.example()
    start, stop = VALUE_SPANS[which]
    text = MACHINE_TEXT[:start] + value + MACHINE_TEXT[stop:]
    try:
        machine = parse_machine(text, Path("fuzz.toml"))
    except MachineError as exc:
        one_line(str(exc), "fuzz.toml: ")
        assert re.match(r"fuzz\.toml: [^:]+: ", str(exc)), str(exc)
    else:
        check_machine(machine)


@fuzz(60)
@given(which=st.integers(0, len(VALUE_SPANS) - 1), value=TOML_VALUES)
def test_servodesk_machine_on_a_damaged_file(measured, tmp_path_factory, which: int,
                                             value: str) -> None:
    """``servodesk machine FILE`` on a damaged file: exit 2 with one line on stderr, or
    exit 0 describing it; never a traceback."""
    measured.example()
    start, stop = VALUE_SPANS[which]
    path = tmp_path_factory.getbasetemp() / "fuzz.toml"
    path.write_text(MACHINE_TEXT[:start] + value + MACHINE_TEXT[stop:])
    code, out, err = run_cli(["machine", str(path)])
    if code == 0:  # still a machine (a new title, say): described, from that file
        assert out.splitlines()[0].endswith(f"from {path}") and err == ""
    else:
        assert code == 2
        one_line(err.strip(), "servodesk: fuzz.toml: ")


def test_a_bad_machine_file_starts_nothing(tmp_path: Path, leftovers) -> None:
    """ControlClient on a damaged machine file raises MachineError before it creates a
    segment or a process."""
    path = tmp_path / "bad.toml"
    path.write_text(MACHINE_TEXT.replace("sample_time_ms = 1.0", "sample_time_ms = -1.0"))
    before = leftovers(os.getpid())
    with pytest.raises(MachineError, match=r"bad\.toml: machine\.sample_time_ms: "):
        ControlClient(path)
    assert leftovers(os.getpid()) == before


def test_a_file_that_is_no_machine_description_starts_nothing(not_a_machine: tuple[Path, str],
                                                              leftovers) -> None:
    """ControlClient on a file that cannot be read as a machine (not UTF-8, a directory, an
    I/O error, nested 5000 deep, an integer wider than a float…): one line of MachineError
    naming the file, before any segment or process."""
    path, message = not_a_machine
    before = leftovers(os.getpid())
    with pytest.raises(MachineError) as refused:
        ControlClient(path)
    one_line(str(refused.value), "")
    assert re.search(message, str(refused.value)), str(refused.value)
    assert leftovers(os.getpid()) == before


# -- coefficient files --------------------------------------------------------------------

TOML_NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-1000, 1000))


def toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") \
            if math.isinf(value) else repr(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return str(value)


NUMBERS = st.lists(TOML_NUMBER, min_size=0, max_size=8)
COEFFICIENT_VALUES = {
    "note": st.text(alphabet=string.printable, max_size=10),
    "kp": st.lists(NUMBERS, min_size=5, max_size=7),
    "w": st.lists(st.lists(TOML_NUMBER, max_size=10), min_size=5, max_size=7),
    "ki": st.lists(TOML_NUMBER, min_size=5, max_size=7),
    "kd": st.lists(TOML_NUMBER, min_size=5, max_size=7),
    "kv": st.lists(TOML_NUMBER, min_size=5, max_size=7),
    "filter": st.lists(TOML_NUMBER, max_size=10),
    "filter_divisor": TOML_NUMBER,
    "integral_limit": TOML_NUMBER,
    "duty_limit": TOML_NUMBER,
    "gain": TOML_NUMBER,
}


@st.composite
def coefficient_files(draw: st.DrawFn) -> str:
    """Text of a coefficient file: a valid dump with some keys replaced, dropped or added."""
    text = dump_coefficients({"hold": UNIMATE.hold, "track": UNIMATE.track}, UNIMATE)
    lines = text.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        key = draw(st.sampled_from(sorted(COEFFICIENT_VALUES)))
        value = toml_value(draw(COEFFICIENT_VALUES[key]))
        at = draw(st.integers(0, len(lines) - 1))
        if draw(st.booleans()):
            lines = [f"{key} = {value}" if ln.startswith(f"{key} = ") and i >= at else ln
                     for i, ln in enumerate(lines)]
        else:
            lines.insert(at, f"{key} = {value}")
    return "\n".join(lines) + "\n"


@fuzz(400)
@given(text=coefficient_files())
def test_damaged_coefficient_files(measured, text: str) -> None:
    """Coefficient files with wrong tap counts, NaN gains, strings, unknown keys, duplicate
    keys, too many taps: CoefficientFileError naming the file and key, or sets the
    controller can take (finite, at most MAX_TAPS taps) that dump and load back equal."""
    measured.example()
    try:
        sets = parse_coefficients(text, UNIMATE, "fuzz.toml")
    except CoefficientFileError as exc:
        one_line(str(exc), "fuzz.toml: ")
    else:
        for c in sets.values():
            taps = [*c.kp, *c.w, c.filter]
            assert all(len(t) <= MAX_TAPS for t in taps)
            values = [v for t in taps for v in t] + [*c.ki, *c.kd, *c.kv, c.filter_divisor,
                                                     c.integral_limit, c.duty_limit]
            assert all(math.isfinite(v) for v in values)
        assert parse_coefficients(dump_coefficients(sets, UNIMATE), UNIMATE) == sets


def test_a_saved_feed_forward_set_loads_back_equal() -> None:
    """A track set with velocity feed-forward (kv) saved as a coefficient file and loaded
    again is the same set: saving must not drop a coefficient."""
    tuned = dataclasses.replace(UNIMATE.track, name="tuned", kv=(0.5, 0.2, 0.3, 0.1, 0.1, 0.1))
    assert parse_coefficients(dump_coefficients({"tuned": tuned}, UNIMATE), UNIMATE) == {
        "tuned": tuned}


def test_machine_and_coefficient_files_saved_with_a_byte_order_mark_load(
        tmp_path: Path) -> None:
    """Notepad saves UTF-8 with a byte-order mark first: a machine file and a coefficient file
    so saved load as they do without it (the one TOML reader, ``hw.machine.read_text``,
    drops it, for positions files too); a damaged one still names its line."""
    bom = b"\xef\xbb\xbf"
    machine = tmp_path / "unimate.toml"
    machine.write_bytes(bom + MACHINE_TEXT.encode())
    loaded = load_machine(machine)
    assert (loaded.joints, loaded.coefficients) == (UNIMATE.joints, UNIMATE.coefficients)
    gains = tmp_path / "gains.toml"
    gains.write_bytes(bom + dump_coefficients({"track": UNIMATE.track}, UNIMATE).encode())
    assert load_coefficients(gains, UNIMATE) == {"track": UNIMATE.track}
    gains.write_bytes(bom + b"[coefficients.x]\nnote = \"\xe9\"\n")
    with pytest.raises(CoefficientFileError, match=r"gains\.toml: line 2: byte 0xe9 is not"):
        load_coefficients(gains, UNIMATE)


@pytest.mark.parametrize(("content", "says"), [
    (b"[coefficients.x]\nnote = \"\xff\xfe\"\n", "line 2: byte 0xff is not UTF-8"),
    (b"x = " + b"[" * 5000 + b"]" * 5000 + b"\n", "nested too deeply"),
    (b"# " + b"a" * (2 << 20) + b"\n", "larger than"),
    (None, "is a directory"),
])
def test_a_coefficient_file_that_is_no_text_of_ours_is_an_error_naming_it(
        tmp_path: Path, content: bytes | None, says: str) -> None:
    """Not UTF-8, nested 5,000 deep, over a megabyte, a directory: CoefficientFileError
    naming the file (the Tuning tab's Load shows it), never a traceback."""
    path = tmp_path / "gains.toml"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    with pytest.raises(CoefficientFileError, match=says) as info:
        load_coefficients(path, UNIMATE)
    one_line(str(info.value), str(path))


@fuzz(200)
@given(text=st.text(max_size=200))
def test_any_text_as_a_coefficient_file(measured, text: str) -> None:
    """Arbitrary text: CoefficientFileError naming the file (not valid TOML, no sets…)."""
    measured.example()
    with contextlib.suppress(tomllib.TOMLDecodeError):
        assume("coefficients" not in tomllib.loads(text))
    with pytest.raises(CoefficientFileError) as info:
        parse_coefficients(text, UNIMATE, "fuzz.toml")
    one_line(str(info.value), "fuzz.toml: ")


# -- the command line's numbers -------------------------------------------------------------


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``servodesk ARGV`` in process: exit code, stdout, stderr."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = cli.main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 2
    return code, out.getvalue(), err.getvalue()


CLI_NUMBER = st.one_of(NUMBER_TEXT, st.floats(-3000, 3000).map(repr),
                       st.sampled_from(["-1e3", "-inf", "-nan", "--", "-h", "-x", "1e5000"]))


@pytest.mark.filterwarnings("error")
@fuzz(300)
@given(command=st.sampled_from(["fk", "ik"]), values=st.lists(CLI_NUMBER, min_size=6,
                                                                max_size=6))
def test_fk_and_ik_numbers(measured, command: str, values: list[str]) -> None:
    """``servodesk fk`` / ``ik`` with any six arguments: exit 0 with a result, or exit 2
    with one line saying which number is wrong (or argparse's usage line); no traceback
    and no warning (numpy's, of an overflow: a warning fails the test)."""
    measured.example()
    code, out, err = run_cli([command, *values])
    assert "Traceback" not in err
    if code == 0:
        assert out and err == ""
    else:
        assert code == 2 and out == ""
        last = err.strip().splitlines()[-1]
        assert last.startswith((f"servodesk {command}: ", "servodesk: error: ",
                                f"usage: servodesk {command}")), err


ROOT = Path(__file__).resolve().parents[2]
POSE = ["1200", "-440", "1187.45", "0", "-90", "0"]  # fk of In/Out 1000 mm, the rest 0


def servodesk(argv: list[str], stdout: int = subprocess.PIPE) -> subprocess.CompletedProcess:
    """The real ``python -m app ARGV`` in a subprocess, warnings shown as a user sees them."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONWARNINGS": "default"}
    return subprocess.run([sys.executable, "-m", "app", *argv], cwd=ROOT, env=env,
                          stdout=stdout, stderr=subprocess.PIPE, text=True, timeout=60)


@pytest.mark.parametrize("argv", [["fk", "1000", "0", "0", "0", "0", "0", "--json"],
                                  ["ik", *POSE, "--json"], ["ik", *POSE],
                                  ["machine", "--json"], ["machine", "rig"]])
def test_a_reader_that_goes_away_ends_the_command_quietly(argv: list[str]) -> None:
    """``servodesk ik … --json | head`` where head has already gone: no BrokenPipeError
    traceback, nothing on stderr, and exit status 141 (128 + SIGPIPE, what the shell shows
    for a command killed by SIGPIPE: the output was cut short)."""
    read, write = os.pipe()
    os.close(read)  # the reader is gone before the command writes a byte
    try:
        done = servodesk(argv, stdout=write)
    finally:
        os.close(write)
    assert (done.returncode, done.stderr) == (141, "")


def run_cli_warning_nothing(argv: list[str]) -> tuple[int, str, str]:
    """``run_cli``, failing on any warning it raises (every one shown, as PYTHONWARNINGS=default
    shows a user its first, with nothing filtered out)."""
    with warnings.catch_warnings(record=True) as raised:
        warnings.simplefilter("always")
        done = run_cli(argv)
    assert [str(w.message) for w in raised] == []
    return done


@pytest.mark.parametrize(("argv", "message"), [
    (["fk", "1e308", "0", "0", "0", "0", "0"], "In/Out 1e+308 mm is too large: the pose overflows"),
    (["fk", "--json", "-1.7e308", "0", "0", "0", "0", "0"], "In/Out -1.7e+308 mm is too large"),
    (["ik", "1e200", "0", "0", "0", "0", "0"], "x 1e+200 mm is too large"),
    (["ik", "0", "0", "-1e300", "0", "0", "0", "--json"], "z -1e+300 mm is too large"),
    (["ik", *POSE, "--near", "1000", "1e308", "0", "0", "0", "0"],
     "--near Rotate 1e+308° is too large: the distance to it overflows"),
    (["ik", *POSE, "--json", "--near", "1e308", "0", "0", "0", "0", "0"],
     "--near In/Out 1e+308 mm is too large"),
])
def test_numbers_that_overflow_are_an_error_naming_the_input(argv: list[str],
                                                             message: str) -> None:
    """Finite numbers so large that a result is not a finite number (the pose, a solution, the
    distance to --near): exit 2 with one line naming the input; nothing on stdout and no
    numpy warning. Run by the CLI's main in this process, as the fuzzed numbers are (a
    servodesk process each, 0.2 s, showed nothing more: the process's own exits are the
    broken pipe's test)."""
    code, out, err = run_cli_warning_nothing(argv)
    assert (code, out) == (2, "")
    one_line(err.strip(), f"servodesk {argv[0]}: {message}")


def test_large_numbers_that_do_not_overflow_still_give_a_result() -> None:
    """In/Out 1e300 mm is far outside its limits but its pose is finite: fk answers, noting
    the limits, without a warning."""
    code, out, err = run_cli_warning_nothing(["fk", "1e300", "0", "0", "0", "0", "0"])
    assert code == 0 and err == ""
    assert "note: In/Out outside the joint limits" in out


@functools.cache
def parser() -> argparse.ArgumentParser:
    """servodesk's whole parser, built once (18 ms a build): parsing leaves it as it was."""
    return cli.build_parser()


@fuzz(200)
@given(option=st.sampled_from(["--corrupt-rate", "--corrupt-rx-rate", "--drop-rate",
                               "--glitch-scale", "--silent-after", "--frozen-after", "--flood",
                               "--seed", "--tcp"]),
       value=CLI_NUMBER)
def test_emulator_options(measured, option: str, value: str) -> None:
    """``servodesk emulate`` options parsed from any text: a usable value (a probability in
    0…1 for the rates) or exit 2 with argparse's message; the emulator is not started
    here, only its command line is parsed."""
    measured.example()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            args = parser().parse_args(["emulate", option, value])
        except SystemExit as exc:
            assert exc.code == 2
            assert err.getvalue().strip().splitlines()[-1].startswith("servodesk emulate: error: ")
            return
    parsed = getattr(args, option[2:].replace("-", "_"))
    if option.endswith("rate"):
        assert 0.0 <= parsed <= 1.0
    elif option in ("--seed", "--tcp", "--flood"):
        assert isinstance(parsed, int)


@pytest.mark.parametrize(("option", "value"), [("--tcp", "99999"), ("--tcp", "-1"),
                                               ("--glitch-scale", "nan"),
                                               ("--silent-after", "nan"),
                                               ("--frozen-after", "inf"), ("--flood", "2.5"),
                                               ("--stuck-bit", "2:8"), ("--stuck-bit", "x:8:1"),
                                               ("--stuck-bit", "2:8:2"),
                                               ("--stuck-bit", "2:40:1")])
def test_emulate_refuses_numbers_it_cannot_use(option: str, value: str) -> None:
    """``servodesk emulate`` refuses a port outside 0…65535, a non-finite scale or delay, a
    fractional flood and a stuck bit that is not JOINT:BIT:0|1 when parsing, with
    argparse's message naming the option (as it does for rates)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), pytest.raises(SystemExit) as info:
        parser().parse_args(["emulate", option, value])
    assert info.value.code == 2 and option in err.getvalue()


# -- serial frames at the I/O board ------------------------------------------------------------


class RecordingPlant(SimBackend):
    """The simulator, remembering every duty the board applied to it."""

    def __init__(self) -> None:
        super().__init__(UNIMATE, lockstep=True, glitch_scale=0.0)
        self.applied: list[tuple[float, ...]] = []

    def write(self, duty_pct: Sequence[float]) -> None:
        self.applied.append(tuple(duty_pct))
        super().write(duty_pct)


def feed(board: EmulatedBoard, data: bytes, cuts: list[int]) -> None:
    """Feed ``data`` in pieces cut at ``cuts``, a millisecond apart, polling between."""
    pieces = [data[a:b] for a, b in zip([0, *cuts], [*cuts, len(data)], strict=True)]
    for k, piece in enumerate(pieces):
        board.receive(piece, k * 1_000_000)
        board.poll(k * 1_000_000)


@fuzz(300)
@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 600), max_size=6))
def test_random_bytes_at_the_board_move_nothing(measured, data: bytes,
                                                cuts: list[int]) -> None:
    """Any bytes on the board's link: it never raises and never opens a valve."""
    measured.example()
    plant = RecordingPlant()
    board = EmulatedBoard(plant)
    feed(board, data, sorted(c for c in cuts if c <= len(data)))
    assert board.applied == 0
    assert all(not any(duty) for duty in plant.applied)


@st.composite
def damaged_sessions(draw: st.DrawFn) -> tuple[bytes, set[tuple[float, ...]]]:
    """A host's CONFIG, HEARTBEAT and DUTY frames with bytes flipped, lost and inserted; and
    the duty vectors (in %, as the board quantises them) the host really sent."""
    writer = MessageWriter()
    config = BoardConfig.from_machine(UNIMATE, 0.05, 0.02)
    frames = [writer.encode(Config(config)), writer.encode(Heartbeat())]
    sent: set[tuple[float, ...]] = set()
    for k in range(draw(st.integers(1, 8))):
        units = tuple(draw(st.lists(st.integers(-10_000, 10_000), min_size=6, max_size=6)))
        frames.append(writer.encode(Duty(units, clear=k == 0)))
        sent.add(tuple(round(u / config.duty_step) * config.duty_step / 100 for u in units))
    stream = bytearray(b"".join(frames))
    for _ in range(draw(st.integers(0, 6))):
        at = draw(st.integers(0, len(stream) - 1))
        action = draw(st.sampled_from(["flip", "drop", "insert"]))
        if action == "flip":
            stream[at] ^= 1 << draw(st.integers(0, 7))
        elif action == "drop":
            del stream[at]
        else:
            stream.insert(at, draw(st.integers(0, 255)))
    return bytes(stream), sent


@fuzz(300)
@given(session=damaged_sessions(), cuts=st.lists(st.integers(0, 400), max_size=4))
def test_a_damaged_session_applies_only_what_the_host_sent(
        measured, session: tuple[bytes, set[tuple[float, ...]]], cuts: list[int]) -> None:
    """A real session with bit flips, lost and inserted bytes: every duty the board applies
    is one the host sent (or all-closed); a damaged frame is counted, never acted on."""
    measured.example()
    data, sent = session
    plant = RecordingPlant()
    board = EmulatedBoard(plant)
    feed(board, data, sorted(c for c in cuts if c <= len(data)))
    closed = (0.0,) * 6
    assert all(duty == closed or duty in sent for duty in plant.applied)


# -- pose inputs --------------------------------------------------------------------------

FIELD_TEXT = st.one_of(NUMBER_TEXT, st.floats(allow_nan=True, allow_infinity=True).map(str),
                       st.text(max_size=12))


@fuzz(400)
@given(text=FIELD_TEXT, joint=st.integers(0, 5))
def test_form_fields(measured, text: str, joint: int) -> None:
    """The End point form's pose fields and a joint-target field with anything typed:
    FieldError naming the field and the fix, or a finite number inside the field's range."""
    measured.example()
    for check in (NumberCheck("x", " mm"), position_check(UNIMATE.joints[joint], UNIMATE,
                                                          "target")):
        try:
            value = check.parse(text)
        except FieldError as exc:
            one_line(str(exc), check.what)
            assert not check.validate(text).is_valid
        else:
            assert value is not None and math.isfinite(value)
            assert check.low is None or check.low <= value <= check.high
            assert check.validate(text).is_valid


@st.composite
def poses(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray | None]:
    """Poses of in-limit configurations, nudged (often out of reach), or any six floats."""
    if draw(st.booleans()):
        q = np.array([draw(st.floats(lo, hi)) for lo, hi in zip(LOWER, UPPER, strict=True)])
        p = builtin_unimate().pose(q)
        nudge = np.array(draw(st.lists(st.sampled_from([0.0, 0.0, 1.0, -50.0, 500.0, 90.0]),
                                       min_size=6, max_size=6)))
        p = p + nudge
    else:
        p = np.array(draw(st.lists(st.floats(allow_nan=True, allow_infinity=True,
                                             width=32), min_size=6, max_size=6)))
    near = draw(st.one_of(st.none(), st.lists(st.floats(-400, 2100), min_size=6, max_size=6)
                          .map(np.array)))
    return p, near


@fuzz(400)
@given(case=poses())
def test_inverse_kinematics_of_any_pose(measured,
                                        case: tuple[np.ndarray, np.ndarray | None]) -> None:
    """Any pose and any ``near``: Unreachable or ValueError with a message, or solutions
    that are all inside the limits and all reach the pose."""
    measured.example()
    p, near = case
    try:
        solutions = builtin_unimate().inverse(p, near=near)
    except (Unreachable, ValueError) as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert len(solutions) >= 1
    assert np.all(solutions >= LOWER - 1e-9) and np.all(solutions <= UPPER + 1e-9)
    t = builtin_unimate().forward(solutions)
    np.testing.assert_allclose(t[:, :3, 3], np.broadcast_to(p[:3], (len(solutions), 3)),
                               atol=1e-6)
    want = xyz_fixed.rotation(*np.radians(p[3:]))
    np.testing.assert_allclose(t[:, :3, :3], np.broadcast_to(want, t[:, :3, :3].shape),
                               atol=1e-9)


POSE_HEADER = st.lists(st.sampled_from(["t", "time", "x", "y", "z", "gamma", "beta", "alpha",
                                        "γ", "x [mm]", "w", "", "X"]), max_size=7)
POSE_ROWS = st.lists(st.lists(NUMBER_TEXT, min_size=0, max_size=7), max_size=6)


def pose_text(header: list[str], rows: list[list[str]]) -> str:
    return ",".join(header) + "\n" + "".join(",".join(r) + "\n" for r in rows)


def expect_poses(read: Callable[[], PosePoints], source: str, text: str | None) -> None:
    """``read()`` raises a PoseFileError naming ``source`` and only lines ``text`` has, or
    returns via points, one per line it names, finite, with increasing times after 0."""
    try:
        points = read()
    except PoseFileError as exc:
        names_its_lines(str(exc), source, text)
        return
    assert text is not None, "a file that is not UTF-8 was read"
    from_lines(points.lines, text)
    assert np.isfinite(points.xyz).all() and len(points.xyz) == len(points.lines)
    if points.t is not None:
        assert np.all(np.diff(np.concatenate([[0.0], points.t])) > 0)


@fuzz(300)
@given(header=POSE_HEADER, rows=POSE_ROWS)
@example(header=[], rows=[["\r", "nan"]])  # found by a random run: csv's "new-line in field"
def test_pose_files(measured, header: list[str], rows: list[list[str]]) -> None:
    """A pose CSV with any header and any fields: PoseFileError naming the file and line,
    or via points that are finite with increasing times."""
    measured.example()
    text = pose_text(header, rows)
    expect_poses(lambda: parse_poses(text, "fuzz.csv"), "fuzz.csv", text)


# -- the file parsers, deeply (slow) ------------------------------------------------------

DEEP_EXAMPLES = 10_000  # per parser, new ones on every local run
DEEP_IN_CI = 200  # CI replays a fixed set (tests/conftest.py): kept short
TSV_FILES = st.one_of(st.text(max_size=300), mutated_table("\t").map(lambda t: tsv_text(*t)))
CSV_FILES = st.one_of(st.text(max_size=300),
                      st.builds(csv_text, st.lists(HEADER_NAMES, max_size=5), mutated_table(",")))
POSE_FILES = st.one_of(st.text(max_size=300), st.builds(pose_text, POSE_HEADER, POSE_ROWS))


def deep_fuzz() -> settings:
    """``fuzz`` for the deep variants: ``DEEP_EXAMPLES``, or under CI ``DEEP_IN_CI``."""
    return fuzz(DEEP_IN_CI if os.environ.get("CI") else DEEP_EXAMPLES)


def file_bytes(texts: st.SearchStrategy[str]) -> st.SearchStrategy[bytes]:
    """A file's bytes: one of ``texts`` in UTF-8, or any bytes at all."""
    return st.one_of(texts.map(str.encode), st.binary(max_size=300))


@deep_fuzz()
@given(data=file_bytes(TSV_FILES))
def test_tsv_path_files_deeply(measured, tmp_path_factory, data: bytes) -> None:
    """Ten thousand TSV path files (any text, damaged tables, any bytes), read as the Moves
    tab reads them, bounded and parsed: a PathFileError naming the file and only lines it
    has, or points that keep every promise."""
    measured.example()
    path, text = written(tmp_path_factory, "deep.tsv", data)
    expect_path(lambda: read_path(path, UNIMATE, HOLD), str(path), text)


@deep_fuzz()
@given(data=file_bytes(CSV_FILES))
def test_csv_path_files_deeply(measured, tmp_path_factory, data: bytes) -> None:
    """Ten thousand CSV path files (any text, any header over damaged rows, any bytes): a
    PathFileError naming the file and only lines it has, or points that keep every promise."""
    measured.example()
    path, text = written(tmp_path_factory, "deep.csv", data)
    expect_path(lambda: read_path(path, UNIMATE, HOLD), str(path), text)


@deep_fuzz()
@given(data=file_bytes(POSE_FILES))
def test_pose_files_deeply(measured, tmp_path_factory, data: bytes) -> None:
    """Ten thousand pose CSVs (any text, any header over any fields, any bytes): a
    PoseFileError naming the file and only lines it has, or via points that keep theirs."""
    measured.example()
    path, text = written(tmp_path_factory, "deep.csv", data)
    expect_poses(lambda: read_poses(path, UNIMATE), str(path), text)


# -- a running controller given bad paths -------------------------------------------------


@pytest.fixture(scope="module")
def live(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlClient]:
    """One real-time controller for the module (1 kHz, not lockstep: it must stay idle)."""
    client = ControlClient("unimate2000b", data_dir=tmp_path_factory.mktemp("runs"))
    yield client
    client.close()


@st.composite
def bad_arrays(draw: st.DrawFn) -> np.ndarray:
    """Holding paths with one thing wrong: a NaN, an infinity, a point past a limit, the
    wrong number of joints, or no samples."""
    n = draw(st.integers(1, 50))
    path = np.tile(np.array(HOLD), (n, 1))
    fault = draw(st.sampled_from(["nan", "inf", "below", "above", "columns", "empty"]))
    k, j = draw(st.integers(0, n - 1)), draw(st.integers(0, 5))
    if fault == "nan":
        path[k, j] = math.nan
    elif fault == "inf":
        path[k, j] = draw(st.sampled_from([math.inf, -math.inf]))
    elif fault == "below":
        path[k, j] = LOWER[j] - draw(st.floats(1e-6, 1e6))
    elif fault == "above":
        path[k, j] = UPPER[j] + draw(st.floats(1e-6, 1e6))
    elif fault == "columns":
        path = path[:, :draw(st.sampled_from([0, 1, 5]))]
    else:
        path = path[:0]
    return path


@fuzz(150)
@given(path=bad_arrays(), as_profile=st.booleans())
def test_a_bad_path_or_profile_starts_nothing(measured, live: ControlClient, leftovers,
                                              path: np.ndarray, as_profile: bool) -> None:
    """Bad arrays handed to a running controller as a path (``move``) or a duty profile
    (``actuate``, where limits are ±100 %): ValueError with a message, no move segment
    created, the controller still holding with nothing moving."""
    measured.example()
    if as_profile:
        path = np.clip(path - np.array(HOLD)[:path.shape[1]], -1e9, 1e9) if path.size else path
        assume(path.ndim != 2 or path.shape[1] != 6 or len(path) == 0
               or not np.all(np.isfinite(path) & (np.abs(path) <= 100)))
    pid = os.getpid()
    with pytest.raises(ValueError) as info:
        (live.actuate if as_profile else live.move)(path)
    assert str(info.value) and "\n" not in str(info.value)
    assert leftovers(pid) == [live.segment_name]
    status = live.status()
    assert not status.moving and status.move_total == 0 and not status.estop
