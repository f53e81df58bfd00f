"""E-stop and faults: Escape and ctrl+e close every valve from every tab (and from a
dialog); releasing takes a deliberate confirmation; a fault says what happened and what
to do; a dead controller is reported at once."""

from __future__ import annotations

import asyncio
import os
import signal

from app.tabs.jog import JogPad
from app.tui import TABS, ServodeskApp
from app.widgets.dialogs import ConfirmScreen
from app.widgets.header import EStopLamp, FaultBanner
from control.rt.layout import Mode

SIZE = (160, 48)
OPEN = [30.0, -30.0, 30.0, -30.0, 30.0, -30.0]  # manual duties that open every valve



def command_cell(app: ServodeskApp, joint: int) -> str:
    """The Jog table's row of ``joint`` as shown."""
    table = app.query_one("#jog-table")
    return table.render_line(joint + 1).text


def test_estop_from_every_tab_closes_the_valves(tui) -> None:
    async def scenario() -> None:
        # real time: the joints barely move between E-stops; every tab is opened
        app = tui.app(lockstep=False, build_behind=True)
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            client = app.client
            seen = tui.notifications(app)
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
                said = len(seen)
                client.jog(OPEN)  # refused while latched: the controller says so, and the
                # status of the tick that refused it is out by then (waited for, not a time)
                await tui.until(lambda n=said: any("manual actuation refused: E-stop latched"
                                                   in m for m in seen[n:]),
                                what=f"the jog refused while latched ({name})")
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


def test_a_limit_fault_says_what_happened_and_what_to_do(tui) -> None:
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            sent: list[object] = []
            send = app.client._send
            app.client._send = lambda command: (sent.append(command), send(command))[1]
            app.client.jog_joint(2, 100.0)  # Up/Down flat out towards its 30° limit
            banner = app.query_one(FaultBanner)

            def state() -> str:
                status = app.client.status()
                return (f"the limit fault; banner {banner.message!r}, mode {status.mode!r}, "
                        f"Up/Down at {status.position[2]:.2f} duty {status.duty[2]}, "
                        f"estop {status.estop}, sent {sent}, log "
                        f"{[e.what for e in app.desk.events.entries]}")

            await tui.until(lambda: "limit" in banner.message, timeout=20, what=state)
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


def test_an_estop_clears_the_jog_duties_keys_while_latched_do_nothing_and_it_closes_a_dialog(
        tui) -> None:
    """The bug report's sequence: Jog tab, duty mode, increment 5, Esc, then ``s`` six times.
    While latched the command column stays 0, the controller is sent nothing and the
    operator is told why; after the release and one ``s`` Rotate's duty is +5 %, not +35 %.
    Then, on the same app, an E-stop closes an open dialog."""
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            client = app.client
            seen = tui.notifications(app)
            await pilot.press("5", "s")
            await tui.until(lambda: client.status().duty[1] == 5.0, what="Rotate at +5 %")
            await pilot.press("escape")
            await tui.until(lambda: client.status().estop, what="the latch")
            assert app.query_one(JogPad).duty == [0.0] * 6
            assert client._manual == [0.0] * 6
            sent: list[object] = []
            send = client._send
            client._send = lambda command: (sent.append(command), send(command))[1]
            await pilot.press(*"ssssss")
            await pilot.pause()
            assert app.query_one(JogPad).duty == [0.0] * 6
            assert "+0" in command_cell(app, 1) and "+30" not in command_cell(app, 1)
            assert sent == [], f"the controller was sent {sent}"
            assert any("E-stop latched" in m and "^R" in m for m in seen), seen
            client._send = send
            await pilot.press("ctrl+r")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the dialog")
            await pilot.press("y")
            await tui.until(lambda: not client.status().estop, what="the release")
            await pilot.pause()
            assert client.status().mode == Mode.HOLD  # the release starts nothing
            await pilot.press("s")
            await tui.until(lambda: client.status().mode == Mode.MANUAL_ACTUATE,
                            what="manual actuation")
            assert client.status().duty == (0.0, 5.0, 0.0, 0.0, 0.0, 0.0)
            assert "+5" in command_cell(app, 1)

            # an E-stop closes an open dialog (the release's own: Esc is the E-stop key)
            await pilot.press("ctrl+e", "ctrl+r")  # the release dialog is open
            await tui.until(lambda: client.status().estop, what="the latch")
            assert isinstance(app.screen, ConfirmScreen), app.screen
            await pilot.press("escape")
            assert not isinstance(app.screen, ConfirmScreen), "the dialog stayed open"
            assert client.status().estop

    asyncio.run(scenario())


def test_a_latch_from_the_controller_clears_the_clients_manual_duties(tui) -> None:
    """The E-stop input latches inside the controller: the client forgets its manual duties
    too, so ``jog_joint`` after the release moves only the joint it names."""
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            client = app.client
            client.jog_joint(1, 30.0)
            await tui.until(lambda: client.status().duty[1] == 30.0, what="Rotate at 30 %")
            client.inject("press_estop", True)
            await tui.until(lambda: client.status().estop, what="the E-stop input's latch")
            await tui.until(lambda: client._manual == [0.0] * 6, what="the client's duties zero")
            client.inject("press_estop", False)
            client.reset()
            await tui.until(lambda: not client.status().estop, what="the release")
            client.jog_joint(3, 20.0)
            await tui.until(lambda: client.status().duty[3] == 20.0, what="Bend at 20 %")
            assert client.status().duty[1] == 0.0

    asyncio.run(scenario())
