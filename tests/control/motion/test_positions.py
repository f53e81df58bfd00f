"""Taught positions: the file round-trips, is written atomically, and a damaged one is refused
naming its line; home and park come from the machine file."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

from control.motion.positions import (
    DECIMALS,
    MAX_NAME,
    Position,
    PositionBook,
    PositionsError,
    dump_positions,
    load_positions,
    parse_positions,
    positions_file,
    save_positions,
)
from hw.machine import load_machine

ROOT = Path(__file__).resolve().parents[3]
UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")


def book() -> PositionBook:
    return (PositionBook(UNIMATE)
            .teach("above the fixture", [1300.0, 12.5, -3.25, 45.0, 90.0, -170.0])
            .teach('pick "A" \\ Ø', [976.0, -110.0, 30.0, -110.0, 174.0, 180.0])
            .teach("p3", [1508.123456, 0.1 + 0.2, 1.5, 0.0, 2.5, 0.0]))


def test_the_file_round_trips_and_reads_as_a_person_would_write_it(tmp_path: Path) -> None:
    path = positions_file(tmp_path / "runs", UNIMATE)
    assert path == tmp_path / "runs" / "positions" / "unimate2000b.toml"
    original = book()
    save_positions(original, path)
    assert load_positions(path, UNIMATE) == original
    text = path.read_text()
    assert "[[position]]\nname = \"above the fixture\"\n" \
           "joints = [1300.0, 12.5, -3.25, 45.0, 90.0, -170.0]\n" in text
    assert "In/Out [mm], Rotate [deg]" in text  # the header says the order and the units
    assert [p.name for p in load_positions(path, UNIMATE).positions] == [
        "home", "park", "above the fixture", 'pick "A" \\ Ø', "p3"]
    assert original.find("p3").joints == (1508.123, 0.3, 1.5, 0.0, 2.5, 0.0)  # 0.001 units


def test_a_hand_written_file_with_comments_loads() -> None:
    text = """# my cell
machine = "rig"   # the rig

[[position]]
name = "top"      # near the top stop
joints = [
  1190,           # an integer is a number too
]

[[position]]
joints = [0.0]
name = "bottom"
"""
    positions = parse_positions(text, RIG, "rig.toml").positions
    assert [(p.name, p.joints, p.source) for p in positions] == [
        ("home", (600.0,), "machine file"), ("park", (10.0,), "machine file"),
        ("top", (1190.0,), "taught"), ("bottom", (0.0,), "taught")]


def test_no_file_yet_is_no_taught_position(tmp_path: Path) -> None:
    assert load_positions(tmp_path / "none.toml", RIG) == PositionBook(RIG)


def test_teach_rename_delete() -> None:
    b = book().rename("p3", "place")
    assert [p.name for p in b.taught] == ["above the fixture", 'pick "A" \\ Ø', "place"]
    assert b.find("place").joints == book().find("p3").joints
    assert b.rename("place", " place ") == b  # its own name, stripped
    b = b.delete("above the fixture")
    assert [p.name for p in b.taught] == ['pick "A" \\ Ø', "place"]
    assert b.find("home") == Position("home", UNIMATE.home, "machine file")


@pytest.mark.parametrize(("change", "message"), [
    (lambda b: b.teach("p3", UNIMATE.home), r"a position named 'p3' exists"),
    (lambda b: b.teach("Home", UNIMATE.home), r"'Home' is the machine file's home position"),
    (lambda b: b.teach("  ", UNIMATE.home), r"type a name"),
    (lambda b: b.teach("x" * (MAX_NAME + 1), UNIMATE.home), rf"at most {MAX_NAME} characters"),
    (lambda b: b.teach("a\x1b[2Jb", UNIMATE.home), r"character 2 of the name \('\\x1b'\)"),
    (lambda b: b.teach("past", (1300, 0, 30.5, 0, 90, 0)),
     r"Up/Down at 30\.5° is outside its limits -27…30°: jog it inside and teach again"),
    (lambda b: b.teach("short", (1300, 0)), r"2 joint values, unimate2000b has 6"),
    (lambda b: b.rename("p3", "above the fixture"), r"a position named 'above the fixture'"),
    (lambda b: b.rename("park", "rest"), r"park comes from the machine file"),
    (lambda b: b.delete("home"), r"home comes from the machine file \(unimate2000b\.toml\)"),
    (lambda b: b.delete("nothing"), r"no taught position named 'nothing'"),
], ids=["taken", "reserved", "empty", "long", "unprintable", "out-of-limits", "count",
        "rename-taken", "rename-park", "delete-home", "delete-missing"])
def test_an_unusable_change_is_refused_with_the_fix(change, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        change(book())


GOOD = dump_positions(book())
DAMAGED = [
    (("joints = [1300.0, 12.5", "joints = [1300.0,, 12.5"),
     r"line 12: not valid TOML: Invalid value \(column 18\)$"),
    (('name = "p3"', 'name = "p3'), r"line 19: not valid TOML: .*\(column \d+\)$"),
    (("joints = [1300.0, 12.5, -3.25, 45.0, 90.0, -170.0]", "joints = [1300.0, 12.5, -3.25]"),
     r"line 12: position 1: 'above the fixture': 3 joint values, unimate2000b has 6 "
     r"\(In/Out, Rotate, Up/Down, Bend, Yaw, Swivel\)$"),
    (("[1300.0, 12.5, -3.25, 45.0, 90.0", "[1300.0, 12.5, -31.0, 45.0, 90.0"),
     r"line 12: position 1: 'above the fixture': Up/Down at -31° is outside its limits "
     r"-27…30°$"),
    (('name = "p3"', 'name = "above the fixture"'),
     r"line 19: position 3: a position named 'above the fixture' exists"),
    (('name = "p3"', 'name = "park"'), r"line 19: position 3: 'park' is the machine file's"),
    (("[976.0,", "[inf,"), r"line 16: position 2: 'pick \"A\" \\\\ Ø': In/Out is inf, not a"),
    (("[976.0,", "[true,"), r"line 16: position 2: .*joints must be a list of numbers"),
    (('name = "p3"', 'name = 3'), r"line 19: position 3: needs a name"),
    (('name = "p3"', 'name = "p3"\nspeed = 0.5'), r"line 20: position 3: unknown key 'speed'"),
    (('machine = "unimate2000b"', 'machine = "rig"'),
     r"line 8: the positions of machine 'rig', not 'unimate2000b'"),
    (('machine = "unimate2000b"', 'machine = "unimate2000b"\npositions = []'),
     r"line 9: unknown key 'positions'"),
]


@pytest.mark.parametrize(("edit", "message"), DAMAGED, ids=[m[:40] for _, m in DAMAGED])
def test_a_damaged_file_is_refused_naming_its_line(tmp_path: Path, edit: tuple[str, str],
                                                   message: str) -> None:
    old, new = edit
    assert GOOD.count(old) == 1, old
    path = tmp_path / "unimate2000b.toml"
    path.write_text(GOOD.replace(old, new))
    with pytest.raises(PositionsError, match="^" + str(path).replace(".", r"\.") + ": " + message):
        load_positions(path, UNIMATE)


def test_a_file_that_is_not_text_or_not_a_file_is_refused_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "rig.toml"
    path.write_bytes(b'machine = "rig"\n\n[[position]]\nname = "caf\xe9"\n')
    with pytest.raises(PositionsError, match=r"rig\.toml: line 4: byte 0xe9 is not UTF-8"):
        load_positions(path, RIG)
    path.unlink()
    path.mkdir()
    with pytest.raises(PositionsError, match=r"rig\.toml: is a directory"):
        load_positions(path, RIG)


@pytest.mark.timeout(20)  # a FIFO opened for reading waits for a writer: for ever
def test_a_file_saved_with_a_byte_order_mark_loads_and_a_fifo_is_refused(
        tmp_path: Path) -> None:
    """A positions file saved by Notepad (a UTF-8 byte-order mark first, CRLF line ends)
    loads as the same file without them; a named pipe in its place is refused at once, naming
    it and what it is."""
    path = save_positions(book(), tmp_path / "unimate2000b.toml")
    text = path.read_text()
    path.write_bytes(b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode())
    assert load_positions(path, UNIMATE) == book()
    path.unlink()
    os.mkfifo(path)
    with pytest.raises(PositionsError, match=rf"^{path}: not a regular file but a named pipe "
                                             r"\(FIFO\): give a positions file \(TOML\)$"):
        load_positions(path, UNIMATE)


def test_a_write_that_fails_leaves_the_old_file_and_no_temporary(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = save_positions(book(), tmp_path / "unimate2000b.toml")
    before = path.read_bytes()

    def disk_full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", disk_full)
    with pytest.raises(PositionsError, match=r"unimate2000b\.toml: cannot write it: No space "
                                             r"left on device; the file is as it was$"):
        save_positions(book().delete("p3"), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["unimate2000b.toml"]


KILLED_WRITER = """
import os, signal, sys
from control.motion.positions import PositionBook, load_positions, save_positions
from hw.machine import load_machine

machine = load_machine("unimate2000b")
path = sys.argv[1]
book = load_positions(path, machine).teach("new", machine.park)
os.replace = lambda *args: os.kill(os.getpid(), signal.SIGKILL)  # dies between temp and rename
save_positions(book, path)
"""


def test_a_writer_killed_between_temporary_and_rename_leaves_the_old_file(
        tmp_path: Path) -> None:
    path = save_positions(book(), tmp_path / "unimate2000b.toml")
    before = path.read_bytes()
    writer = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(path)], cwd=ROOT,
                              env={**os.environ, "PYTHONPATH": str(ROOT)},
                              stderr=subprocess.PIPE)
    _, err = writer.communicate(timeout=60)
    assert writer.returncode == -9, err.decode()
    assert path.read_bytes() == before  # whole, and the old one
    (temp,) = (p for p in tmp_path.iterdir() if p.name.endswith(".tmp"))
    assert temp.name.startswith(f".{writer.pid}-")  # named for the writer that died
    assert load_positions(path, UNIMATE) == book()
    assert "name = \"new\"" in temp.read_text()  # the new file was complete, never renamed
    save_positions(book().delete("p3"), path)  # the next save clears the dead writer's temp
    assert sorted(p.name for p in tmp_path.iterdir()) == ["unimate2000b.toml"]
    assert [p.name for p in load_positions(path, UNIMATE).taught] == [
        "above the fixture", 'pick "A" \\ Ø']


def test_teaching_keeps_the_reading_to_a_thousandth() -> None:
    b = PositionBook(RIG).teach("r", [599.99951])
    assert b.find("r").joints == (round(599.99951, DECIMALS),) == (600.0,)


def test_a_joint_resting_just_past_a_limit_is_taught_on_it() -> None:
    (ram,) = RIG.joints  # on its bottom stop the rig reads -0.1 mm; its tolerance is 1 mm
    assert PositionBook(RIG).teach("stop", [-0.1]).find("stop").joints == (ram.lower,)
    assert PositionBook(RIG).teach("top", [1200.9]).find("top").joints == (ram.upper,)
    with pytest.raises(ValueError, match=r"Ram at -1\.5mm is outside its limits 0…1200mm: jog"):
        PositionBook(RIG).teach("below", [-1.5])
