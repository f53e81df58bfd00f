"""The smaller things issue 26 found: a range message that says the real bound, ^K that a text
field keeps, refusals in the TUI's words, the line of a file's fault, the preset list on the
set chosen, Initialise without a step's columns under a 0 % bar, Esc on an open list."""

from __future__ import annotations

import asyncio
from dataclasses import replace

from rich.text import Text
from textual.widgets import DataTable, Input, ProgressBar, RadioButton, Select, Static
from textual.widgets._select import SelectOverlay

from app.coefficient_files import CoefficientFileError, dump_coefficients, parse_coefficients
from app.tabs.tuning import TuningTab
from app.tui import attached_app
from app.widgets.fields import NumberField, seconds_check
from app.widgets.live_text import LiveText
from control.motion.positions import PositionsError, parse_positions
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
POSITIONS = """# Taught positions, edited by hand
machine = "unimate2000b"

[[position]]
name = "above"
joints = [1300, 0, 0, 0, 90, 0]

[[position]]
name = "below"
joints = [1300, 0, -5, 0, 90, 0]

"""


def test_a_time_above_0_says_so() -> None:
    """0 s is not outside 0…600 s: the message says the bound that 0 breaks."""
    result = seconds_check("ramp time").validate("0")
    (message,) = result.failure_descriptions
    assert "more than 0 s" in message and "at most 600 s" in message, message
    assert "outside 0…" not in message, message


def test_a_file_fault_names_its_line() -> None:
    """A fault on line 12 of a positions file (a table of its own) and of a coefficient file
    (a set's key) is named as on line 12."""
    assert POSITIONS.count("\n") == 11
    try:
        parse_positions(POSITIONS + "[stations]\nx = 1\n", UNIMATE, "mine.toml")
    except PositionsError as exc:
        assert str(exc).startswith("mine.toml: line 12: unknown key 'stations'"), exc
    else:
        raise AssertionError("a positions file with a [stations] table was read")
    lines = dump_coefficients({"hold": UNIMATE.hold}, UNIMATE).splitlines()
    assert lines[11].startswith("integral_limit = ")
    for fault in ("integral_limit = -5.0", 'integral_limit = "x"', "integral_limt = 100.0"):
        bad = "\n".join([*lines[:11], fault, *lines[12:]])
        try:
            parse_coefficients(bad, UNIMATE, "gains.toml")
        except CoefficientFileError as exc:
            assert str(exc).startswith("gains.toml: coefficients.hold"), exc
            assert str(exc).endswith("(at line 12)"), exc
        else:
            raise AssertionError(f"{fault!r} was read")


def test_ctrl_k_in_a_text_field_is_the_fields(controller_service, tui) -> None:
    """A TUI attached to a controller service: ^K in the Moves target field deletes to the
    end of the field (Textual's Input) and does not take command; on the Jog tab it does."""

    async def scenario() -> None:
        app = attached_app(controller_service.socket)
        async with app.run_test(size=(160, 48)) as pilot:
            await tui.ready(app, pilot)
            health = app.query_one("#header-health", LiveText)
            await tui.until(lambda: "observing" in health.text, what="observing")
            await pilot.press("f2")
            target = app.query_one("#form-step #target", NumberField)
            target.input.focus()
            target.text = "1712.5"
            await pilot.press("home", "right", "right", "right", "right", "ctrl+k")
            await tui.until(lambda: target.text == "1712", what=lambda: f"{target.text!r}")
            assert "COMMANDING" not in health.text
            await pilot.press("f1")
            await tui.until(lambda: not isinstance(app.focused, Input), what="the Jog tab")
            await pilot.press("ctrl+k")
            await tui.until(lambda: "COMMANDING" in health.text, what="command taken on Jog")

    asyncio.run(scenario())


def test_the_tuning_tab_says_what_to_do_and_its_preset_list_shows_the_set_chosen(tui) -> None:
    """One app's Tuning tab (these were two tests, each with an app of its own):

    The gain check's refusal, in the tab, the notice and the log: the joint and why, and what
    to do with the TUI's keys, not an API call. The refusal applies nothing: the preset list
    is then checked on the sets the tab started with.

    Choosing the hold set puts the preset list on "hold" (it kept saying "track")."""

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=(160, 48)) as pilot:
            await tui.ready(app, pilot)
            said = tui.notifications(app)
            await pilot.press("f5")
            tab = app.query_one(TuningTab)
            before = app.client.coefficients
            refused = replace(app.machine.hold, kp=((-20.0,), *app.machine.hold.kp[1:]))
            tab.apply({"hold": refused}, "a test")
            await tui.until(lambda: "refused" in str(app.query_one("#tuning-outcome",
                                                                     Static).render()),
                            what="the refusal in the tab")
            outcome = str(app.query_one("#tuning-outcome", Static).render())
            logged = [e.what for e in app.desk.events.entries if e.kind == "refused"]
            for text in (outcome, said[-1], logged[-1]):
                assert "In/Out" in text and "Identify tab" in text, text
                assert "set_coefficients" not in text and "override=" not in text, text
            assert app.client.coefficients == before, "the refused set was applied"
            # the preset list on the set chosen
            preset = app.query_one("#tuning-preset", Select)
            assert preset.value == "track"
            await pilot.click(app.query_one("#which-hold", RadioButton))
            await tui.until(lambda: tab.which == "hold", what="hold chosen")
            await tui.until(lambda: preset.value == "hold", what=lambda: f"{preset.value!r}")
            await pilot.click(app.query_one("#which-track", RadioButton))
            await tui.until(lambda: preset.value == "track", what=lambda: f"{preset.value!r}")

    asyncio.run(scenario())


def test_initialise_shows_no_steps_columns_under_a_0_bar(tui) -> None:
    """The rig's Initialise: before, while and after it runs no step's result columns; the
    bar pulses while it runs and is full when it is done (it stood at 0 %)."""

    async def scenario() -> None:
        app = tui.app("rig")
        async with app.run_test(size=(120, 36)) as pilot:
            await tui.ready(app, pilot)
            await pilot.press("f2")
            result = app.query_one("#move-result", DataTable)
            assert "step" not in tui.text(result), tui.text(result)  # no move yet
            kinds = app.query_one("#move-kinds")
            kinds.highlighted = next(i for i in range(kinds.option_count)
                                     if str(kinds.get_option_at_index(i).prompt) == "Initialise")
            await pilot.pause()
            await pilot.press("ctrl+s")
            state = app.query_one("#move-state")
            await tui.until(lambda: "initialise: complete" in tui.text(state),
                            what=lambda: f"the initialise done: {tui.text(state)!r}")
            await pilot.pause()
            bar = app.query_one("#move-progress", ProgressBar)
            assert bar.percentage == 1.0, (bar.progress, bar.total)
            assert not tui.text(result).strip(), tui.text(result)

    asyncio.run(scenario())


def test_esc_on_an_open_list_latches_and_closes_it(tui) -> None:
    """Esc with the Step form's joint list open: the E-stop latches (it always wins) and the
    list is closed, none left over the tab bar."""

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=(80, 24)) as pilot:
            await tui.ready(app, pilot)
            await pilot.press("f2")
            joint = app.query_one("#form-step Select", Select)
            joint.focus()
            await pilot.press("enter")
            overlay = joint.query_one(SelectOverlay)
            await tui.until(lambda: joint.expanded and overlay.display, what="the list open")
            await pilot.press("escape")
            await tui.until(lambda: app.estop_latched, what="the E-stop latched")
            await tui.until(lambda: app.client.status().estop, what="the controller latched")
            await pilot.pause()
            assert not joint.expanded
            assert overlay.region.height == 0 or not overlay.display
            lamp = Text(tui.text(app.query_one("#estop-lamp"))).plain
            assert "E-STOP" in lamp, lamp

    asyncio.run(scenario())
