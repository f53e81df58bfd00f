"""``servodesk machine FILE`` and ``servodesk --machine FILE``, run in-process: a file that is
no machine description is one line on stderr and exit 2, never a traceback."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from app import cli
from app.tui import ServodeskApp

BUILTIN = Path(__file__).resolve().parents[2] / "hw" / "machines"


@pytest.mark.parametrize("form", ["servodesk machine FILE", "servodesk --machine FILE"])
def test_a_file_that_is_no_machine_description_is_one_line_and_exit_2(
        not_a_machine: tuple[Path, str], form: str, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    path, message = not_a_machine
    monkeypatch.setattr(ServodeskApp, "run", lambda self: pytest.fail(f"the TUI opened {path}"))
    argv = ["machine", str(path)] if form == "servodesk machine FILE" else ["--machine", str(path)]
    code = cli.main(argv)
    out, err = capsys.readouterr()
    assert (code, out) == (2, ""), err
    line = err.removesuffix("\n")
    assert line.startswith("servodesk: ") and "\n" not in line, err
    assert re.search(message, line.removeprefix("servodesk: ")), line


def test_a_machine_is_described_from_its_file(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["machine", str(BUILTIN / "rig.toml")]) == 0
    out, err = capsys.readouterr()
    assert out.startswith(f"Single-axis hydraulic test rig (rig) from {BUILTIN / 'rig.toml'}\n")
    assert out.endswith("\nhome: Ram 600mm\npark: Ram 10mm\n")  # the named positions
    assert err == ""


@pytest.mark.parametrize("form", ["servodesk machine FILE", "servodesk --machine FILE"])
def test_a_plant_the_simulator_cannot_run_is_refused_naming_the_key(
        form: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The machine description reads the plant's numbers; the simulator judges them
    (hw.sim.check_plant), asked before anything starts: exit 2, one line naming the key."""
    path = tmp_path / "heavy.toml"
    path.write_text((BUILTIN / "unimate2000b.toml").read_text().replace(
        "gravity_nm = 1500.0", "gravity_nm = 1e6"))
    monkeypatch.setattr(ServodeskApp, "run", lambda self: pytest.fail(f"the TUI opened {path}"))
    argv = ["machine", str(path)] if form == "servodesk machine FILE" else ["--machine", str(path)]
    code = cli.main(argv)
    out, err = capsys.readouterr()
    assert (code, out) == (2, ""), err
    assert re.fullmatch(r"servodesk: heavy\.toml: joints\[2\]\.plant: Up/Down cannot hold its "
                        r"load: .* \(plant\.supply_mpa\): raise the supply.*\n", err), err
