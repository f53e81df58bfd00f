"""Tuning with care (issue 13): Load shows what a file would change and applies it only when
confirmed, all or nothing; Save asks before replacing a file; ctrl+z puts back the set in use
before the last apply; a set the gain check refuses is shown with its reason in the tab."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

from textual.widgets import DataTable, Input, Static

from app.coefficient_files import coefficient_changes, load_coefficients, save_coefficients
from app.widgets.dialogs import ConfirmScreen, ReviewScreen
from hw.machine import load_machine
from tests.app.terminal import REPO

SIZE = (160, 48)
UNIMATE = load_machine("unimate2000b")


def shown(widget: Static) -> str:
    return str(widget.render())


async def open_tuning(tui, app, pilot) -> DataTable:
    await tui.ready(app, pilot)
    await pilot.press("f5")
    table = app.query_one("#tuning-joints", DataTable)
    await tui.until(lambda: app.focused is table, what="the table focused")
    return table


def test_changes_between_two_sets_are_listed_by_joint_and_key() -> None:
    track = UNIMATE.track
    tuned = replace(track, kp=((25.0,), *track.kp[1:]), ki=(track.ki[0], 21.0, *track.ki[2:]),
                    filter_divisor=2.0)
    assert coefficient_changes(track, tuned, UNIMATE) == [
        ("In/Out", "kp", ", ".join(f"{t:g}" for t in track.kp[0]), "25"),
        ("Rotate", "ki", f"{track.ki[1]:g}", "21"),
        ("all joints", "filter_divisor", f"{track.filter_divisor:g}", "2"),
    ]
    assert coefficient_changes(track, track, UNIMATE) == []


def test_save_asks_load_applies_only_on_confirm_then_undo_and_a_refused_file_applies_nothing(
        tui, tmp_path: Path) -> None:
    """On one app, each part starting from the sets in use (the undo puts them back): Save asks
    before replacing a file; Load shows the differences and applies only on confirm, ^Z puts
    back the set before; a file whose hold set passes the check and whose track set (In/Out's
    kp negated) does not applies neither, and the reason stays in the tab."""
    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            table = await open_tuning(tui, app, pilot)
            client = app.client
            path_field = app.query_one("#tuning-path", Input)

            # Save asks before replacing a file
            mine = tmp_path / "mine.toml"
            mine.write_text("# the operator's own notes\n")
            path_field.value = str(mine)
            await pilot.click("#tuning-save")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            await pilot.press("n")
            await tui.until(lambda: not isinstance(app.screen, ConfirmScreen))
            assert mine.read_text() == "# the operator's own notes\n", "replaced after no"
            await pilot.click("#tuning-save")
            await tui.until(lambda: isinstance(app.screen, ConfirmScreen), what="the question")
            await pilot.press("y")
            await tui.until(lambda: "[coefficients.track]" in mine.read_text(), what="saved")
            assert load_coefficients(mine, app.machine)["track"] == client.coefficients[
                "track"], "the file saved is not the track set in use"

            # Load: the differences, applied only on confirm, then undone
            live = client.coefficients["track"]
            tuned = replace(live, kp=((18.0,), *live.kp[1:]))  # In/Out's kp → 18
            path = save_coefficients(tmp_path / "tuned", {"track": tuned}, app.machine)
            path_field.value = str(path)
            await pilot.click("#tuning-load")
            await tui.until(lambda: isinstance(app.screen, ReviewScreen), what="the review")
            review = "\n".join(str(s.render()) for s in app.screen.query(Static))
            assert "track set ← 'track' from tuned.toml" in review
            assert "In/Out" in review and "kp" in review and f"{live.kp[0][0]:g} → 18" in review
            assert client.coefficients["track"] == live  # nothing yet
            await pilot.press("n")
            await tui.until(lambda: not isinstance(app.screen, ReviewScreen))
            assert client.coefficients["track"] == live
            assert "not applied" in shown(app.query_one("#tuning-outcome"))
            await pilot.click("#tuning-load")
            await tui.until(lambda: isinstance(app.screen, ReviewScreen), what="the review")
            await pilot.press("y")
            await tui.until(lambda: client.coefficients["track"] == tuned,
                            what=lambda: shown(app.query_one("#tuning-outcome")))
            await tui.until(lambda: table.get_row_at(0)[1] == "18", what="the table updated")
            table.focus()
            await pilot.press("ctrl+z")
            await tui.until(lambda: client.coefficients["track"] == live, what="undone")
            assert "undone" in shown(app.query_one("#tuning-outcome"))
            await pilot.press("ctrl+z")  # nothing left to undo: nothing changes
            assert client.coefficients["track"] == live

            # a file with a refused set applies nothing, and says why in the tab
            hold, track = client.coefficients["hold"], client.coefficients["track"]
            sets = {"hold": replace(hold, ki=(hold.ki[0] * 0.5, *hold.ki[1:])),
                    "track": replace(track, kp=((-20.0,), *track.kp[1:]))}
            path_field.value = str(save_coefficients(tmp_path / "mixed", sets, app.machine))
            await pilot.click("#tuning-load")
            await tui.until(lambda: isinstance(app.screen, ReviewScreen), what="the review")
            await pilot.press("y")
            outcome = app.query_one("#tuning-outcome")
            await tui.until(lambda: "refused" in shown(outcome), what="the refusal in the tab")
            assert "In/Out: unstable on the nominal model: negative gain" in shown(outcome)
            assert client.coefficients == {"hold": hold, "track": track}

    asyncio.run(scenario())


def test_the_first_gain_check_leaves_the_ui_taking_keys_esc_included(tui) -> None:
    """A fresh interpreter, so that the first apply imports scipy.signal for its gain check
    (about 1 s, 3 under load; this one has it loaded). Apply preset twice, and Esc straight
    after: the second apply waits behind the first's check, the E-stop is taken while that
    check still runs, and both applies are made after, in order. The old tab checked on the
    UI's thread, so Esc waited for the import and both applies."""
    script = f"""
import asyncio, json, sys
from pathlib import Path
from textual import events
from textual.widgets import Button
import app.tui
from app.tui import ServodeskApp

class Live(ServodeskApp):
    CSS_PATH = [str(Path(app.tui.__file__).parent / path) for path in ServodeskApp.CSS_PATH]

async def main():
    app = Live("unimate2000b", "sim", None, {str(tui.data_dir)!r},
               client_options={{"heartbeat_timeout_s": 2.0}})
    async with app.run_test(size=(160, 48)) as pilot:
        while app.client is None or app.client.status() is None:
            await asyncio.sleep(0.01)
        await pilot.press("f5")
        while not app.query("#tuning-apply-preset") or not app.query("#tuning-outcome"):
            await asyncio.sleep(0.01)
        outcome = app.query_one("#tuning-outcome")
        loaded_before = "scipy.signal" in sys.modules
        app.query_one("#tuning-apply-preset", Button).press()
        app.query_one("#tuning-apply-preset", Button).press()
        app._driver.send_message(events.Key("escape", None))
        while not app.estop_latched:
            await asyncio.sleep(0.002)
        at_estop = str(outcome.render())
        tab = app.query_one("#tab-tuning")
        while tab.checking or tab.waiting or not app.client.status().estop:
            await asyncio.sleep(0.01)
        print(json.dumps({{"loaded_before": loaded_before, "at_estop": at_estop,
                          "after": str(outcome.render()),
                          "applies": len(tab.undo_stack)}}))

asyncio.run(main())
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert not seen["loaded_before"], "scipy.signal loaded before the first apply"
    assert "preset track: waits for the check of preset track" in seen["at_estop"], (
        f"Esc taken only after the check: {seen}")
    assert "preset track applied to the track set" in seen["after"], seen
    assert seen["applies"] == 2, seen
