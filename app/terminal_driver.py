"""The terminal's driver: Textual's Linux driver, resumed only from its own suspend.

Textual's driver restarts application mode at every SIGCONT: a new input reader and a new
writer beside the ones still running. After its own suspend (SIGTSTP: ^Z, then the shell's
``fg``) the old ones have stopped and that is right; after a SIGSTOP from outside (a
debugger, ``kill -STOP``, a job-control tool) they have not, and two readers then take the
terminal's bytes between them, so keys arrive split and out of order: an arrow's escape
sequence read half by each is an Esc and two letters. This driver resumes only when it
suspended.
"""

from __future__ import annotations

from textual.drivers.linux_driver import LinuxDriver


class TerminalDriver(LinuxDriver):
    def _sigcont_application(self, *args: object) -> None:
        if self._must_signal_resume:  # set by the driver's own SIGTSTP handler, and only there
            super()._sigcont_application(*args)
