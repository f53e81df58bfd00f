"""Shared pieces of the TUI tests: a private data directory, and driving the app.

Every app in these tests runs a real control subprocess (the simulator) and
saves its runs under ``tmp_path``, never in the user's data directory. Tests are
plain functions that ``asyncio.run`` a scenario (no async plugin needed).
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import time
from collections.abc import AsyncGenerator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import ClassVar

import pytest
from textual import events
from textual.pilot import Pilot
from textual.widget import Widget
from textual.widgets import Button
from textual.worker import WorkerCancelled

from app.tui import ServodeskApp
from control.rt.layout import Status

START_S = 30.0  # a loaded machine can take a while to spawn the controller
SIZE = (160, 48)


class TabPilot(Pilot):
    """Pilot whose keys leave the tab they chose built and shown before the test goes on
    (the tests' apps build a tab only when it is first shown), and whose click on a button
    comes once the button has shown its last (Textual ignores a click on a button while it is
    ``-active``, 0.2 s after the one before: a test's second Apply or Resume came within
    that when the first's answer was quick, and was lost)."""

    async def press(self, *keys: str) -> None:
        await super().press(*keys)
        await Tui.built(self.app, self)

    async def click(self, *args: object, **kwargs: object) -> bool:
        target = args[0] if args else kwargs.get("widget")
        if isinstance(target, str):
            target = self.app.query_one(target)
        if isinstance(target, Button):
            button = target
            await Tui.until(lambda: not button.has_class("-active"),
                            what=f"{button} to show its last click")
        clicked = await super().click(*args, **kwargs)
        await Tui.built(self.app, self)  # a tab of the tab bar
        return clicked


class PilotedApp(ServodeskApp):
    """The app as the tests drive it: its pilot is a ``TabPilot``, and nothing on it is
    animated. The tab bar's underline slides for 0.3 s at every change of tab, and Pilot's
    ``press`` waits for every animation to end: a third of a second a tab, two thirds of each
    tab key's cost, spent on a slide no test reads (what the tabs show is checked, and is the
    same at its end)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.animation_level = "none"

    # Textual reads a class's stylesheets beside the module that defines it
    CSS_PATH: ClassVar = [Path(inspect.getfile(ServodeskApp)).parent / path
                          for path in ServodeskApp.CSS_PATH]

    @asynccontextmanager
    async def run_test(self, *args: object, **kwargs: object) -> AsyncGenerator[Pilot, None]:
        async with super().run_test(*args, **kwargs):
            try:
                yield TabPilot(self)
            finally:
                await Tui.no_tab_half_built(self)


class Tui:
    """Build apps on the test's data directory and wait for things in them."""

    def __init__(self, data_dir: Path) -> None:
        self.data_dir = data_dir

    def app(self, machine: str = "unimate2000b", lockstep: bool = True,
            build_behind: bool = False, **options: object) -> ServodeskApp:
        """An app that builds a tab when the test first shows it (``build_behind``: every
        tab once the screen is live, as the operator's does)."""
        # A Pilot-driven app on a loaded two-core machine can pause its client's heartbeat
        # thread past 250 ms, and the controller would (rightly) abort the move. Heartbeat
        # loss is proven in tests/faults and tests/control; here the UI flows are.
        # The flows proven here run at full speed, as before the TUI started in reduced speed
        # (T1); tests/app/test_tui_speed_mode.py starts it as an operator does.
        client_options = {"heartbeat_timeout_s": 2.0, "speed_mode": "automatic",
                          **options.pop("client_options", {})}
        return PilotedApp(machine, "sim", None, self.data_dir, lockstep=lockstep,
                          client_options=client_options, build_behind=build_behind, **options)

    @staticmethod
    async def ready(app: ServodeskApp, pilot: Pilot) -> Status:
        """Wait until the controller runs, the first status was sampled and the first tab
        has the focus (its keys work), and, in an app that builds behind, every tab is
        built; return the status."""
        deadline = time.monotonic() + START_S
        while (app.client is None or app.sampler is None or app.sampler.latest is None
               or app.focused is None or app.tab("jog") not in app.focused.ancestors_with_self
               or (app.build_behind and not all(tab.is_mounted for tab in app.tabs.values()))):
            # a tab attached is not yet mounted, and one mounting may take the focus from
            # the keys a test presses next
            if app.client_problem:
                pytest.fail(f"the controller did not start: {app.client_problem}")
            if time.monotonic() > deadline:
                pytest.fail(f"the controller did not start within {START_S:g} s")
            await pilot.pause(0.05)
        return app.client.status()

    @staticmethod
    async def built(app: ServodeskApp, pilot: Pilot) -> None:
        """Wait until the tabs chosen so far (by keys, clicks, the app) are built, and the
        one chosen last is shown with its focus; in an app that builds behind, ``ready``
        waited for every tab and the keys of a test before it are the operator's."""
        if app.build_behind:
            return
        await pilot._wait_for_screen()  # the keys and clicks sent so far were handled
        while building := [worker for worker in app.workers
                           if worker.group == "build" and not worker.is_finished]:
            with contextlib.suppress(WorkerCancelled):  # the app is closing
                await app.workers.wait_for_complete(building)
            await pilot._wait_for_screen()  # the focus the shown tab asked for

    @staticmethod
    async def no_tab_half_built(app: ServodeskApp) -> None:
        """No tab is being mounted when the test ends its app: the background build starts
        no more, and the one it is mounting finishes (as ^Q waits, ``_exit_once_built``). A
        tab whose mount the test's exit overtook found its own widgets gone (NoMatches in
        ScopeTab.on_mount, one run in three of a test that ended as the build went on)."""
        app._quitting = True
        while app._building:
            await asyncio.wait_for(next(iter(app._building.values())).wait(), START_S)

    @staticmethod
    async def until(condition: Callable[[], object], timeout: float = 10.0,
                    what: str | Callable[[], str] = "") -> None:
        """Wait (without Pilot's idle waits) until ``condition()`` is true; ``what`` (or
        what it returns, when the wait fails) names it in the failure."""
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                detail = what() if callable(what) else what
                pytest.fail(f"timed out after {timeout:g} s waiting for {detail or condition}")
            await asyncio.sleep(0.01)

    @staticmethod
    def text(widget: Widget) -> str:
        """What a widget shows, as plain text, line after line."""
        return "\n".join(widget.render_line(y).text for y in range(widget.size.height))

    @staticmethod
    def notifications(app: ServodeskApp) -> list[str]:
        """Every message the app or a widget of it is asked to show from now on."""
        seen: list[str] = []
        show = app.notify

        def notify(message: str, *args: object, **kwargs: object) -> None:
            seen.append(str(message))
            show(message, *args, **kwargs)

        app.notify = notify  # Widget.notify calls the app's
        return seen

    @staticmethod
    def post_key(app: ServodeskApp, key: str) -> None:
        """Deliver a key the way the terminal driver does, without waiting for idle."""
        assert app._driver is not None
        app._driver.send_message(events.Key(key, key if len(key) == 1 else None))


@pytest.fixture
def data_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Where the app saves runs; the user's data directory is pointed here too, just in case."""
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    return tmp_path / "runs"


@pytest.fixture
def tui(data_dir: Path) -> Tui:
    return Tui(data_dir)
