"""Banners and the log tell the story (issue 26 item 5): under an E-stop the header's mode is
the E-stop; every banner line has its time; a limit banner clears once the joint has left the
limit (with hysteresis); "run the move again" only when a client-silent hold stopped one; the
Log follows the newest entry unless scrolled back, End goes to the newest row with the time
column in view, a move's start follows the end of the move before; the session's start and
end, feed changes, taught positions, gain refusals and changes of command are logged; an
observer is refused the E-stop's release, and a go-to, before any dialog."""

from __future__ import annotations

import asyncio
import json
import re
import time
from dataclasses import replace

from app.event_log import EventLog, LogEntry
from app.messages import ControllerEvent
from app.tabs.log import LogTable
from app.tabs.tuning import TuningTab
from app.widgets.dialogs import ConfirmScreen, EditValueScreen
from app.widgets.header import FaultBanner
from app.widgets.limit_bar import LimitWatch
from app.widgets.live_text import LiveText
from control.client import Event
from control.rt.events import Fault, MoveDone
from hw.machine import load_machine
from tests.app.conftest import PilotedApp

SIZE = (120, 36)
CLOCK = re.compile(r"\d\d:\d\d:\d\d")
UI_LOST = "client silent for 250 ms: holding position"


def test_a_moves_start_is_logged_after_the_end_of_the_move_before() -> None:
    """The client raises a move's start as it sends it; the end of the move before comes
    from the controller and may come after it (before: "move 7 started" above "move 6")."""
    log = EventLog()
    log.add(LogEntry(100.0, "move start", "move 6 started", data={"move_id": 6}))
    log.add(LogEntry(101.00, "move start", "move 7 started", data={"move_id": 7}))
    log.add(LogEntry(101.01, "move end", "move 6: complete", data={"move_id": 6}))
    assert [e.what for e in log.entries] == ["move 6 started", "move 6: complete",
                                             "move 7 started"]
    assert [e.wall for e in log.entries] == [100.0, 101.01, 101.01]  # in time order too
    log.add(LogEntry(200.0, "move start", "move 8 started", data={"move_id": 8}))
    log.add(LogEntry(300.0, "notice", "later"))  # move 7's end never came: not waited for
    assert [e.what for e in log.entries][-2:] == ["later", "move 8 started"]


def test_a_limit_clears_once_the_joint_is_clear_of_it_by_its_hysteresis() -> None:
    """Only a status published after the report clears it: one from before (the UI's sampler
    behind the event; a lockstep simulator runs far ahead of real time) shows the joint on
    its way to the limit. The old watch cleared on it, and the limit's banner went at once."""
    machine = load_machine("unimate2000b")
    j = machine.joint_index("updown")
    watch = LimitWatch(machine.lower, machine.upper)
    watch.reported(j, 100.0)
    q = list(machine.home)
    margin = 0.01 * (machine.upper[j] - machine.lower[j])
    q[j] = machine.lower[j] + 20 * margin
    assert watch.cleared(q, 99.9) == [] and watch.at == {j}, "cleared by a status from before"
    for near in (machine.lower[j] - 0.1, machine.lower[j] + 0.5 * margin):  # on it, or close
        q[j] = near
        assert watch.cleared(q, 100.1) == [] and watch.at == {j}
    q[j] = machine.lower[j] + 1.5 * margin
    assert watch.cleared(q, 100.2) == [j] and not watch.at


def logged(app, kind: str, text: str = "") -> list[LogEntry]:
    return [e for e in app.desk.events.entries if e.kind == kind and text in e.what]


def test_banners_and_the_log_tell_the_story_of_a_session(controller_service, tui) -> None:
    async def scenario() -> None:
        # it builds the tabs it shows alone (Jog, Tuning, Log, Positions), as tui.app's do
        app = PilotedApp.attached(controller_service.socket, take_command=True,
                                  build_behind=False)
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            client, name = app.client, app.client.name
            health = app.query_one("#header-health", LiveText)
            banner = app.query_one(FaultBanner)
            await tui.until(lambda: "COMMANDING" in health.text, what="command taken")
            assert logged(app, "session", "session started")
            await tui.until(lambda: logged(app, "command", f"{name} took command"))

            # E-stop: the mode is the E-stop, the banner has its time, the log says who
            await pilot.press("ctrl+e")
            await tui.until(lambda: client.status().estop and "E-STOP" in health.text,
                            what="the E-stop in the header")
            assert "mode E-STOP" in health.text and "HOLD" not in health.text, health.text
            await tui.until(lambda: logged(app, "E-stop", f"operator E-stop from {name}"),
                            what="the E-stop logged with who pressed it")
            assert CLOCK.fullmatch(tui.text(banner).split()[1]), tui.text(banner)
            await pilot.press("ctrl+r")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the dialog")
            await pilot.press("y")
            await tui.until(lambda: not client.status().estop, what="the release")

            # a client-silent hold says "run it again" only when it stopped a move
            def silent(*records: object) -> None:
                for record in records:
                    app.post_message(ControllerEvent(Event(record)))

            silent(Fault("ui_lost", -1, UI_LOST))
            await tui.until(lambda: UI_LOST in banner.message)
            assert "run it again" not in banner.message, banner.message
            silent(MoveDone(999, "interrupted: client silent", 10), Fault("ui_lost", -1, UI_LOST))
            await tui.until(lambda: "It stopped move 999: run it again" in banner.message)
            await pilot.press("ctrl+l")

            # a limit banner goes once the joint has left the limit, with no ^L
            client.set_speed_mode("automatic")  # taking command set T1, which refuses duty
            client.jog_joint("updown", -100.0)  # from park (-20°) down to its -27° limit
            await tui.until(lambda: "limit" in banner.message, timeout=20, what="the limit")
            client.jog_joint("updown", 60.0)
            await tui.until(lambda: not banner.display, timeout=20, what="the banner cleared")
            client.hold()
            assert logged(app, "limit clear", "Up/Down back inside its limits")

            # feed, a taught position and a refused gain set go into the log
            await pilot.press("ctrl+down")
            await tui.until(lambda: logged(app, "feed", "feed override 100% → 90%"),
                            what="the feed change logged")
            await pilot.press("ctrl+t")
            await tui.until(lambda: isinstance(app.screen, EditValueScreen))
            await pilot.press("enter")
            await tui.until(lambda: logged(app, "position", "taught p1: In/Out"),
                            what="the taught position logged")
            await pilot.press("f5")
            tuning = app.query_one(TuningTab)
            unstable = replace(app.machine.hold, kp=((-20.0,), *app.machine.hold.kp[1:]))
            tuning.apply({"hold": unstable}, "a negative gain")
            await tui.until(lambda: logged(app, "refused", "apply a negative gain refused"),
                            what="the refusal logged")

            # the Log: at the newest row, follows it, stays where the operator scrolled back
            for k in range(30):  # more than a screen, one wider than it
                app.desk.events.add(LogEntry(time.time(), "notice", f"filler {k} " + "x" * k * 8))
            await pilot.press("f10")
            table = app.query_one(LogTable)
            await tui.until(lambda: table.row_count == app.desk.events.count
                            and table.max_scroll_y > 0 and table.at_newest,
                            what="the Log at its newest row")
            assert table.max_scroll_x > 0  # one row is wider than the screen
            await pilot.press("end")
            await tui.until(lambda: table.at_newest and table.scroll_x == 0,
                            what="End at the newest row, the time column in view")
            app.desk.events.add(LogEntry(time.time(), "notice", "followed"))
            await tui.until(lambda: table.row_count == app.desk.events.count
                            and table.at_newest, what="the new row followed")
            await pilot.press("pageup", "pageup")
            await tui.until(lambda: not table.at_newest, what="scrolled back")
            back = table.cursor_row
            app.desk.events.add(LogEntry(time.time(), "notice", "not followed"))
            await tui.until(lambda: table.row_count == app.desk.events.count)
            await pilot.pause()
            assert table.cursor_row == back and not table.at_newest
            await pilot.press("end")
            await tui.until(lambda: table.at_newest and table.scroll_x == 0,
                            what="End at the newest row")

            # released command: an observer is refused the E-stop's release before any dialog
            await pilot.press("ctrl+o")
            await tui.until(lambda: "observing" in health.text, what="command released")
            assert logged(app, "command", f"{name} released command")
            await pilot.press("ctrl+e")
            await tui.until(lambda: client.status().estop, what="the observer's E-stop")
            refused = tui.notifications(app)
            await pilot.press("ctrl+r")
            assert not isinstance(app.screen, ConfirmScreen)
            assert any("observing: nobody holds command" in text for text in refused), refused
            assert logged(app, "refused", "release the E-stop refused")
            await pilot.press("f9")  # and a go-to (issue 26 item 7)
            await tui.until(lambda: app.query_one("#positions-table").row_count >= 2)
            await pilot.press("g")
            assert not isinstance(app.screen, ConfirmScreen)
            assert [e for e in logged(app, "refused", "refused: observing")
                    if e.what.startswith("go to ")], app.query_one("#positions-state").text
            path = app.desk.events.path
        written = [json.loads(line) for line in path.read_text().splitlines()]
        assert written[-1]["what"] == "session ended: servodesk closed", written[-1]

    asyncio.run(scenario())
