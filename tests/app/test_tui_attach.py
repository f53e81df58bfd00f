"""``servodesk --attach``: two TUIs on one ``servodesk controller``. One takes command (^K),
the other's header says who holds it and its jog is refused with the reason; command is
handed over with ^O and ^K."""

from __future__ import annotations

import asyncio
import os
import signal

from app.tabs.jog import JogPad
from app.tui import attached_app
from app.widgets.dialogs import ConfirmScreen
from app.widgets.live_text import LiveText
from control.rt.layout import Mode

SIZE = (160, 48)


def test_two_attached_tuis_one_commands_the_other_observes(controller_service, tui) -> None:
    async def scenario() -> None:
        first = attached_app(controller_service.socket)
        second = attached_app(controller_service.socket)
        async with first.run_test(size=SIZE) as one, second.run_test(size=SIZE) as two:
            await tui.ready(first, one)
            await tui.ready(second, two)
            headers = [app.query_one("#header-health", LiveText) for app in (first, second)]
            await tui.until(lambda: "observing: nobody holds command" in headers[1].text,
                            what="the observer's header")
            tui.post_key(first, "ctrl+k")
            await tui.until(lambda: "COMMANDING" in headers[0].text, what="the commander's header")
            name = first.client.name
            await tui.until(lambda: f"observing: command is held by {name}" in headers[1].text,
                            what="the observer's header naming the commander")
            refused = tui.notifications(second)
            tui.post_key(second, "a")  # a jog key on the Jog tab
            await tui.until(lambda: any(f"command is held by {name}; take it first" in text
                                        for text in refused), what="the observer's refusal")
            assert first.client.status().mode == Mode.HOLD  # nothing reached the controller
            tui.post_key(first, "ctrl+y")  # taking command set T1, which refuses a duty jog
            await tui.until(lambda: isinstance(first.screen, ConfirmScreen), what="the question")
            tui.post_key(first, "y")
            pad = first.query_one(JogPad)  # its duty mode back once it has seen automatic
            await tui.until(lambda: first.client.speed_mode == "automatic" and pad.mode == "duty",
                            what=lambda: f"automatic, the pad in duty mode: {pad.mode}")
            tui.post_key(first, "a")
            await tui.until(lambda: first.client.status().mode == Mode.MANUAL_ACTUATE
                            and first.client.status().duty[0] > 0, what="the commander's jog")
            tui.post_key(first, "space")
            await tui.until(lambda: not any(first.client.status().duty), what="the jog stopped")
            tui.post_key(second, "ctrl+k")  # refused: the first holds command
            await tui.until(lambda: any("holds command; it must release it first" in text
                                        for text in refused), what="the take refused")
            tui.post_key(first, "ctrl+o")
            await tui.until(lambda: "observing: nobody holds command" in headers[0].text,
                            what="the release in the first header")
            tui.post_key(second, "ctrl+k")
            await tui.until(lambda: "COMMANDING" in headers[1].text, what="the hand-over")
            await tui.until(lambda: f"held by {second.client.name}" in headers[0].text,
                            what="the first header naming the new commander")
        assert controller_service.proc.poll() is None  # both TUIs gone, the controller runs on

    asyncio.run(scenario())


def test_esc_after_take_command_from_a_frozen_service_latches_at_once(controller_service,
                                                                      tui) -> None:
    """^K waits for the service's answer (up to 2 s) off the UI's thread: with the service
    frozen (SIGSTOP; its controller ticks on), Esc pressed after ^K latches the E-stop through
    shared memory while the take still waits, and the take then fails, said. The old app
    waited for the answer on the UI's thread, nothing else running meanwhile."""
    async def scenario() -> None:
        app = attached_app(controller_service.socket)
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            said = tui.notifications(app)
            os.kill(controller_service.proc.pid, signal.SIGSTOP)
            try:
                tui.post_key(app, "ctrl+k")
                await tui.until(lambda: any(w.name == "client calls" and w.is_running
                                            for w in app.workers),
                                what="the take waiting for its answer off the UI's thread")
                tui.post_key(app, "escape")
                await tui.until(lambda: app.estop_latched, what="Esc read")
                told_before = [text for text in said if "no answer" in text]
                await tui.until(lambda: app.client.status().estop, what="the E-stop")
                await tui.until(lambda: any("take command: no answer" in text for text in said),
                                what=lambda: f"the take's failure told: {said}")
            finally:
                os.kill(controller_service.proc.pid, signal.SIGCONT)
            assert told_before == [], "Esc was read only after the take had failed"
            assert "COMMANDING" not in app.query_one("#header-health", LiveText).text

    asyncio.run(scenario())
