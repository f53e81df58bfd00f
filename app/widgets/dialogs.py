"""Small modal dialogs: a deliberate confirmation, and one validated value to edit.

Escape is the E-stop on every screen, so a dialog is cancelled with ``n`` or
its Cancel button; the E-stop also closes any dialog that is open.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar, TypeVar

from rich.console import RenderableType
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.validation import ValidationResult, Validator
from textual.widgets import Button, Input, Label, Static

from app.widgets.typed import FieldInput

Answer = TypeVar("Answer")


class Dialog(ModalScreen[Answer]):
    """A box in the middle of the screen: a title, a detail line, buttons."""

    DEFAULT_CSS = """
    Dialog {
        align: center middle;
    }
    .dialog {
        width: 72;
        height: auto;
        border: thick $error;
        background: $surface;
        padding: 1 2;
    }
    .dialog-title {
        text-style: bold;
        margin-bottom: 1;
    }
    .dialog-detail {
        margin-bottom: 1;
    }
    .dialog-error {
        height: auto;
        color: $error;
    }
    .dialog-buttons {
        height: auto;
        margin-top: 1;
    }
    .dialog-buttons Button {
        margin-right: 2;
    }
    """


class ConfirmScreen(Dialog[bool]):
    """Ask once more before something that matters; ``y`` or Enter confirms, ``n`` cancels."""

    BINDINGS: ClassVar = [
        Binding("y", "answer(True)", "yes"),
        Binding("n", "answer(False)", "no"),
    ]

    def __init__(self, question: str, detail: str, confirm: str = "Confirm") -> None:
        super().__init__()
        self.question = question
        self.detail = detail
        self.confirm = confirm

    def compose(self) -> ComposeResult:
        with Vertical(classes="dialog"):
            yield Label(self.question, classes="dialog-title")
            yield Static(self.detail, classes="dialog-detail")
            with Horizontal(classes="dialog-buttons"):
                yield Button(f"{self.confirm} (y)", id="confirm", variant="error")
                yield Button("Cancel (n)", id="cancel")

    def on_mount(self) -> None:
        self.query_one("#confirm", Button).focus()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        self.dismiss(event.button.id == "confirm")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


class ReviewScreen(ConfirmScreen):
    """A confirmation with a long detail (what a change would do, line by line): the
    detail scrolls, the buttons stay in view."""

    DEFAULT_CSS = """
    ReviewScreen .dialog {
        width: 96;
        max-height: 90%;
    }
    ReviewScreen .dialog-review {
        height: auto;
        max-height: 24;
    }
    """

    def __init__(self, question: str, detail: str, review: RenderableType,
                 confirm: str = "Confirm") -> None:
        super().__init__(question, detail, confirm)
        self.review = review

    def compose(self) -> ComposeResult:
        with Vertical(classes="dialog"):
            yield Label(self.question, classes="dialog-title")
            yield Static(self.detail, classes="dialog-detail")
            with VerticalScroll(classes="dialog-review"):
                yield Static(self.review)
            with Horizontal(classes="dialog-buttons"):
                yield Button(f"{self.confirm} (y)", id="confirm", variant="error")
                yield Button("Cancel (n)", id="cancel")


class _Check(Validator):
    def __init__(self, parse: Callable[[str], object]) -> None:
        super().__init__()
        self.parse = parse

    def validate(self, value: str) -> ValidationResult:
        try:
            self.parse(value)
        except ValueError as exc:
            return self.failure(str(exc))
        return self.success()


class EditValueScreen(Dialog[str | None]):
    """Edit one value; ``parse`` raises ValueError with the fix. Returns the text, or None."""

    def __init__(self, title: str, value: str, parse: Callable[[str], object],
                 hint: str = "") -> None:
        super().__init__()
        self.title_text = title
        self.value = value
        self.parse = parse
        self.hint = hint

    def compose(self) -> ComposeResult:
        with Vertical(classes="dialog"):
            yield Label(self.title_text, classes="dialog-title")
            yield Static(self.hint, classes="dialog-detail")
            yield FieldInput(self.value, validators=[_Check(self.parse)], id="edit-value",
                        validate_on=["changed", "submitted"])
            yield Static("", classes="dialog-error", id="edit-error")
            with Horizontal(classes="dialog-buttons"):
                yield Button("Apply (Enter)", id="apply", variant="primary")
                yield Button("Cancel", id="cancel")

    def on_input_changed(self, event: Input.Changed) -> None:
        result = event.validation_result
        self.query_one("#edit-error", Static).update(
            "" if result is None or result.is_valid else result.failure_descriptions[0])

    def on_input_submitted(self, event: Input.Submitted) -> None:
        event.stop()
        self._apply()

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "apply":
            self._apply()
        else:
            self.dismiss(None)

    def _apply(self) -> None:
        text = self.query_one(Input).value
        try:
            self.parse(text)
        except ValueError as exc:
            self.query_one("#edit-error", Static).update(str(exc))
            return
        self.dismiss(text)
