"""Text fields that apply keys in the order they were typed.

Textual hands a key to the focused widget's queue. An ``Input`` or ``TextArea`` inserts a
printable character there at once, but its editing keys (backspace, delete, the arrows,
home, end, ctrl+w …) are bindings, and a binding runs only after the key has bubbled up
through every container to the app (``App._on_key``), a dozen queues later on the Moves
tab. The characters typed meanwhile go in first, and a late backspace eats one of them:
in tmux, 10 backspaces then a number, keys 5 ms apart, left a wrong value in 61 of 104
tries over the Moves forms (``1618.0`` -> ``618.0``, ``-1.4`` -> ``1.4``), 27 at 10 ms, 31
at 20 ms (issue 26; Textual issue 6605). A ``FieldInput`` runs its own bindings as it
takes the key, in its own queue, so every key acts in the order it came: 0 of 104 at
each (``python benchmarks/typing.py``). Nothing else changes: priority bindings (the
E-stop) act before the key reaches the field, as before, and a key the field does not bind
bubbles on as before."""

from __future__ import annotations

from textual import events
from textual.widget import Widget
from textual.widgets import Input, TextArea


class KeysInOrder(Widget):
    """A widget that runs its own (non-priority) key bindings when it takes the key, instead
    of when the key has bubbled to the app."""

    async def _on_key(self, event: events.Key) -> None:
        # Textual calls every class's ``_on_key`` down the MRO until one prevents the default:
        # the field's own (after this mixin in the MRO) has inserted a printable character
        for binding in self._bindings.key_to_bindings.get(event.key, ()):
            if not binding.priority and await self.app.run_action(binding.action, self):
                event.stop()  # acted on here: the app must not act on it again
                event.prevent_default()
                return


# the widget's class first: Textual's CSS and queries know a widget by its first bases
class FieldInput(Input, KeysInOrder):
    """An ``Input`` whose editing keys act in the order typed."""


class FieldTextArea(TextArea, KeysInOrder):
    """A ``TextArea`` whose editing keys act in the order typed."""
