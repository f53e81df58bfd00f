"""A path a commanding client got wrong (a script that skips the client's acceptance rules,
a bug): the controller checks every row it reads, and a row that is not a number, is past a
limit or jumps on a smooth path is a fault and a hold, never motion. (Nobody else can change
a path once sent: it is sealed, tests/control/test_service_trust.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from control import Mode
from control.motion import moves
from control.motion.plan import MovePlan
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROTATE = UNIMATE.joint_index("rotate")


@pytest.mark.parametrize(("value", "says"), [(float("nan"), "nan"), (1e308, "outside"),
                                             ("jump", "jumps")])
def test_a_bad_row_ahead_of_the_controller_is_a_fault_and_a_hold(
        controller, until, value: float | str, says: str) -> None:
    client = controller()
    start = np.array(client.status().position)
    end = start.copy()
    end[ROTATE] += 10.0
    desired = moves.sine(start, end, period=4.0, duration=4.0, machine=UNIMATE)
    row = 300
    desired[row, ROTATE] = desired[row - 1, ROTATE] + 5.0 if value == "jump" else value
    handle = client._start(MovePlan.of_path(desired, "sine"))  # past the acceptance rules
    result = client.wait(handle, timeout=10)
    assert result.status.startswith(f"fault: move {handle.move_id} row {row}: Rotate"), \
        result.status
    assert says in result.status
    assert result.run.samples == row  # nothing was done with the row itself
    status = client.status()
    assert status.mode == Mode.HOLD and not status.estop
    assert abs(status.desired[ROTATE] - result.run.actual[-1, ROTATE]) < 1.0
