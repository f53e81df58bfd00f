"""Issue 22, item 3: a TUI attached to ``servodesk controller`` that does not command changes
no file the commander's moves use. Its teach, rename and delete of a taught position and its
Tuning Save are refused at once (no dialog), with who holds command, in the Log tab too; a
path it types (Tuning Load, the Moves path file) must lie inside the data directory, after
``..`` and symlinks. The commanding TUI beside it does all of these as before."""

from __future__ import annotations

import asyncio
from dataclasses import replace
from pathlib import Path

from textual.screen import ModalScreen
from textual.widgets import Button, DataTable, Input, OptionList, Select

from app.coefficient_files import save_coefficients
from app.tabs.log import LogTab
from app.tabs.positions import PositionsTab
from app.tabs.tuning import TuningTab
from app.tui import ServodeskApp
from app.widgets.dialogs import ConfirmScreen, EditValueScreen
from control.motion.positions import load_positions, positions_file
from tests.app.conftest import PilotedApp

SIZE = (160, 48)


def pairs(socket: Path) -> tuple[ServodeskApp, ServodeskApp]:
    """A TUI that takes command at start, and one that only observes; each builds a tab when
    it is first shown (the few these tests use, not all eleven)."""
    return (PilotedApp.attached(socket, take_command=True, build_behind=False),
            PilotedApp.attached(socket, observe_only=True, build_behind=False))


async def start(tui, commander: ServodeskApp, one, observer: ServodeskApp, two) -> str:
    """Both ready, the first commanding; its name (the observer's refusals give it)."""
    await tui.ready(commander, one)
    await tui.ready(observer, two)
    await tui.until(lambda: commander.client.commanding
                    and observer.client.holder == commander.client.name,
                    what="the first TUI commanding, seen by the second")
    return commander.client.name


async def said(tui, seen: list[str], text: str, what: str) -> None:
    await tui.until(lambda: any(text in s for s in seen), what=lambda: f"{what}: {seen}")


async def show(tui, app: ServodeskApp, key: str, name: str) -> None:
    tui.post_key(app, key)
    await tui.until(lambda: app.tab(name).visible_now
                    and app.focused is not None
                    and app.tab(name) in app.focused.ancestors_with_self,
                    what=f"the {name} tab shown and focused")


async def name_it(tui, app: ServodeskApp, name: str) -> None:
    await tui.until(lambda: isinstance(app.screen, EditValueScreen)
                    and app.screen.query(Input), what="the name dialog")
    app.screen.query_one(Input).value = name
    tui.post_key(app, "enter")
    await tui.until(lambda: not isinstance(app.screen, ModalScreen), what="the name taken")


def test_an_observer_cannot_teach_rename_or_delete_and_the_commander_can(
        controller_service, tui) -> None:
    async def scenario() -> None:
        commander, observer = pairs(controller_service.socket)
        path = positions_file(controller_service.data_dir, commander.machine)
        async with commander.run_test(size=SIZE) as one, observer.run_test(size=SIZE) as two:
            holder = await start(tui, commander, one, observer, two)
            refusal = f"observing: command is held by {holder}; take it first"
            seen = tui.notifications(observer)

            # the observer lists the positions; the commander teaches "fixture"
            await show(tui, observer, "f9", "positions")
            table = observer.query_one("#positions-table", DataTable)
            await tui.until(lambda: table.row_count == 2, what="the observer listing home, park")
            await show(tui, commander, "f9", "positions")
            tui.post_key(commander, "t")
            await name_it(tui, commander, "fixture")
            await tui.until(lambda: path.exists() and [p.name for p in load_positions(
                path, commander.machine).taught] == ["fixture"], what="fixture taught")
            before = path.read_bytes()

            # the observer sees it, and can change none of it
            assert isinstance(observer.tab("positions"), PositionsTab)
            tui.post_key(observer, "l")  # read again: taught since the observer last read
            await tui.until(lambda: table.row_count == 3, what="the observer listing fixture")
            table.move_cursor(row=2)
            for key, what in (("r", "rename"), ("delete", "delete"), ("t", "teach")):
                tui.post_key(observer, key)
                await said(tui, seen, f"{what} refused: {refusal}", f"{what} refused")
                assert not isinstance(observer.screen, ModalScreen), what  # nothing asked
                assert path.read_bytes() == before, what
            await show(tui, observer, "f1", "jog")
            tui.post_key(observer, "ctrl+t")  # from any tab
            await tui.until(lambda: sum("teach refused" in s for s in seen) == 2,
                            what="^T refused")
            assert not isinstance(observer.screen, ModalScreen)
            assert path.read_bytes() == before

            # its header shows the newest entry of its log: that refusal
            await tui.until(lambda: "teach refused" in str(observer.header.latest and
                                                           observer.header.latest.line()),
                            what="the refusal in the header")
            # and its Log tab says so, every time
            await show(tui, observer, "f10", "log")
            log = observer.tab("log")
            assert isinstance(log, LogTab)
            rows = observer.query_one("#log-table", DataTable)

            def refused() -> list[str]:
                return [str(rows.get_row_at(i)[3]) for i in range(rows.row_count)
                        if str(rows.get_row_at(i)[1]) == "refused"]
            await tui.until(lambda: len(refused()) == 4, what=lambda: f"the log: {refused()}")
            assert refused() == [f"{what} refused: {refusal}"
                                 for what in ("rename", "delete", "teach", "teach")]

            # the commander renames and deletes as before
            commander_table = commander.query_one("#positions-table", DataTable)
            await tui.until(lambda: commander_table.row_count == 3)
            commander_table.move_cursor(row=2)
            tui.post_key(commander, "r")
            await name_it(tui, commander, "bench")
            await tui.until(lambda: [p.name for p in load_positions(
                path, commander.machine).taught] == ["bench"], what="renamed by the commander")
            await tui.until(lambda: commander_table.row_count == 3
                            and str(commander_table.coordinate_to_cell_key(
                                commander_table.cursor_coordinate).row_key.value) == "bench",
                            what="bench selected")
            tui.post_key(commander, "delete")
            await tui.until(lambda: isinstance(commander.screen, ConfirmScreen),
                            what="the question")
            tui.post_key(commander, "y")
            await tui.until(lambda: not load_positions(path, commander.machine).taught,
                            what="deleted by the commander")

    asyncio.run(scenario())


def test_an_observer_saves_no_gains_and_reads_only_inside_the_data_directory(
        controller_service, tui, tmp_path: Path) -> None:
    async def scenario() -> None:
        commander, observer = pairs(controller_service.socket)
        data_dir = controller_service.data_dir
        outside = tmp_path / "elsewhere"
        async with commander.run_test(size=SIZE) as one, observer.run_test(size=SIZE) as two:
            holder = await start(tui, commander, one, observer, two)
            seen = tui.notifications(observer)
            live = observer.client.coefficients["track"]
            tuned = {"track": replace(live, kp=((18.0,), *live.kp[1:]))}
            await show(tui, observer, "f5", "tuning")
            tab = observer.tab("tuning")
            assert isinstance(tab, TuningTab)
            field = observer.query_one("#tuning-path", Input)
            buttons = {b: observer.query_one(f"#tuning-{b}", Button) for b in ("save", "load")}
            await tui.until(lambda: all(b.display and b.region.area
                                        for b in buttons.values()), what="the file buttons")

            # Save: refused wherever it would write (a gain file), nothing created
            for target in (outside / "gains.toml", data_dir / "gains.toml"):
                field.value = str(target)
                count = len(seen)
                buttons["save"].press()
                await tui.until(lambda n=count: len(seen) > n, what="the answer to Save")
                assert f"save refused: observing: command is held by {holder}; take it " \
                       "first" in seen[-1]
                assert not isinstance(observer.screen, ModalScreen)
                assert not target.exists(), target

            # Load: outside the data directory refused, typed plainly, with .., via a symlink
            away = save_coefficients(outside / "tuned", tuned, observer.machine)
            (data_dir / "link.toml").symlink_to(away)
            presets = dict(tab.presets)
            for typed in (str(away), f"{data_dir}/../elsewhere/tuned.toml",
                          str(data_dir / "link.toml")):
                field.value = typed
                count = len(seen)
                buttons["load"].press()
                await tui.until(lambda n=count: len(seen) > n, what=f"the answer to Load {typed}")
                assert (f"only a file inside the data directory {data_dir} may be named; "
                        f"{typed!r} is outside it") in seen[-1]
                assert tab.presets == presets and not isinstance(observer.screen, ModalScreen)

            # inside it: read and offered as presets, never applied
            inside = save_coefficients(data_dir / "tuned", tuned, observer.machine)
            field.value = str(inside)
            buttons["load"].press()
            await said(tui, seen, "tuned.toml: 1 change(s) to the live sets, offered as "
                       "presets only; apply tuned.toml refused", "the file read, not applied")
            assert "tuned:track" in tab.presets
            assert observer.query_one("#tuning-preset", Select).value == "tuned:track"
            assert not isinstance(observer.screen, ModalScreen)
            assert commander.client.coefficients["track"] == live

            # the commander saves where it chooses
            await show(tui, commander, "f5", "tuning")
            commander.query_one("#tuning-path", Input).value = str(outside / "mine.toml")
            commander.query_one("#tuning-save", Button).press()
            await tui.until(lambda: (outside / "mine.toml").exists(), what="the commander's save")

            # the Moves path file: the observer previews only the data directory's files
            await show(tui, observer, "f2", "moves")
            kinds = observer.query_one("#move-kinds", OptionList)
            kinds.highlighted = next(i for i in range(kinds.option_count)
                                     if str(kinds.get_option_at_index(i).prompt) == "Path file")
            path_input = observer.query_one("#path-file", Input)
            await tui.until(lambda: path_input.region.area, what="the path file form")
            q = observer.client.status().position[3]
            wave = f"t,Bend\n0,{q}\n0.5,{q + 5}\n1.0,{q}\n"
            (outside / "wave.csv").write_text(wave)
            (data_dir / "wave.csv").write_text(wave)
            state = observer.query_one("#path-state")
            path_input.focus()
            path_input.value = str(outside / "wave.csv")
            tui.post_key(observer, "enter")
            await tui.until(lambda: f"data directory {data_dir}" in str(state.render()),
                            what=lambda: f"the outside file refused: {state.render()}")
            path_input.value = str(data_dir / "wave.csv")
            tui.post_key(observer, "enter")
            await tui.until(lambda: "3 points" in str(state.render()),
                            what=lambda: f"the inside file read: {state.render()}")

    asyncio.run(scenario())
