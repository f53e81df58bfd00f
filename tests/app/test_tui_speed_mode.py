"""Reduced speed (T1) in the TUI (issue 27 item 4): it starts in reduced speed, the header says
which mode the controller is in, the Jog tab jogs joints by position steps (the duty modes are
refused in reduced speed) and takes its mode back in automatic, ^Y asks before automatic (full
speed) and goes back to reduced at once; an observer's ^Y is refused, and a TUI that takes
command puts the controller in reduced speed."""

from __future__ import annotations

import asyncio
from pathlib import Path

from app.tabs.jog import JogPad
from app.widgets.dialogs import ConfirmScreen
from app.widgets.live_text import LiveText
from tests.app.conftest import PilotedApp

SIZE = (160, 48)
T1, AUTO = "T1 250 mm/s", "AUTO"


def test_the_tui_starts_in_reduced_speed_and_asks_before_automatic(tui, data_dir: Path) -> None:
    async def scenario() -> None:
        # as an operator starts it: no speed mode given (the tests' Tui.app sets automatic);
        # the Jog tab alone is built, as in Tui.app's apps
        app = PilotedApp("unimate2000b", "sim", None, data_dir, lockstep=True,
                         client_options={"heartbeat_timeout_s": 2.0}, build_behind=False)
        async with app.run_test(size=SIZE) as pilot:
            status = await tui.ready(app, pilot)
            assert status.speed_mode == "reduced"
            header = app.query_one("#header-health", LiveText)
            await tui.until(lambda: T1 in header.text, what="T1 in the header")
            assert AUTO not in header.text

            # the Jog tab jogs joints by position steps: its duty modes would be refused
            pad = app.query_one(JogPad)
            await tui.until(lambda: pad.reduced and pad.mode == "position",
                            what="the Jog pad in position mode")
            before = app.client.status().desired[1]
            await pilot.press("7", "s")  # Rotate + 1°: a position step, not a refused duty
            await tui.until(lambda: app.client.status().desired[1] > before + 0.5,
                            what="Rotate's target stepped")
            await pilot.press("m")  # the duty modes need automatic
            assert pad.mode == "position"

            await pilot.press("ctrl+y")  # asks; cancelled, still reduced
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            assert "automatic (full speed)" in app.screen.question
            await pilot.press("n")
            await tui.until(lambda: not isinstance(app.screen, ConfirmScreen))
            assert app.client.speed_mode == "reduced"

            await pilot.press("ctrl+y")  # confirmed: automatic, in the header
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            await pilot.press("y")
            await tui.until(lambda: app.client.speed_mode == "automatic", what="automatic")
            await tui.until(lambda: AUTO in header.text and T1 not in header.text,
                            what="AUTO in the header")
            assert pad.mode == "duty"  # automatic: the mode it had before reduced speed

            await pilot.press("ctrl+y")  # back to reduced at once: no question
            await tui.until(lambda: app.client.speed_mode == "reduced", what="reduced again")
            assert not isinstance(app.screen, ConfirmScreen)
            await tui.until(lambda: T1 in header.text, what="T1 in the header again")

    asyncio.run(scenario())


def test_a_commanding_tui_sets_reduced_speed_and_an_observer_cannot_switch(
        controller_service, tui) -> None:
    async def scenario() -> None:
        commander = PilotedApp.attached(controller_service.socket, take_command=True,
                                        build_behind=False)  # the Jog tab alone is built
        observer = PilotedApp.attached(controller_service.socket, build_behind=False)
        async with commander.run_test(size=SIZE) as one, observer.run_test(size=SIZE) as two:
            await tui.ready(commander, one)
            await tui.ready(observer, two)
            # the service's controller starts in automatic; taking command sets reduced
            await tui.until(lambda: commander.client.speed_mode == "reduced",
                            what="reduced speed once the TUI commands")
            header = observer.query_one("#header-health", LiveText)
            await tui.until(lambda: T1 in header.text, what="T1 in the observer's header")
            refused = tui.notifications(observer)
            tui.post_key(observer, "ctrl+y")
            await tui.until(lambda: any("take command first" in text for text in refused),
                            what="the observer's refusal")
            assert not isinstance(observer.screen, ConfirmScreen)
            assert observer.client.speed_mode == "reduced"

    asyncio.run(scenario())
