"""Tabs and big forms drawn in parts the first time they are shown (app/widgets/staged.py):
the first frames show the first parts only, and every part is shown in the end, where it
would have been (nothing moves when a later part appears)."""

from __future__ import annotations

import asyncio
import itertools

from textual.errors import NoWidget
from textual.widget import Widget
from textual.widgets import OptionList, TabbedContent

from app.tabs.end_point_form import EndPointForm
from app.tui import TABS

SIZE = (160, 48)


def on_screen(widget: Widget) -> bool:
    """Whether the screen shows ``widget`` (or one of its own) at its middle."""
    region = widget.region
    if not region.area:
        return False
    try:
        found, _ = widget.screen.get_widget_at(*region.center)
    except NoWidget:
        return False
    return widget in found.ancestors_with_self


async def watch_parts(app, parts: list[Widget], show) -> list[tuple[bool, ...]]:
    """``show()``, then which of ``parts`` the screen shows, after every turn of the event
    loop until it shows them all: the distinct states, in order."""
    regions = {}
    show()
    states: list[tuple[bool, ...]] = []
    for _ in range(5000):
        await asyncio.sleep(0)
        state = tuple(on_screen(p) for p in parts)
        for p, shown in zip(parts, state, strict=True):
            if shown and p not in regions:
                regions[p] = p.region
        if not states or states[-1] != state:
            states.append(state)
        if all(state):
            break
    assert {p: p.region for p in parts} == regions  # drawn where its room was kept
    return states


def test_the_moves_tab_is_drawn_in_parts_the_first_time_and_whole_after(tui) -> None:
    async def scenario() -> None:
        app = tui.app(build_behind=True)  # as the operator's: every tab built once live
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            parts = [app.query_one(s) for s in ("#move-kinds", "#move-forms", "#move-preview",
                                                "#move-result")]
            tabs = app.query_one(TabbedContent)
            states = await watch_parts(app, parts, lambda: setattr(tabs, "active",
                                                                   "pane-moves"))
            shown = [s for s in states if any(s)]
            assert shown[0] == (True, False, False, False), states  # the kinds first, alone
            assert shown[-1] == (True,) * 4, states
            for before, after in itertools.pairwise(shown):  # a part once shown stays
                assert all(a or not b for b, a in zip(before, after, strict=True)), states

            form = app.query_one(EndPointForm)
            parts = [form.query_one(s) for s in ("#pose-x", "#pose-alpha", "#ik-solutions")]
            menu = app.query_one("#move-kinds", OptionList)
            index = next(i for i, o in enumerate(menu.options) if o.id == "EndPointForm")
            states = await watch_parts(app, parts, lambda: setattr(menu, "highlighted", index))
            shown = [s for s in states if any(s)]
            assert shown[0] == (True, False, False), states
            assert shown[-1] == (True,) * 3, states

    asyncio.run(scenario())


def test_every_tab_ends_up_whole(tui) -> None:
    """Every tab opened in turn, each left before its parts could be drawn: every part of
    each is shown when the tab is next opened."""
    async def scenario() -> None:
        app = tui.app(build_behind=True)  # as the operator's: every tab built once live
        async with app.run_test(size=SIZE) as pilot:
            await tui.ready(app, pilot)
            tabs = app.query_one(TabbedContent)
            for name, _ in TABS:
                tabs.active = f"pane-{name}"
                await asyncio.sleep(0)
            for name, _ in TABS:
                tabs.active = f"pane-{name}"
                tab = app.tab(name)
                for widget in [w for selector in tab.LATER for w in tab.query(selector)]:
                    await tui.until(lambda w=widget: on_screen(w),
                                    what=f"{name}'s {widget} shown")

    asyncio.run(scenario())
