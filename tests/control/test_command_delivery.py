"""A command reaches the control loop by its next tick (issue 29 item 1): the client sends it
from the caller's thread, so a caller that keeps running Python (a UI drawing, a script
polling the status) does not hold it back for the interpreter's switch interval, as it did
when a sender thread had to win the GIL first (6 ms from ``jog`` to the valve)."""

from __future__ import annotations

import sys

from control import ControlClient
from hw.transmission import valve_duty


def test_a_jog_is_at_the_valve_two_ticks_after_the_call_returned_while_the_caller_runs(
        lockstep: ControlClient) -> None:
    """Sent before ``jog_joint`` returns, the command is read at the start of the first tick
    begun after it: at worst the tick after the one under way when the call returned, whose
    predecessor may not have published yet; so every status from the published tick + 2 on
    shows it at the valve. The caller spins on the status meanwhile, never giving up the GIL,
    with a switch interval long enough that another thread of this process would wait for
    it far longer than those ticks take."""
    joint = lockstep.machine.joints[0]
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1.0)
    try:
        for duty in (5.0, 6.0, 5.0, 6.0):
            lockstep.jog_joint(0, duty)
            returned = lockstep.status().tick
            while (status := lockstep.status()).tick < returned + 2:
                pass
            assert status.valve[0] == valve_duty(joint, duty), (returned, status.tick)
    finally:
        sys.setswitchinterval(interval)
        lockstep.hold()
