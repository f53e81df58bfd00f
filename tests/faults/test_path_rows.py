"""A move segment damaged while the controller follows it (another process writing into
/dev/shm, a bad client): the controller checks every row it reads, and a row that is not
a number, is past a limit or jumps on a smooth path is a fault and a hold, never motion."""

from __future__ import annotations

import numpy as np
import pytest

from control import Mode
from control.motion import moves
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROTATE = UNIMATE.joint_index("rotate")


@pytest.mark.parametrize(("value", "says"), [(float("nan"), "nan"), (1e308, "outside"),
                                             ("jump", "jumps")])
def test_a_damaged_row_ahead_of_the_controller_is_a_fault_and_a_hold(
        controller, until, value: float | str, says: str) -> None:
    client = controller()  # real time: the damage lands ahead of the row being followed
    start = np.array(client.status().position)
    end = start.copy()
    end[ROTATE] += 10.0
    handle = client.move(moves.sine(start, end, period=4.0, duration=4.0, machine=UNIMATE),
                         kind="sine")
    until(lambda: client.status().move_done > 200, 10.0, "the move to run")
    desired = handle.layout.desired(handle.segment.buf)
    row = client.status().move_done + 300
    desired[row, ROTATE] = desired[row - 1, ROTATE] + 5.0 if value == "jump" else value
    result = client.wait(handle, timeout=10)
    assert result.status.startswith(f"fault: move {handle.move_id} row {row}: Rotate"), \
        result.status
    assert says in result.status
    assert result.run.samples == row  # nothing was done with the row itself
    status = client.status()
    assert status.mode == Mode.HOLD and not status.estop
    assert abs(status.desired[ROTATE] - result.run.actual[-1, ROTATE]) < 1.0
