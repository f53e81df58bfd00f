"""Machine files changed to the last number (issue 12): whatever numbers a file holds, it either
loads into a machine the controller runs, or is refused as ``FILE: KEY: what`` (MachineError):
by the machine description, or by the simulator for its plant (``hw.sim.check_plant``).

The property changes one to three numbers of a built-in file, to extremes (0, ±5e-324,
±1e300, inf and nan as TOML spells them, integers wider than a float and wider than int's
4300-digit limit) or to the file's own value scaled across twelve decades. A machine that
loads gets an in-process Controller on the lockstep simulator (built as in
tests/control/rt/test_loop.py): it holds, then drives every valve open one way and the other,
and no tick may raise, no command break, no plant state turn non-finite.

The CI-sized variant runs with the inner loop (CI replays it derandomized, tests/conftest.py);
the exhaustive one tries 10,000 files, about a minute, and is slow (tests/conftest.py's
SLOW_TESTS); under CI it replays 200, as the file parsers' deep variants do.
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from hypothesis import HealthCheck, event, example, given, settings
from hypothesis import strategies as st

from app.cli_machine import describe, summary
from control.motion.robot_model import model_of
from control.rt import shm
from control.rt.channel import client_end, controller_end
from control.rt.commands import Manual
from control.rt.events import Refused
from control.rt.layout import ControlLayout
from control.rt.loop import Controller, LoopConfig
from control.rt.seqlock import SeqlockWriter
from control.rt.wire import Wire
from hw.machine import Machine, MachineError, parse_machine
from hw.sim import SimBackend, check_plant

MACHINES = Path(__file__).resolve().parents[2] / "hw" / "machines"
TEXTS = {name: (MACHINES / f"{name}.toml").read_text(encoding="utf-8")
         for name in ("unimate2000b", "rig")}
STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')
NUMBER = re.compile(r"(?<![\w.])[-+]?\d[\d_]*(?:\.\d+)?(?:[eE][-+]?\d+)?(?![\w.])")
KEY = r"[a-z_]\w*(\[\d+\])*(\.[a-z_]\w*(\[\d+\])*)*"  # joints[0].plant.mass_kg, kp[0][1]
REFUSAL = re.compile(rf"fuzz-\w+\.toml: (line \d+|{KEY}): \S")
EXTREMES = ("0", "-0", "0.0", "-0.0", "1", "-1", "5e-324", "-5e-324", "1e-300", "-1e-300",
            "1e300", "-1e300", "1.7976931348623157e308", "inf", "+inf", "-inf", "nan", "+nan",
            "-nan", "9" * 400, "-" + "9" * 400, "0x" + "f" * 300, "9" * 5000)
HOLD_TICKS, DRIVE_TICKS = 100, 50  # hold, then each valve open each way
EXHAUSTIVE = 200 if os.environ.get("CI") else 10_000


def number_spans(text: str) -> list[tuple[int, int]]:
    """Where each number of the file's values is: not in a comment, a string or a key."""
    spans: list[tuple[int, int]] = []
    start = 0
    for line in text.splitlines(keepends=True):
        code = STRING.sub(lambda m: " " * len(m.group()), line).split("#")[0]
        spans += [(start + m.start(), start + m.end()) for m in NUMBER.finditer(code)]
        start += len(line)
    return spans


SPANS = {name: number_spans(text) for name, text in TEXTS.items()}


def number_for(original: str) -> st.SearchStrategy[str]:
    """TOML for a number in place of ``original``: an extreme, any float or integer, the
    original within a factor of two (mostly still in range), or scaled by up to 1e±6 and
    either sign (near the ends of ranges and past them)."""
    value = float(original.replace("_", ""))
    near = st.floats(0.5, 2.0).map(lambda factor: repr(value * factor))
    scaled = st.builds(lambda sign, decades, factor: repr(sign * value * factor * 10.0**decades),
                       st.sampled_from((1.0, -1.0)), st.integers(-6, 6), st.floats(0.5, 2.0))
    return st.one_of(st.sampled_from(EXTREMES), near, scaled,
                     st.floats(allow_nan=False, allow_infinity=False).map(repr),
                     st.integers(-(2**70), 2**70).map(str))


@st.composite
def mutated(draw: st.DrawFn) -> tuple[str, str]:
    """(built-in machine, its text with one to three numbers replaced)."""
    name = draw(st.sampled_from(sorted(TEXTS)))
    text, spans = TEXTS[name], SPANS[name]
    chosen = set(draw(st.lists(st.integers(0, len(spans) - 1), min_size=1, max_size=3)))
    for index in sorted(chosen, key=lambda i: -spans[i][0]):  # from the end: offsets hold
        start, stop = spans[index]
        text = text[:start] + draw(number_for(text[start:stop])) + text[stop:]
    return name, text


def edited(name: str, *edits: tuple[str, str]) -> tuple[str, str]:
    text = TEXTS[name]
    for old, new in edits:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return name, text


@contextmanager
def controller_on(machine: Machine) -> Iterator[tuple[Controller, SimBackend, Wire]]:
    """A Controller on the lockstep simulator with the client's coefficient sets written, as
    ControlClient and control.rt.process would set it up; every segment released after."""
    backend = SimBackend(machine, lockstep=True)
    layout = ControlLayout(machine.n_joints)
    segment = shm.create("fuzz", layout.size)
    ours, theirs = socket.socketpair()
    client = client_end(ours)
    controller: Controller | None = None
    try:
        layout.write_header(segment.buf)
        for which in ("hold", "track"):
            writer = SeqlockWriter(segment.buf, layout.coefficient_offset(which),
                                   layout.coefficients.struct)
            writer.write(*layout.coefficients.encode(machine.coefficients[which]))
            writer.release()
        never = 10**15  # the test is the client: it never beats and never goes away
        controller = Controller(machine, backend, controller_end(theirs), segment.buf,
                                LoopConfig(period_ns=round(machine.sample_time_s * 1e9),
                                           heartbeat_timeout_ns=never, orphan_timeout_ns=never))
        controller.start()
        yield controller, backend, client
    finally:
        if controller is not None:
            controller.release()
        shm.release(segment, unlink=True)
        client.close()


def tick(controller: Controller, backend: SimBackend, n: int) -> None:
    """``n`` ticks on the deadline grid; an exception in one fails the test (no fail-safe)."""
    period = controller.config.period_ns
    for _ in range(n):
        backend.clock.sleep_until(backend.clock.now_ns() + period)
        controller.deadline = backend.clock.now_ns()
        controller.tick(controller.deadline)


def broken_commands(client: Wire) -> list[str]:
    """Refusals that are an exception's text (``ZeroDivisionError: …``), not a reason."""
    broken = []
    while client.poll(0):
        event = client.recv().record
        if isinstance(event, Refused) and re.match(r"\w+(Error|Exception): ", event.reason):
            broken.append(event.reason)
    return broken


def described(machine: Machine) -> None:
    """What ``servodesk machine`` and the TUI do with a machine before any controller: its
    description, and its kinematic model (a DH table not of its form is a MachineError)."""
    assert describe(machine).startswith(machine.title)
    json.dumps(summary(machine))
    try:
        model_of(machine)
    except MachineError as exc:
        assert REFUSAL.match(str(exc)), str(exc)


def loads_and_runs(name: str, text: str) -> None:
    filename = f"fuzz-{name}.toml"
    try:
        machine = parse_machine(text, Path(filename))
        check_plant(machine)  # the simulator's numbers, judged as a SimBackend is built
    except MachineError as exc:
        message = str(exc)
        assert REFUSAL.match(message) and "\n" not in message, message
        event("refused")
        return
    event("loaded and ran")
    described(machine)
    with controller_on(machine) as (controller, backend, client):
        tick(controller, backend, HOLD_TICKS)
        for duty in (100.0, -100.0):
            controller.channel.deliver(Manual((duty,) * machine.n_joints))
            tick(controller, backend, DRIVE_TICKS)
        assert broken_commands(client) == []
        for a in backend.plant.actuators:
            state = (a.q, a.v, a.pa, a.pb, a.spool)
            assert all(map(math.isfinite, state)), state
        assert all(map(math.isfinite, controller.encoders.position)), controller.encoders.position


# What a hostile tester found (issue 12): each must be refused naming its key.
REPORTED = [
    edited("unimate2000b", ("period_us = 325.0", "period_us = 1e-300")),
    edited("unimate2000b", ("gradient = -0.2617", "gradient = -5e-324")),
    edited("unimate2000b", ("mass_kg = 60.0", "mass_kg = 1e-300")),
    edited("unimate2000b", ("settle_ms = 6.0", "settle_ms = 1e300")),
    edited("unimate2000b", ("limits = [976.0, 2041.0]", "limits = [-1e308, 1e308]"),
           ("bits = 13", "bits = 1")),
    edited("rig", ("sample_time_ms = 1.0", "sample_time_ms = 1" + "0" * 400)),
]


def with_examples(test: Callable[..., None]) -> Callable[..., None]:
    for case in REPORTED:
        test = example(case=case)(test)
    return test


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@with_examples
@given(case=mutated())
def test_a_changed_machine_file_loads_and_runs_or_names_its_key(case: tuple[str, str]) -> None:
    loads_and_runs(*case)


@settings(max_examples=EXHAUSTIVE, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=mutated())
def test_ten_thousand_changed_machine_files_load_and_run_or_name_their_key(
        case: tuple[str, str]) -> None:
    loads_and_runs(*case)
