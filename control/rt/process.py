"""Entry point of the control subprocess: owns the backend, runs the loop, cleans up.

``ControlClient`` starts it as a fork of the control processes' server
(``control/rt/forkserver.py``), which has imported this module and nothing of the client's:
it shares nothing with the UI process but one end of a socketpair (the command channel,
``control/rt/wire.py`` frames) and the shared memory.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import traceback

from control.rt import shm
from control.rt.events import Crash, Ready
from control.rt.layout import ControlLayout
from control.rt.loop import Controller, LoopConfig
from control.rt.process_config import ProcessConfig
from control.rt.realtime import enter_realtime
from control.rt.warmup import WarmUp
from control.rt.wire import Broken, Wire
from hw.backend import RealClock
from hw.factory import make_backend
from hw.machine import load_machine

WARM_UP_ENV = "SERVODESK_WARM_UP"  # "0": no shadow ticks; "report": their counters at exit
# "0": no spin before a deadline, whatever the client asked: a loop that sleeps to each one
# (the test suite's controllers, whose wake-up timing is not what those tests test)
SPIN_ENV = "SERVODESK_SPIN"


def main(config: ProcessConfig, wire: Wire) -> None:
    """Run the controller until told to stop, orphaned, or killed by SIGTERM."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl+C belongs to the operator's UI
    segment = shm.attach(config.control_segment)
    controller: Controller | None = None
    try:
        machine = load_machine(config.machine)
        options = config.sim_options
        backend = (make_backend(machine, "sim", seed=config.seed, lockstep=config.lockstep,
                                **options) if config.backend == "sim"
                   else make_backend(machine, config.backend, port=config.port))
        layout = ControlLayout(machine.n_joints)
        layout.check_header(segment.buf)
        loop_config = LoopConfig(
            period_ns=round(config.period_s * 1e9),
            heartbeat_timeout_ns=round(config.heartbeat_timeout_s * 1e9),
            orphan_timeout_ns=round(config.orphan_timeout_s * 1e9),
            slots=config.slots, slips=frozenset(config.slips),
        )
        if isinstance(backend.clock, RealClock) and os.environ.get(SPIN_ENV) != "0":
            backend.clock.spin_ns = round(config.spin_us * 1e3)
        controller = Controller(machine, backend, wire, segment.buf, loop_config)
        signal.signal(signal.SIGTERM, lambda *_: setattr(controller, "running", False))
        backend.open()
        try:
            report = enter_realtime() if config.realtime and not config.lockstep else None
            controller.realtime = bool(report and report.fifo)
            if os.environ.get(WARM_UP_ENV) != "0" and not (report and report.shared):
                controller.warm_up = WarmUp.beside(controller)
            controller.start()
            notice = report.notice if report else "real-time scheduling off (lockstep or asked)"
            controller.outbox.put(Ready(controller.realtime, notice))
            controller.outbox.flush()
            controller.run()
        finally:
            with contextlib.suppress(Exception):
                controller.zero_valves()
            backend.close()
            if controller.warm_up is not None:
                if os.environ.get(WARM_UP_ENV) == "report":  # for benchmarks/loop.py
                    print(controller.warm_up.report(), file=sys.stderr, flush=True)
                controller.warm_up.close()
    except Exception as exc:
        with contextlib.suppress(Broken):
            wire.send(Crash(f"{type(exc).__name__}: {exc}", traceback.format_exc()))
        raise
    finally:
        orphaned = controller is None or controller.orphaned
        handed = controller.release() if controller is not None else []
        shm.release(segment, unlink=orphaned)
        if handed:
            hand_over(handed)


def hand_over(segments: list[str]) -> None:
    """Start the saver of the runs this controller kept for a client that has gone (in
    ``segments``): a process of its own (``control/recovery.py``) that waits for this one to
    exit, then saves them with the run keeper. The control process writes no run file."""
    with contextlib.suppress(OSError):
        subprocess.Popen([sys.executable, "-m", "control.recovery", "--after", str(os.getpid()),
                          *segments], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                         start_new_session=True)
