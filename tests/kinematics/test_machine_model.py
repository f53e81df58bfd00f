"""The machine file's DH table and limits are the model the kinematics package solves
(``control.motion.robot_model``), and ``Unimate2000B.from_links`` takes only that form."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pytest

from control.motion.robot_model import dh_links, model_of, unimate_model
from hw.machine import MachineError, load_machine
from kinematics import dh, unimate
from kinematics.unimate import Unimate2000B

MACHINE = load_machine("unimate2000b")


def test_machine_dh_table_is_the_unimate_model() -> None:
    links, order = dh_links(MACHINE)
    rng = np.random.default_rng(7)
    q = rng.uniform(MACHINE.lower, MACHINE.upper, size=(500, 6))
    np.testing.assert_allclose(dh.forward(links, q[:, order]), unimate.forward(q), atol=1e-9)
    assert unimate_model(MACHINE) == unimate.MODEL
    assert model_of(load_machine("rig")) is None


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
    links = list(unimate.MODEL.links())
    links[row] = replace(links[row], **change)
    with pytest.raises(ValueError, match=rf"{re.escape(named)} is .* but the Unimate 2000B's "
                                         r"closed form needs"):
        Unimate2000B.from_links(links, unimate.MODEL.lower, unimate.MODEL.upper)


def test_rows_in_another_joint_order_are_a_machine_error() -> None:
    rows = list(MACHINE.dh)
    rows[3], rows[4] = rows[4], rows[3]
    with pytest.raises(MachineError, match=r"kinematics\.dh: rows must drive Rotate, Up/Down, "
                                           r"In/Out, Bend, Yaw, Swivel in that order"):
        unimate_model(replace(MACHINE, dh=tuple(rows)))
