"""Every key typed into a form acts in the order typed, however fast the keys come (issue 26).

Every field of every kind of Moves form (numbers, the path file's name, the via points) is
given a value, then sent 7 backspaces and a new value as the terminal driver
sends keys (``Driver.send_message``), all at once, with no wait between them: the field
must hold the new value (what the form reads when it plans the move) once it has taken them
all, and still at the end, with every form typed into.
The forms sit in a plain app (no controller: the fast set) under as many containers as the
Moves tab puts over them, since a key that bubbles crosses every one.

Before app/widgets/typed.py the backspaces ran last, after bubbling to the app, and ate the
characters typed after them: every field was left empty.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from functools import partial

from textual import events
from textual.app import App, ComposeResult
from textual.containers import Container, Vertical, VerticalScroll
from textual.dom import DOMNode
from textual.keys import _character_to_key
from textual.pilot import Pilot
from textual.widget import Widget
from textual.widgets import TextArea

from app.tabs.move_forms import MoveForm
from app.tabs.moves import forms_for
from app.widgets.fields import NumberField
from control.motion.robot_model import has_unimate_model, unimate_model
from hw.machine import load_machine

OLD = "1508.44"  # what the operator types over (issue 26's case)
CLEAR = 7  # every backspace has a character to delete
NUMBER = "1712.5"
DEPTH = 8  # containers over a form on the Moves tab (tab, panes, switchers, columns)
TAKEN_S = 60.0  # for a field to take its keys: some 10 ms, seconds on a loaded machine


class Forms(App[None]):
    """Every kind of Moves form, one under the other: the Unimate 2000B's, and the rig's that
    the Unimate has not (each machine's in a column of its own: their ids are the same)."""

    def compose(self) -> ComposeResult:
        seen: set[type[MoveForm]] = set()
        columns = []
        for name in ("unimate2000b", "rig"):
            machine = load_machine(name)
            model = unimate_model(machine) if has_unimate_model(machine) else None
            kinds = [kind for kind in forms_for(machine) if kind not in seen]
            seen.update(kinds)
            columns.append(Vertical(*[kind(machine, model) for kind in kinds]))
        with VerticalScroll():
            yield nested(columns)


def nested(columns: list[Widget], depth: int = DEPTH) -> Widget:
    inner: Widget = Vertical(*columns)
    for _ in range(depth):
        inner = Container(inner)
    return inner


def fields(app: Forms) -> list[Widget]:
    """Every text field a key can reach: number fields (their inputs), the path file's
    name, the via points."""
    return [w for w in app.query("Input, TextArea") if w.focusable]


def typed(widget: Widget) -> str:
    return widget.text if isinstance(widget, TextArea) else str(getattr(widget, "value", ""))


def send(app: App, keys: list[str]) -> None:
    """Keys as the terminal driver delivers them, none waiting for another."""
    assert app._driver is not None
    for key in keys:
        if key == "backspace":
            app._driver.send_message(events.Key("backspace", "\x7f"))
        else:
            app._driver.send_message(events.Key(_character_to_key(key), key))


async def type_everywhere() -> list[str]:
    """Type into every field of every form, the form shown alone as the Moves tab shows it
    (with every form shown, each key's change laid out the screen's 51 fields again: 0.25 s
    a field); return what came out wrong."""
    app = Forms()
    wrong: list[str] = []
    async with app.run_test(size=(160, 48)) as pilot:
        forms = list(app.query(MoveForm))
        for form in forms:
            form.reveal_later()
        for _ in range(5):  # a staged form draws one part a refresh
            await pilot.pause()
        found = fields(app)
        assert len(found) >= 30, f"only {len(found)} fields in the forms"
        assert all(any(f in w.ancestors for f in forms) for w in found), "a field in no form"
        for form in forms:
            form.display = False
        for form in forms:
            form.display = True
            await pilot.pause()
            wrong += await type_into(pilot, [w for w in found if form in w.ancestors])
            form.display = False
        await pilot.pause()
        wrong += [f"{describe(w)}: {typed(w)!r} at the end" for w in found
                  if typed(w) != NUMBER]
    return wrong


async def type_into(pilot: Pilot, found: list[Widget]) -> list[str]:
    """Type into each field of ``found``; return what came out wrong."""
    app = pilot.app
    wrong: list[str] = []
    for widget in found:
        widget.focus()
        if isinstance(widget, TextArea):
            widget.text = OLD
            widget.move_cursor(widget.document.end)
        else:
            widget.value = OLD
            widget.cursor_position = len(OLD)
        send(app, ["backspace"] * CLEAR + list(NUMBER))
        await taken(app, widget)
        if typed(widget) != NUMBER:  # wrong once taken: wrong still when the app is idle?
            await wait_for(lambda w=widget: typed(w) == NUMBER, pilot)
        if typed(widget) != NUMBER:
            wrong.append(f"{describe(widget)}: {typed(widget)!r}")
    return wrong


async def taken(app: App, widget: Widget) -> None:
    """Until every key sent so far has been taken where it goes: by the app (which hands a
    key to the focused ``widget``), the widget, and each container a key the widget leaves
    bubbles through, up to the app (where the old code's backspaces ran). A callback sent as
    the keys were runs after them on the app, then queues one on the widget, which queues
    one on its parent, and so on: each runs after the keys its queue held. A pause of the
    pilot there waited for every widget of the ten forms: some 70 ms a field."""
    assert app._driver is not None
    done: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def then(pumps: list[DOMNode]) -> None:
        if pumps:
            pumps[0].call_later(then, pumps[1:])
        elif not done.done():
            done.set_result(None)

    app._driver.send_message(events.Callback(
        callback=partial(then, [widget, *widget.ancestors])))
    await asyncio.wait_for(done, TAKEN_S)


async def wait_for(condition: Callable[[], bool], pilot: Pilot, attempts: int = 20) -> None:
    """Let the app take the keys: until ``condition()``, or until it has been idle a while
    (a wrong value never comes right)."""
    for _ in range(attempts):
        if condition():
            return
        await pilot.pause()


def describe(widget: Widget) -> str:
    form = next((a for a in widget.ancestors if isinstance(a, MoveForm)), None)
    field = next((a for a in widget.ancestors if isinstance(a, NumberField)), None)
    where = field.label if field is not None else (widget.id or type(widget).__name__)
    return f"{type(form).__name__ if form else '?'} {where}"


def test_keys_typed_with_no_pause_land_in_order_in_every_field() -> None:
    wrong = asyncio.run(type_everywhere())
    assert not wrong, f"{len(wrong)} fields took the keys out of order: " + "; ".join(wrong)
