"""``servodesk fk`` / ``servodesk ik``, run in-process through their argparse subcommands."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from app import cli, cli_kinematics
from app.cli_options import global_options
from control.motion.robot_model import builtin_unimate

BUILTIN = Path(__file__).resolve().parents[2] / "hw" / "machines"


def parser() -> argparse.ArgumentParser:
    """A top-level parser like app.cli's: the global --machine with its default."""
    top = argparse.ArgumentParser(prog="servodesk",
                                  parents=[global_options("machine", defaults=True)])
    cli_kinematics.add_parsers(top.add_subparsers())
    return top


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    args = parser().parse_args(argv)
    code = args.func(args)
    out, err = capsys.readouterr()
    return code, out, err


def is_row(line: str) -> bool:
    """A solution row of ``ik``'s table: a mark column, then 6 joints and a distance."""
    try:
        return line[:1] in "* " and len([float(v) for v in line[1:].split()]) == 7
    except ValueError:
        return False


HOME = ["1000", "0", "0", "0", "0", "0"]
Q = [1857.5, -20.0, 4.3, -103.9, 89.5, 13.7]  # two in-limit wrist branches


def test_fk_prints_the_pose(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["fk", *HOME], capsys)
    assert code == 0 and err == ""
    assert "x   1200.000 mm" in out
    assert "y   -440.000 mm" in out
    assert "z   1187.450 mm" in out
    assert "β    -90.000 °" in out


def test_fk_json(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(["fk", "--json", *map(str, Q)], capsys)
    assert code == 0
    doc = json.loads(out)
    assert list(doc["q"].values()) == Q
    np.testing.assert_allclose(list(doc["pose"].values()), builtin_unimate().pose(Q), atol=1e-9)
    assert list(doc["pose"]) == ["x", "y", "z", "gamma", "beta", "alpha"]
    assert doc["outside_limits"] == []


@pytest.mark.parametrize("text, value", [("-27", -27.0), ("-1e1", -10.0), ("-.5", -0.5),
                                         ("-2.5E+1", -25.0)])
def test_negative_numbers_are_values_not_options(
    capsys: pytest.CaptureFixture[str], text: str, value: float,
) -> None:
    code, out, _ = run(["fk", "--json", "1000", "0", text, "0", "0", "0"], capsys)
    assert code == 0
    assert json.loads(out)["q"]["Up/Down"] == value


def test_fk_notes_joints_outside_the_limits(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(["fk", "0", "0", "0", "0", "0", "0"], capsys)
    assert code == 0
    assert "note: In/Out outside the joint limits" in out


@pytest.mark.parametrize("bad, reason", [
    ("abc", "Bend 'abc' is not a number"),
    ("nan", "Bend 'nan' must be a finite number"),
    ("inf", "Bend 'inf' must be a finite number"),
    ("-inf", "Bend '-inf' must be a finite number"),
    ("-NaN", "Bend '-NaN' must be a finite number"),
])
def test_fk_bad_numbers_exit_2_with_one_line(
    capsys: pytest.CaptureFixture[str], bad: str, reason: str,
) -> None:
    code, out, err = run(["fk", "1000", "0", "0", bad, "0", "0"], capsys)
    assert code == 2 and out == ""
    assert err == f"servodesk fk: {reason}\n"


def test_ik_lists_every_solution_nearest_first_and_marks_the_chosen_one(
    capsys: pytest.CaptureFixture[str],
) -> None:
    pose = builtin_unimate().pose(Q)
    code, out, err = run(["ik", *map(repr, pose.tolist()), "--near", *map(str, Q)], capsys)
    assert code == 0 and err == ""
    rows = [line for line in out.splitlines() if is_row(line)]
    solutions = builtin_unimate().inverse(pose, near=Q)
    assert len(rows) == len(solutions) > 1
    assert [r[0] for r in rows] == ["*"] + [" "] * (len(rows) - 1)
    printed = np.array([[float(v) for v in r[1:].split()] for r in rows])
    np.testing.assert_allclose(printed[:, :6], solutions, atol=1e-3)
    np.testing.assert_allclose(printed[0, :6], Q, atol=1e-3)
    assert list(printed[:, 6]) == sorted(printed[:, 6])


def test_ik_json_round_trips_fk(capsys: pytest.CaptureFixture[str]) -> None:
    _, out, _ = run(["fk", "--json", *map(str, Q)], capsys)
    pose = [repr(v) for v in json.loads(out)["pose"].values()]
    code, out, _ = run(["ik", "--json", *pose, "--near", *map(str, Q)], capsys)
    assert code == 0
    doc = json.loads(out)
    assert doc["chosen"] == 0
    np.testing.assert_allclose(list(doc["solutions"][0].values()), Q, atol=1e-6)
    assert doc["distance"] == sorted(doc["distance"])
    assert doc["wrist_singular"] is False


def test_ik_default_near_is_the_middle_of_the_limits(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(["ik", "--json", "1200", "-440", "1187.45", "90", "-90", "0"], capsys)
    assert code == 0
    doc = json.loads(out)
    assert doc["near"] == {"In/Out": 1508.5, "Rotate": 0.0, "Up/Down": 1.5, "Bend": 0.0,
                           "Yaw": 2.5, "Swivel": 0.0}
    np.testing.assert_allclose(list(doc["solutions"][0].values()), [1000, 0, 0, 0, 0, 0],
                               atol=1e-9)
    assert doc["wrist_singular"] is True


def test_ik_notes_a_wrist_singularity(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = run(["ik", "1200", "-440", "1187.45", "90", "-90", "0"], capsys)
    assert code == 0
    assert "note: wrist singular" in out


def test_ik_unreachable_exits_2_with_the_reason(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["ik", "5000", "0", "0", "0", "0", "0"], capsys)
    assert code == 2 and out == ""
    assert err.startswith("servodesk ik: out of reach: In/Out would be")
    assert err.count("\n") == 1


@pytest.mark.parametrize("argv, reason", [
    (["ik", "1", "2", "x", "0", "0", "0"], "servodesk ik: z 'x' is not a number\n"),
    (["ik", "1", "2", "3", "0", "-inf", "0"], "servodesk ik: β '-inf' must be a finite number\n"),
    (["ik", *HOME, "--near", "1000", "0", "0", "0", "0", "nan"],
     "servodesk ik: Swivel 'nan' must be a finite number\n"),
])
def test_ik_bad_numbers_exit_2_with_one_line(
    capsys: pytest.CaptureFixture[str], argv: list[str], reason: str,
) -> None:
    code, out, err = run(argv, capsys)
    assert (code, out, err) == (2, "", reason)


def test_wrong_number_of_values_is_an_argparse_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        parser().parse_args(["fk", "1", "2", "3"])
    assert info.value.code == 2
    assert "required: BEND, YAW, SWIVEL" in capsys.readouterr().err


def machine_file(tmp_path: Path, old: str, new: str) -> Path:
    """The Unimate 2000B's machine file with ``old`` replaced by ``new`` (once)."""
    text = (BUILTIN / "unimate2000b.toml").read_text()
    assert text.count(old) == 1
    path = tmp_path / "unimate-variant.toml"
    path.write_text(text.replace(old, new))
    return path


def test_fk_and_ik_solve_the_machine_files_model(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A longer tool (d of the Swivel row) moves the pose; ``--machine`` before or after the
    subcommand; ik of that pose on that machine gives back the joints."""
    longer = machine_file(tmp_path, 'joint = "swivel", alpha = 0.0, a = 0.0, d = 440.0',
                          'joint = "swivel", alpha = 0.0, a = 0.0, d = 540.0')
    code, out, _ = run(["--machine", str(longer), "fk", "--json", *map(str, Q)], capsys)
    assert code == 0
    pose = np.array(list(json.loads(out)["pose"].values()))
    built_in = builtin_unimate().pose(Q)
    np.testing.assert_allclose(np.linalg.norm(pose[:3] - built_in[:3]), 100.0, atol=1e-9)
    np.testing.assert_allclose(pose[3:], built_in[3:], atol=1e-9)
    code, out, _ = run(["ik", "--json", *map(str, pose), "--near", *map(str, Q),
                        "--machine", str(longer)], capsys)
    assert code == 0
    np.testing.assert_allclose(list(json.loads(out)["solutions"][0].values()), Q, atol=1e-6)


def test_ik_respects_the_machine_files_limits(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    narrow = machine_file(tmp_path, "limits = [976.0, 2041.0]", "limits = [976.0, 1700.0]")
    pose = builtin_unimate().pose(Q)  # In/Out 1857.5 or 1777.5 mm: both above 1700
    code, _, err = run(["--machine", str(narrow), "ik", *map(str, pose)], capsys)
    assert code == 2 and "In/Out" in err and "1700" in err, err


def test_a_dh_table_of_another_form_names_the_file_and_row(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bent = machine_file(tmp_path, 'joint = "bend", alpha = 90.0', 'joint = "bend", alpha = 45.0')
    code, _, err = run(["--machine", str(bent), "fk", *HOME], capsys)
    assert code == 2
    assert err.startswith(f"servodesk fk: {bent.name}: kinematics.dh: DH row 4 (Bend) is "
                          "α 45°"), err
    assert cli.main(["machine", str(bent)]) == 2  # validating the file says so too
    assert "kinematics.dh: DH row 4 (Bend)" in capsys.readouterr().err


def test_a_machine_without_kinematics_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run(["--machine", "rig", "ik", "0", "0", "0", "0", "0", "0"], capsys)
    assert code == 2 and out == ""
    assert err.strip() == ("servodesk ik: machine rig has no unimate2000b kinematics (its "
                           "file's [kinematics] model): poses, end points and Cartesian paths "
                           "need it")
