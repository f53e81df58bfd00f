"""A held key's repeats waiting in a busy app's queue are no release (app/tabs/jog.py,
``behind_queued_keys``).

A terminal sends no key-up: a held key is its auto-repeat, and its release is their
silence. The repeats reach the Jog pad through the app's message queue; the pad's release
check ran on its own timer. When the app's queue stalled (a slow handler; a loaded machine),
the check, on time, saw the repeats stop and braked the tool mid-line, though they were
waiting in the queue: a suite run broke a held Cartesian jog so. The check now waits in the
same queue, behind them.
"""

from __future__ import annotations

import asyncio
import itertools
import time
from collections.abc import Callable

import pytest

from app.tabs.jog import TOOL_RELEASE, JogPad
from control import ControlClient
from tests.app.test_tui_cartesian_jog import held_in_world_at_start

SIZE = (160, 48)
GAP_S = 0.04  # a terminal's auto-repeat, at the slow end of its 30-50 ms
STALL_S = 0.4  # the app's queue stands still this long, in the middle of the hold
KEYS = 25  # a second of repeats: the stall starts after the fifth
TRIES = 3  # holds, until one whose repeats the test itself sent on time


def standing(client: ControlClient) -> Callable[[], bool]:
    """True once the commanded joints have not moved for half a second."""
    still = [time.monotonic(), client.status().desired]

    def stands() -> bool:
        desired, now = client.status().desired, time.monotonic()
        if desired != still[1]:
            still[:] = [now, desired]
        return now - still[0] > 0.5

    return stands


def test_a_held_key_outlasts_a_stall_of_the_apps_queue(tui) -> None:
    async def scenario() -> None:
        app = tui.app(lockstep=False)
        async with app.run_test(size=SIZE) as pilot:
            await held_in_world_at_start(tui, app, pilot)
            pad = app.query_one(JogPad)
            stops: list[float] = []
            post = pad.post_message

            def recorded(message) -> bool:
                if isinstance(message, JogPad.Stopped):
                    stops.append(time.monotonic())
                return post(message)

            pad.post_message = recorded

            async def stall() -> None:  # the app's queue waits; every other task runs
                await asyncio.sleep(STALL_S)

            for _ in range(TRIES):
                stops.clear()
                before = len([e for e in app.desk.events.entries if e.kind == "jog"])
                posted = []
                for k in range(KEYS):  # z up, held
                    tui.post_key(app, "d")
                    posted.append(time.monotonic())
                    if k == 5:
                        app.call_later(stall)
                    await asyncio.sleep(GAP_S)
                let_go = time.monotonic()
                await tui.until(lambda: stops, what="the release, after the last repeat")
                gap = max(b - a for a, b in itertools.pairwise(posted))
                if gap < TOOL_RELEASE[0]:  # the test's own repeats came on time
                    break
                await tui.until(standing(app.client), timeout=10, what="the tool standing")
            else:
                pytest.fail(f"the test's own repeats came {gap:.2f} s apart in {TRIES} holds: "
                            "a loaded machine let go of the key for it")
            assert all(t >= let_go for t in stops), (
                f"released {let_go - stops[0]:.2f} s before the last repeat (repeats at most "
                f"{gap * 1000:.0f} ms apart)")
            jogs = [e.what for e in app.desk.events.entries if e.kind == "jog"][before:]
            assert len(jogs) <= 1, f"the hold broke in two: {jogs}"

    asyncio.run(scenario())
