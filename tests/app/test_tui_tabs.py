"""Scope, Status, Tuning and Latency tabs: each one's main flow against the simulator."""

from __future__ import annotations

import asyncio
import re
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from textual.widgets import DataTable, Input

from app.coefficient_files import load_coefficients, save_coefficients
from app.tabs.latency import LatencyTab
from app.tabs.scope import JointScope, ScopeTab
from app.tabs.tuning import parse_number, parse_taps
from app.widgets.dialogs import EditValueScreen
from app.widgets.live_text import LiveText
from app.widgets.scope import ScopePlot
from control.motion.robot_model import builtin_unimate
from hw.machine import COEFFICIENT, FILTER_DIVISOR, load_machine

SIZE = (160, 48)
BRAILLE = range(0x2801, 0x2900)


def test_scope_then_latency(tui, monkeypatch) -> None:
    """The Scope's and the Latency tab's flows, one after the other on one app (they were
    two tests, each with an app of its own)."""
    monkeypatch.setattr("app.tabs.latency.TEST_S", 0.5)

    async def scenario() -> None:
        app = tui.app(lockstep=False)
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            await scope_draws_live_traces_and_answers_its_keys(tui, app, pilot)
            await latency_tab_shows_table_2_1_and_runs_a_fresh_test(tui, app, pilot)

    asyncio.run(scenario())


async def scope_draws_live_traces_and_answers_its_keys(tui, app, pilot) -> None:
    tui.post_key(app, "f3")
    await tui.built(app, pilot)  # the Scope is built when first shown
    scope = app.query_one(ScopeTab)
    await tui.until(lambda: scope.visible_now and len(app.history) > 50,
                    what="samples in the scope")
    first = app.query_one("#scope-joint-0 .scope-position", ScopePlot)
    await tui.until(lambda: "In/Out [mm]" in tui.text(first), what="the first frame")
    assert any(ord(c) in BRAILLE for c in tui.text(first)), "no trace drawn"
    tui.post_key(app, "2")  # hide Rotate
    await tui.until(lambda: not app.query_one("#scope-joint-1", JointScope).display)
    tui.post_key(app, "p")
    await tui.until(lambda: scope.paused)
    frozen = tui.text(first)
    await asyncio.sleep(0.3)
    assert tui.text(first) == frozen
    tui.post_key(app, "e")
    await tui.until(lambda: "error" in tui.text(first))
    tui.post_key(app, "minus")
    await tui.until(lambda: scope.window_s == 20.0)
    assert "PAUSED" in app.query_one("#scope-bar", LiveText).text


def test_status_then_tuning(tui, tmp_path: Path) -> None:
    """The Status tab's flow, then the Tuning tab's refusal and its edits, one after the other
    on one app (they were three tests, each with an app of its own; the refusal applies
    nothing, so the edits start from the sets in use, as on an app of their own)."""

    async def scenario() -> None:
        app = tui.app()
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            await status_shows_joints_pose_loop_and_link(tui, app, pilot)
            await a_set_the_gain_check_refuses_is_shown_and_applies_nothing(tui, app, pilot)
            await tuning_edits_apply_live_and_files_round_trip(tui, app, pilot, tmp_path)

    asyncio.run(scenario())


async def status_shows_joints_pose_loop_and_link(tui, app, pilot) -> None:
    await pilot.press("f4")
    joints = app.query_one("#status-joints", LiveText)
    await tui.until(lambda: "Swivel" in tui.text(joints), what="the joints table")
    for joint in app.machine.joints:
        assert joint.name in tui.text(joints)
    pose = tui.text(app.query_one("#status-pose", LiveText))
    x = builtin_unimate().pose(np.array(app.client.status().position))[0]
    shown = float(re.search(r"^ *x +(-?[\d.]+) mm", pose, re.MULTILINE).group(1))
    assert "end effector" in pose and abs(shown - x) < 1.0  # eq. 4.11 of the reading
    loop = tui.text(app.query_one("#status-loop", LiveText))
    assert "sample" in loop and "lateness" in loop and "HOLD" in loop
    assert re.search(r"supply +6\.90 MPa", loop)  # the simulator's pump, section 4.6.1
    assert "crc errors" in tui.text(app.query_one("#status-link", LiveText))


async def tuning_edits_apply_live_and_files_round_trip(tui, app, pilot, tmp_path: Path) -> None:
    await pilot.press("f5")
    table = app.query_one("#tuning-joints", DataTable)
    await tui.until(lambda: app.focused is table,
                    what=lambda: f"the table focused, not {app.focused}")
    table.move_cursor(row=2, column=1)  # Up/Down kp of the track set
    await pilot.press("enter")
    assert isinstance(app.screen, EditValueScreen)
    edit = app.screen.query_one(Input)
    edit.value = "abc"
    await pilot.press("enter")
    assert isinstance(app.screen, EditValueScreen)  # refused, says why
    assert "numbers separated by commas" in str(app.screen.query_one("#edit-error")
                                                .render())
    edit.value = "42, -3"
    await pilot.press("enter")
    assert not isinstance(app.screen, EditValueScreen)
    assert app.client.coefficients["track"].kp[2] == (42.0, -3.0)
    app.query_one("#tuning-preset").value = "thesis_pi"
    await pilot.click("#tuning-apply-preset")
    assert app.client.coefficients["track"].kp[0] == (20.0,)
    assert app.client.coefficients["track"].ki[1] == 20.0  # section 5.4.2 Rotate
    path = tmp_path / "tuned.toml"
    app.query_one("#tuning-path", Input).value = str(path)
    await pilot.click("#tuning-save")
    await tui.until(path.exists, what="the file saved")
    saved = load_coefficients(path, app.machine)
    assert saved["track"].ki == app.client.coefficients["track"].ki
    path.write_text(path.read_text().replace("[coefficients.hold]",
                                             "[coefficients.mine]"))
    await pilot.click("#tuning-load")
    await tui.until(lambda: "tuned:mine" in app.query_one("#tab-tuning").presets,
                    what="the loaded set offered as a preset")


async def a_set_the_gain_check_refuses_is_shown_and_applies_nothing(tui, app, pilot) -> None:
    """In/Out's kp edited to −20 in the track set: the client refuses it (issue 11's gain
    check) and the tab shows why; the set in use and the table are unchanged."""
    seen = tui.notifications(app)
    await pilot.press("f5")
    table = app.query_one("#tuning-joints", DataTable)
    await tui.until(lambda: app.focused is table, what="the table focused")
    before = app.client.coefficients["track"]
    table.move_cursor(row=0, column=1)  # In/Out kp of the track set
    await pilot.press("enter")
    app.screen.query_one(Input).value = "-20"
    await pilot.press("enter")
    await tui.until(lambda: any("refused" in m for m in seen), what=lambda: str(seen))
    (shown,) = [m for m in seen if "refused" in m]
    assert "In/Out: unstable on the nominal model: negative gain" in shown, shown
    in_tab = str(app.query_one("#tuning-outcome").render())  # not only in a toast
    assert "In/Out: unstable on the nominal model: negative gain" in in_tab, in_tab
    assert app.client.coefficients["track"] == before
    assert table.get_row_at(0)[1] == f"{before.kp[0][0]:g}"


async def latency_tab_shows_table_2_1_and_runs_a_fresh_test(tui, app, pilot) -> None:
    """(``TEST_S`` set to 0.5 s by the test.)"""
    await pilot.press("f7")
    total = app.query_one("#latency-total")
    await tui.until(lambda: "since the controller started" in tui.text(total),
                    what="Table 2.1")
    assert "lateness µs" in tui.text(total)
    tab = app.query_one(LatencyTab)
    clicked = time.monotonic()
    await pilot.click("#latency-test")
    await tui.until(lambda: tab.fresh is not None, timeout=30, what="the fresh test")
    waited_s = time.monotonic() - clicked
    # 0.5 s at 1 kHz, or as long as a loaded machine kept the UI's timer waiting
    assert 300 < tab.fresh.ticks <= 1000 * waited_s + 50
    fresh = app.query_one("#latency-fresh")
    await tui.until(lambda: "fresh" in tui.text(fresh), what="the fresh table")


def test_the_rigs_observer_preset_is_refused_with_the_reason(tui) -> None:
    """Section 3.6.2's observer as printed cannot be stable (errata #12): the preset is
    offered and refused with the client's message; the thesis's PID preset applies."""
    async def scenario() -> None:
        app = tui.app("rig")
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            seen = tui.notifications(app)
            await pilot.press("f5")
            await pilot.pause()
            app.query_one("#tuning-preset").value = "observer"
            await pilot.click("#tuning-apply-preset")
            await tui.until(lambda: any("refused" in m for m in seen), what=lambda: str(seen))
            assert any("Ram: unstable on the nominal model: a closed-loop pole at |z| = 94.98"
                       in m for m in seen), seen
            assert app.client.coefficients["track"] == app.machine.track
            app.query_one("#tuning-preset").value = "thesis_track"
            await pilot.click("#tuning-apply-preset")
            thesis = app.machine.coefficients["thesis_track"]
            await tui.until(lambda: app.client.coefficients["track"] == thesis, what=lambda: (
                f"the preset applied; the track set is {app.client.coefficients['track'].name!r}"
                f", the tab says {app.query_one('#tuning-outcome').render()!s:.300}, told {seen}"))

    asyncio.run(scenario())


def test_the_tuning_tab_takes_only_what_a_machine_file_takes(tmp_path: Path) -> None:
    """A coefficient typed in the Tuning tab lies in the machine file's range (issue 12): at
    its ends a set saves and loads back; past them the cell says why."""
    machine = load_machine("rig")
    with pytest.raises(ValueError, match=r"taps must lie within ±1e\+06"):
        parse_taps("0.5, -2e6")
    with pytest.raises(ValueError, match=r"out of range: enter a value ≥ -1e\+06 and ≤ 1e\+06"):
        parse_number("1e7", -COEFFICIENT, COEFFICIENT)
    extreme = replace(machine.track, kp=(parse_taps("1e6, -1e6"),), ki=(-COEFFICIENT,),
                      filter_divisor=FILTER_DIVISOR[0], integral_limit=COEFFICIENT)
    path = save_coefficients(tmp_path / "extreme", {"track": extreme}, machine)
    assert load_coefficients(path, machine)["track"].kp == ((1e6, -1e6),)
