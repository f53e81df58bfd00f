"""E-stop and faults: Escape and ctrl+e close every valve from every tab (and from a
dialog); releasing takes a deliberate confirmation; a fault says what happened and what
to do; a dead controller is reported at once."""

from __future__ import annotations

import asyncio
import os
import signal

from app.tui import TABS
from app.widgets.dialogs import ConfirmScreen
from app.widgets.header import EStopLamp, FaultBanner
from control.layout import Mode

SIZE = (160, 48)
OPEN = [30.0, -30.0, 30.0, -30.0, 30.0, -30.0]  # manual duties that open every valve


def test_estop_from_every_tab_closes_the_valves(tui) -> None:
    async def scenario() -> None:
        app = tui.app(lockstep=False)  # real time: the joints barely move between E-stops
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            client = app.client
            for i, (name, _) in enumerate(TABS):
                tui.post_key(app, f"f{i + 1}")  # keys as the terminal sends them, no idle waits
                await tui.until(lambda name=name: app.query_one("#tabs").active == f"pane-{name}")
                client.jog([d * (-1) ** i for d in OPEN])  # to and fro: no joint reaches a limit
                await tui.until(lambda: all(client.status().valve), what=f"valves open ({name})")
                key = "escape" if i % 2 == 0 else "ctrl+e"
                tui.post_key(app, key)
                await tui.until(lambda: client.status().estop and not any(client.status().valve),
                                timeout=2, what=f"{key} on the {name} tab to close the valves")
                await tui.until(lambda: "E-STOP" in app.query_one(EStopLamp).text)
                await tui.until(lambda: "E-STOP latched" in app.query_one(FaultBanner).message,
                                what="the E-stop banner")
                assert "^R to release" in app.query_one(FaultBanner).message
                client.jog(OPEN)  # refused while latched
                await asyncio.sleep(0.05)
                assert not any(client.status().valve)
                tui.post_key(app, "ctrl+r")
                await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the dialog")
                tui.post_key(app, "n")  # not yet: it stays latched
                await tui.until(lambda: not isinstance(app.screen, ConfirmScreen))
                assert client.status().estop
                tui.post_key(app, "ctrl+r")
                await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the dialog")
                tui.post_key(app, "y")
                await tui.until(lambda: not client.status().estop, what="the release")
                assert client.status().mode == Mode.HOLD

    asyncio.run(scenario())


def test_estop_closes_an_open_dialog(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            await pilot.press("ctrl+e", "ctrl+r")  # the release dialog is open
            await tui.until(lambda: app.client.status().estop)
            assert isinstance(app.screen, ConfirmScreen)
            await pilot.press("escape")
            assert not isinstance(app.screen, ConfirmScreen)
            assert app.client.status().estop

    asyncio.run(scenario())


def test_a_limit_fault_says_what_happened_and_what_to_do(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            app.client.jog_joint(2, 100.0)  # Up/Down flat out towards its 30° limit
            banner = app.query_one(FaultBanner)
            await tui.until(lambda: "limit" in banner.message, timeout=20, what="limit fault")
            assert "Up/Down" in banner.message and "opposite jog key" in banner.message
            assert app.client.status().duty[2] == 0.0
            await pilot.press("ctrl+l")
            assert not banner.display

    asyncio.run(scenario())


def test_a_dead_controller_is_reported_at_once(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            os.kill(app.client.pid, signal.SIGKILL)
            banner = app.query_one(FaultBanner)
            await tui.until(lambda: "restart servodesk" in banner.message, timeout=2,
                            what="the death reported")
            await tui.until(lambda: "CONTROLLER DOWN" in app.query_one(EStopLamp).text,
                            timeout=1)
            await pilot.press("a")  # a jog now tells the operator, and raises nothing
            await pilot.press("escape")

    asyncio.run(scenario())
