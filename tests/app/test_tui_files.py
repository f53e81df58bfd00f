"""What the TUI reads without a controller: coefficient files (the machine file's schema,
errors naming file and key) and path files (errors naming the line)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from app.coefficient_files import (
    CoefficientFileError,
    dump_coefficients,
    load_coefficients,
    parse_coefficients,
    save_coefficients,
)
from control.motion.path_files import PathFileError, parse_csv, parse_tsv, read_path, resample
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
HERE = (1500.0, 0.0, 0.0, 0.0, 0.0, 0.0)


# -- coefficient files ---------------------------------------------------------------------

@pytest.mark.parametrize("machine", [UNIMATE, RIG], ids=lambda m: m.name)
def test_coefficient_sets_round_trip_through_a_file(machine, tmp_path: Path) -> None:
    path = save_coefficients(tmp_path / "sets", dict(machine.coefficients), machine)
    assert path.suffix == ".toml"
    assert load_coefficients(path, machine) == dict(machine.coefficients)


def test_velocity_feed_forward_is_saved_and_loaded() -> None:
    tuned = replace(UNIMATE.track, name="tuned", kv=(0.5, 0.2, 0.3, 0.1, 0.1, 0.1))
    text = dump_coefficients({"tuned": tuned}, UNIMATE)
    assert "kv = [0.5, 0.2" in text
    assert parse_coefficients(text, UNIMATE) == {"tuned": tuned}


def test_a_path_lasting_longer_than_a_move_can_is_refused() -> None:
    with pytest.raises(PathFileError, match="line 2: the path lasts 1e\\+15 s; a move lasts"):
        parse_tsv("0\t100\n1e15\t200\n", RIG, (0.0,), "long.tsv")


def test_a_machine_files_coefficient_tables_load_as_they_are() -> None:
    text = UNIMATE.path.read_text()
    tables = text[text.index("[coefficients.hold]"):]
    assert parse_coefficients(tables, UNIMATE)["thesis_pi"] == UNIMATE.coefficients["thesis_pi"]


@pytest.mark.parametrize(("text", "message"), [
    ("[coefficients.x]\nkp = [[1.0]]\n", "f.toml: coefficients.x.kp: must be a list of 6"),
    ("speed = 3\n", "f.toml: top level: unknown key(s) speed"),
    ("[coefficients]\n", "f.toml: coefficients: no [coefficients.NAME] table"),
    ('[coefficients.x]\nkp = [[1],[1],[1],[1],[1],[1]]\nki = [1,1,1,1,1,"a"]\n',
     "f.toml: coefficients.x.ki[5]: must be a number"),
    ("[coefficients.x\n", "f.toml: not valid TOML"),
])
def test_a_bad_coefficient_file_names_file_and_key(text: str, message: str) -> None:
    with pytest.raises(CoefficientFileError) as raised:
        parse_coefficients(text, UNIMATE, "f.toml")
    assert message in str(raised.value)


def test_too_many_taps_for_the_controller_are_refused() -> None:
    text = dump_coefficients({"hold": UNIMATE.coefficients["thesis_hold"]}, UNIMATE).replace(
        "kp = [[10.0]", "kp = [[1, 2, 3, 4, 5, 6, 7, 8, 9]")
    with pytest.raises(CoefficientFileError, match=r"coefficients.hold.kp\[0\]: 9 taps"):
        parse_coefficients(text, UNIMATE, "f.toml")


# -- path files ----------------------------------------------------------------------------

def test_the_thesis_tsv_is_resampled_with_its_changes_of_speed_blended() -> None:
    """Straight lines at the sample time; each change of speed a parabola at the Ram's
    max_accel, 8000 mm/s²: 12.5 ms from rest to 100 mm/s at t = 0 (the path starts 7 ms
    early), 18.75 ms from 100 to −50 mm/s at t = 1 s (passing 150²/(8·8000) mm inside the
    point), 6.25 ms to rest at t = 2 s (4 ms after it)."""
    points = parse_tsv("# time\tposition\n0\t100\n1.0\t200\n\n2.0\t150\n", RIG, (0.0,))
    assert points.lines == (2, 3, 5)
    dt = RIG.sample_time_s
    assert points.lead_s(dt) == pytest.approx(0.007)
    path = resample(points, dt)
    assert path.shape == (7 + 2000 + 4 + 1, 1)
    assert path[0, 0] == 100.0 and path[7 + 500, 0] == pytest.approx(150.0)
    assert path[7 + 1000, 0] == pytest.approx(200.0 - 150.0**2 / (8 * 8000.0))
    assert path[-1, 0] == 150.0
    assert np.abs(np.diff(path[:, 0])).max() / dt == pytest.approx(100.0)
    assert np.abs(np.diff(path[:, 0], 2)).max() / dt**2 <= 8000.0 * (1 + 1e-9)


def test_a_csv_names_its_joints_and_the_others_stay() -> None:
    points = parse_csv("t,In/Out,updown [deg]\n0,1500,0\n2,1510,5\n", UNIMATE, HERE)
    assert points.q.tolist() == [[1500, 0, 0, 0, 0, 0], [1510, 0, 5, 0, 0, 0]]
    # the joints it leaves out stay where they are when it plays, not where they were read
    later = points.held_at(np.array([1400.0, 12.0, -3.0, 4.0, 5.0, 6.0]))
    assert later.q.tolist() == [[1500, 12, 0, 4, 5, 6], [1510, 12, 5, 4, 5, 6]]


def test_a_saved_run_plays_back_its_desired_columns() -> None:
    header = ",".join(["t [s]"] + [f"{j.name} {r} [{j.unit}]" for j in UNIMATE.joints
                                   for r in ("desired", "actual", "duty")])
    row = ",".join(["0.0"] + ["1500", "1490", "3"] + ["0", "0", "0"] * 5)
    points = parse_csv(f"{header}\n{row}\n", UNIMATE, HERE)
    assert points.q[0, 0] == 1500.0


@pytest.mark.parametrize(("text", "message"), [
    ("0\t100\n1\tabc\n", "line 2: field 2 'abc' is not a number"),
    ("0\t100\n0\t200\n", "line 2: time 0 s does not increase"),
    ("0\t100\n0.01\t900\n", "line 2: Ram moves \\+800 mm in 0.01 s at t = 0.01 s: 8e\\+04 mm/s, "
     "100 times its max_speed 800 mm/s \\(machine rig\\); that change needs at least 1 s: "
     "space the points further apart"),
    ("0\t100\n0.01\t101\n0.02\t100\n", "lines 1 and 2: Ram changes speed by \\+100 mm/s at the "
     "first \\(t = 0 s\\) and by -200 mm/s at the second \\(t = 0.01 s\\), 0.01 s apart; at its "
     "max_accel 8000 mm/s² those changes need 0.0188 s \\(machine rig\\): space the points"),
    ("0\t1300\n", "line 1: Ram target 1300mm is outside 0…1200mm"),
    ("0\t100\t5\n", "line 1: 3 field\\(s\\), expected 2"),
    ("0\tnan\n", "line 1: field 2 is nan"),
])
def test_a_bad_tsv_line_is_reported_with_its_number(text: str, message: str) -> None:
    with pytest.raises(PathFileError, match=f"path.tsv: {message}"):
        parse_tsv(text, RIG, (0.0,), "path.tsv")


def test_a_bad_csv_header_lists_the_joints(tmp_path: Path) -> None:
    path = tmp_path / "p.csv"
    path.write_text("t,Elbow\n0,1\n")
    with pytest.raises(PathFileError, match="column 2 'Elbow' is not a joint of unimate2000b"):
        read_path(path, UNIMATE, HERE)
    with pytest.raises(PathFileError, match="cannot read"):
        read_path(tmp_path / "missing.csv", UNIMATE, HERE)
