"""The UI never misses its heartbeat (issue 13, item 11): every tab opened for the first time,
End point in Moves too, beside a CPU burner (a busy loop in another process), with the
controller's real 250 ms timeout: the controller never reports the client silent (it would
hold). How long the UI pauses meanwhile is measured in ``benchmarks/ui.py --pauses``."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from textual.widget import Widget
from textual.widgets import OptionList

from app.tabs.end_point_form import EndPointForm
from app.tui import TABS, ServodeskApp
from control.client import HEARTBEAT_S
from control.rt.layout import HEARTBEAT_WORD

SIZE = (160, 48)
HEARTBEAT_TIMEOUT_S = 0.25  # the controller's own default, not the tests' relaxed 2 s


@contextmanager
def burner() -> Iterator[subprocess.Popen]:
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield busy
    finally:
        busy.kill()
        busy.wait()


def beats(app: ServodeskApp) -> int:
    """The client's latest heartbeat (its monotonic ns), as the controller reads it."""
    assert app.client is not None
    return app.client._words[HEARTBEAT_WORD]


def laid_out(widget: Widget) -> Callable[[], bool]:
    """Whether ``widget`` is displayed, with room on the screen."""
    return lambda: widget.display and widget.region.area > 0


def test_opening_every_tab_for_the_first_time_beside_a_burner_keeps_the_heartbeat(tui) -> None:
    async def scenario() -> None:
        with burner():
            app = tui.app(lockstep=False, build_behind=True,  # as the operator's
                          client_options={"heartbeat_timeout_s": HEARTBEAT_TIMEOUT_S})
            async with app.run_test(size=SIZE) as pilot:
                await tui.ready(app, pilot)
                assert app._settled == {"jog"}, "a tab other than Jog was shown before"
                for i, (name, _) in enumerate(TABS):
                    tab = app.tab(name)
                    tui.post_key(app, f"f{i + 1}")
                    await tui.until(laid_out(tab), timeout=30, what=f"the {name} tab laid out")
                    if name == "moves":
                        menu = app.query_one("#move-kinds", OptionList)
                        menu.highlighted = next(k for k, option in enumerate(menu.options)
                                                if option.id == EndPointForm.__name__)
                        await tui.until(laid_out(app.query_one(EndPointForm)), timeout=30,
                                        what="the End point form laid out")
                # the heartbeat is written again after the last tab: a silence before it long
                # enough to hold was seen by the controller by then
                shown = beats(app)
                await tui.until(lambda: beats(app) > shown + HEARTBEAT_S * 1e9,
                                what="two heartbeats after the last tab")
                app.client.estop()  # a fence: the controller's events before it arrive first
                await tui.until(lambda: any(e.kind == "E-stop" for e in app.desk.events.entries),
                                what="the E-stop, logged")
                silent = [e.line() for e in app.desk.events.entries if e.kind == "UI lost"]
                # the load says whether other work starved the whole UI process meanwhile
                assert silent == [], (f"{silent} at load average {os.getloadavg()[0]:.1f} on "
                                      f"{os.cpu_count()} CPUs")

    asyncio.run(scenario())
