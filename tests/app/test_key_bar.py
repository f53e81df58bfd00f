"""The footer (KeyBar): the keys that work where the operator is, the E-stop first at every
width, and a click on a key presses it (the browser of ``servodesk serve`` clicks)."""

from __future__ import annotations

import asyncio

from app.tui import ServodeskApp
from app.widgets.key_bar import KeyBar

SMALL = (80, 24)


def bar(app: ServodeskApp) -> str:
    return str(app.query_one(KeyBar).render())


def test_the_key_bar_follows_the_tab_and_a_click_on_e_stop_latches_it(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SMALL) as pilot:
            await tui.ready(app, pilot)
            await tui.until(lambda: "jog joint" in bar(app), what="the Jog tab's keys")
            assert bar(app).startswith(" Esc/^E E-STOP ")
            tui.post_key(app, "f2")
            await tui.until(lambda: "run move" in bar(app), what="the Moves tab's keys")
            assert bar(app).startswith(" Esc/^E E-STOP ") and "jog joint" not in bar(app)
            await pilot.click(KeyBar, offset=(2, 0))
            await tui.until(lambda: app.estop_latched, what="the E-stop, clicked")
            await tui.until(lambda: app.client.status().estop,
                            what="latched at the controller")

    asyncio.run(scenario())
