"""The machine file's DH table and limits are the model the kinematics package solves
(``control.motion.robot_model``), and ``Unimate2000B.from_links`` takes only that form.
The built-in model is the built-in file's: no machine number is a constant in kinematics/,
which reads no file (tests/test_layers.py)."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from control.motion.robot_model import builtin_unimate, dh_links, model_of, unimate_model
from hw.machine import MachineError, load_machine
from kinematics import Unreachable, dh
from kinematics.unimate import Unimate2000B

MACHINE = load_machine("unimate2000b")


def test_machine_dh_table_is_the_unimate_model() -> None:
    links, order = dh_links(MACHINE)
    rng = np.random.default_rng(7)
    q = rng.uniform(MACHINE.lower, MACHINE.upper, size=(500, 6))
    np.testing.assert_allclose(dh.forward(links, q[:, order]), builtin_unimate().forward(q),
                               atol=1e-9)
    assert model_of(load_machine("rig")) is None


def test_the_builtin_model_is_the_builtin_machine_files() -> None:
    """``builtin_unimate()`` is what ``robot_model`` makes of the built-in file, loaded once,
    and that file holds Table 4.1 and rtshare.h."""
    builtin = builtin_unimate()
    assert builtin == unimate_model(MACHINE)
    assert builtin is builtin_unimate()
    assert builtin == Unimate2000B(
        d1=1066.8, a2=120.65, lb=200.0, ly=440.0,
        lower=(976.0, -110.0, -27.0, -110.0, -169.0, -180.0),
        upper=(2041.0, 110.0, 30.0, 110.0, 174.0, 180.0))


def test_a_modified_machine_file_changes_fk_and_ik(tmp_path: Path) -> None:
    """Other Table 4.1 lengths and limits in a file are the model robot_model solves."""
    text = MACHINE.path.read_text(encoding="utf-8")
    for old, new in (("d = 1066.8", "d = 900.0"), ("a = 120.65", "a = 80.0"),
                     ("d = 200.0", "d = 150.0"), ("d = 440.0", "d = 300.0"),
                     ("limits = [976.0, 2041.0]", "limits = [700.0, 1800.0]"),
                     ("limits = [-27.0, 30.0]", "limits = [-40.0, 45.0]"),
                     # its encoder reads from the new lower limit: count 0 is at -40°
                     ("gradient = 0.01432, constant = -27.0",
                      "gradient = 0.01432, constant = -40.0")):
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path = tmp_path / "unimate_modified.toml"
    path.write_text(text, encoding="utf-8")
    model = unimate_model(load_machine(path))

    # all angles 0 (section 4.4): P = (d3 + Lb, -Ly, d1 + a2)
    home = np.array([1000.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(model.pose(home)[:3], [1150.0, -300.0, 980.0], atol=1e-9)
    np.testing.assert_allclose(builtin_unimate().pose(home)[:3], [1200.0, -440.0, 1187.45],
                               atol=1e-9)

    # Up/Down 40° and In/Out 800 mm: inside the file's limits, outside the built-in ones
    q = np.array([800.0, 20.0, 40.0, 10.0, 40.0, 30.0])
    np.testing.assert_allclose(model.inverse(model.pose(q), near=q)[0], q, atol=1e-6)
    np.testing.assert_allclose(model.inverse_batch(model.pose(q), near=q).best, q, atol=1e-6)
    builtin = builtin_unimate()
    builtin_limits = replace(model, lower=builtin.lower, upper=builtin.upper)
    with pytest.raises(Unreachable, match=r"Up/Down would be 40\.0°, outside -27…30°"):
        builtin_limits.inverse(model.pose(q), near=q)


def test_from_links_takes_the_lengths_and_limits() -> None:
    lower = (1000.0, -90.0, -20.0, -100.0, -150.0, -170.0)
    upper = (1900.0, 90.0, 25.0, 100.0, 150.0, 170.0)
    model = Unimate2000B(d1=900.0, a2=80.0, lb=150.0, ly=300.0, lower=lower, upper=upper)
    assert Unimate2000B.from_links(model.links(), lower, upper) == model


@pytest.mark.parametrize("row, change, named", [
    (3, {"alpha_deg": 45.0}, "DH row 4 (Bend)"),
    (2, {"prismatic": False}, "DH row 3 (In/Out)"),
    (0, {"a": 10.0}, "DH row 1 (Rotate)"),
])
def test_from_links_refuses_another_form_naming_the_row(row: int, change: dict,
                                                        named: str) -> None:
    builtin = builtin_unimate()
    links = list(builtin.links())
    links[row] = replace(links[row], **change)
    with pytest.raises(ValueError, match=rf"{re.escape(named)} is .* but the Unimate 2000B's "
                                         r"closed form needs"):
        Unimate2000B.from_links(links, builtin.lower, builtin.upper)


def test_rows_in_another_joint_order_are_a_machine_error() -> None:
    rows = list(MACHINE.dh)
    rows[3], rows[4] = rows[4], rows[3]
    with pytest.raises(MachineError, match=r"kinematics\.dh: rows must drive Rotate, Up/Down, "
                                           r"In/Out, Bend, Yaw, Swivel in that order"):
        unimate_model(replace(MACHINE, dh=tuple(rows)))
