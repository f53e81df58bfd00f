"""The TUI says a move is settling (issue 24): after its path the move holds the end until
every joint is in position, and the header says "settling" meanwhile, not that it is done;
the Scope marks the settle."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import numpy as np

from app.tabs.scope import ScopeTab
from app.widgets.live_text import LiveText
from control.rt.layout import Mode

SIZE = (160, 48)


def test_the_header_says_settling_while_a_move_comes_in_position(tui) -> None:
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: the settle lasts goal_time, 2 s
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            await pilot.press("f3")  # the Scope, which marks the settle while it shows
            scope = app.query_one(ScopeTab)
            client = app.client
            hold = client.machine.hold
            zero = replace(hold, name="zero", kp=((0.0,),) * 6, ki=(0.0,) * 6,
                           kd=(0.0,) * 6, w=((),) * 6)
            client.set_coefficients("hold", zero, override="test: a joint that cannot settle")
            path = np.tile(np.array(client.status().position), (100, 1))
            path[-1, 1] += 2.0  # Rotate steps in the path's last row; nothing brings it there
            handle = client.move(path, kind="step")
            header = app.query_one("#header-health", LiveText)
            await tui.until(lambda: "settling" in header.text, 10,
                            what=lambda: f"the header to say settling: {header.text}")
            assert client.status().settling and client.status().mode == Mode.HOLD
            await tui.until(lambda: "SETTLING" in tui.text(scope.query_one("#scope-bar")), 5,
                            what="the Scope's bar to say SETTLING")
            result = await asyncio.to_thread(client.wait, handle, 30)
            assert result.unsettled, result.status
            await tui.until(lambda: "settling" not in header.text, 5,
                            what=lambda: f"the header to stop saying settling: {header.text}")
            await tui.until(lambda: scope.settles and scope.settles[-1].end_s is not None, 5,
                            what="the Scope to note the settle's end")
            (settle,) = scope.settles
            assert settle.goal[1] == path[-1, 1]  # the end it held
            assert 1.8 < settle.end_s - settle.start_s < 2.5  # goal_time, as the Scope saw it
            client.set_coefficients("hold", hold)

    asyncio.run(scenario())
