"""The machine file's DH table and limits are the model the kinematics package solves."""

from __future__ import annotations

import numpy as np

from hw.machine import load_machine
from kinematics import dh, unimate


def test_machine_dh_table_is_the_unimate_model() -> None:
    machine = load_machine("unimate2000b")
    links = [dh.DHLink(r.alpha, r.a, r.d, r.theta, machine.joints[r.joint].kind == "prismatic")
             for r in machine.dh]
    order = [r.joint for r in machine.dh]
    rng = np.random.default_rng(7)
    q = rng.uniform(machine.lower, machine.upper, size=(500, 6))
    np.testing.assert_allclose(dh.forward(links, q[:, order]), unimate.forward(q), atol=1e-9)
    assert (unimate.MODEL.lower, unimate.MODEL.upper) == (machine.lower, machine.upper)
