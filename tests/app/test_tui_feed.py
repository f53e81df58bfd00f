"""Feed override and feed hold from the keyboard, on every tab: ctrl+↓/↑ set the override
in tenths, ctrl+f holds the running move and resumes it, and the header says so."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import numpy as np

from app.widgets.live_text import LiveText
from control.motion import moves
from hw.machine import load_machine

SIZE = (160, 48)
UNIMATE = load_machine("unimate2000b")


def test_feed_keys_and_the_moves_tabs_buttons_slow_hold_and_resume_a_running_move(tui) -> None:
    """The keys on the Jog tab, then the Moves tab's buttons on a second ramp of the same app
    (the override put back to 100 % first: it holds for the moves after)."""
    async def scenario() -> None:
        app = tui.app(lockstep=False)
        async with app.run_test(size=SIZE) as pilot:
            status = await tui.ready(app, pilot)
            client = app.client
            header = app.query_one("#header-health", LiveText)
            sent: list[object] = []
            send = client._send
            client._send = lambda command, *fds: (sent.append(command), send(command, *fds))[1]

            def state(awaited: str) -> Callable[[], str]:
                def said() -> str:
                    now = client.status()
                    return (f"{awaited}; paused {now.paused}, feed rate {now.feed_rate}, "
                            f"override {now.feed_override}, move_done {now.move_done}, moving "
                            f"{now.moving}, mode {now.mode!r}, header {header.text!r}, sent "
                            f"{sent[-4:]}, log {[e.what for e in app.desk.events.entries]}")
                return said
            start = np.array(status.position)
            end = start.copy()
            end[1] += 20.0
            handle = client.move(moves.ramp(start, end, ramp_time=20.0, machine=UNIMATE),
                                 kind="ramp")
            await tui.until(lambda: client.status().move_done > 100, what="the ramp under way")
            for _ in range(5):  # as fast as the terminal sends them
                tui.post_key(app, "ctrl+down")
            await tui.until(lambda: client.status().feed_override == 0.5, what="50 %")
            await tui.until(lambda: "feed 50%" in header.text, what="the header's feed")
            tui.post_key(app, "ctrl+f")
            await tui.until(lambda: client.status().feed_rate == 0.0, what="the feed hold")
            await tui.until(lambda: "FEED HOLD" in header.text, what="the header's hold")
            held = client.status().move_done
            await asyncio.sleep(0.3)
            assert client.status().move_done == held and client.status().moving
            tui.post_key(app, "ctrl+f")
            await tui.until(lambda: client.status().move_done > held + 50,
                            what=state("the resume"))
            assert not client.status().paused
            tui.post_key(app, "ctrl+up")
            await tui.until(lambda: client.status().feed_override == 0.6, what="60 %")
            tui.post_key(app, "ctrl+g")
            result = await asyncio.to_thread(client.wait, handle, 30)
            assert not result.complete and result.run.meta["feed"][-1][1] == 0.6
            assert len(result.run.meta["pauses"]) == 1

            # the Moves tab's buttons
            for _ in range(4):
                tui.post_key(app, "ctrl+up")
            await tui.until(lambda: client.status().feed_override == 1.0, what="100 % again")
            await pilot.press("f2")
            start = np.array(client.status().position)
            end = start.copy()
            end[1] += 20.0
            handle = client.move(moves.ramp(start, end, ramp_time=20.0, machine=UNIMATE),
                                 kind="ramp")
            await tui.until(lambda: client.status().move_done > 100, what="the ramp under way")
            await pilot.click("#feed-down")
            await tui.until(lambda: client.status().feed_override == 0.9, what="90 %")
            button = app.query_one("#feed-hold")
            await tui.until(lambda: str(button.label) == "90%", what="the button's 90%")
            await pilot.click("#feed-hold")
            await tui.until(lambda: client.status().paused, what="the feed hold")
            await tui.until(lambda: str(button.label) == "resume", what="the button's resume")
            assert await pilot.click("#feed-hold"), "the click missed the resume button"
            await tui.until(lambda: not client.status().paused, what=state("the resume"))
            await pilot.click("#feed-up")
            await tui.until(lambda: client.status().feed_override == 1.0, what="100 %")
            tui.post_key(app, "ctrl+g")
            await asyncio.to_thread(client.wait, handle, 30)

    asyncio.run(scenario())
