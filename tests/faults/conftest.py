"""The fault-injection suite's shared pieces: real controllers, real emulators, measured figures.

Every case here runs the real control subprocess (``ControlClient``), and the
serial cases the real I/O board emulator (``servodesk emulate``) in another
process over a pty or TCP. Timing claims (a death reported within 250 ms, the
board's watchdog within 50 ms…) are *measured and recorded*, not asserted
tightly: the machine is a shared two-core VM, so assertions use generous
bounds and the figures go to the terminal summary and, when the environment
variable ``SERVODESK_FAULT_REPORT`` names a file, to a JSON report that
``benchmarks/run_all.py`` turns into the README's Reliability section.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import pytest

from control import ControlClient
from control.rt import shm

REPORT_ENV = "SERVODESK_FAULT_REPORT"
CASE_KEY = "servodesk_fault_case"  # a test report's user property: its CaseRecord as a dict


@dataclass
class CaseRecord:
    """What one test proved and measured: filled by the ``measured`` fixture and the hooks."""

    nodeid: str
    doc: str = ""
    outcome: str = ""
    reason: str = ""
    duration_s: float = 0.0
    figures: dict[str, tuple[float, str]] = field(default_factory=dict)
    examples: int = 0


CASES: dict[str, CaseRecord] = {}


def _record(nodeid: str) -> CaseRecord:
    return CASES.setdefault(nodeid, CaseRecord(nodeid))


class Figures:
    """Measured figures of the running test: printed, and kept for the report."""

    def __init__(self, nodeid: str) -> None:
        self.record = _record(nodeid)

    def __call__(self, name: str, value: float, unit: str = "") -> float:
        self.record.figures[name] = (float(value), unit)
        print(f"{name}: {value:g}{(' ' + unit) if unit else ''}")
        return value

    def example(self) -> None:
        """Count one property-based example tried (hypothesis calls the test once each)."""
        self.record.examples += 1


@pytest.fixture
def measured(request: pytest.FixtureRequest) -> Figures:
    """Record a measured figure: ``measured("client_told_ms", 12.0, "ms")``."""
    return Figures(request.node.nodeid)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    outcome = yield
    report = outcome.get_result()
    record = _record(item.nodeid)
    function = getattr(item, "function", None)
    record.doc = " ".join((getattr(function, "__doc__", None) or "").split())
    if hasattr(report, "wasxfail"):
        record.outcome, record.reason = "xfailed", report.wasxfail
    elif report.when == "call" or report.outcome != "passed":
        record.outcome = (report.outcome if report.when == "call"
                          else f"{report.when} {report.outcome}")
    if report.when == "call":
        record.duration_s = report.duration
    report.user_properties.append((CASE_KEY, asdict(record)))


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Under pytest-xdist the cases run in workers: their records come back with each report,
    for the summary and the report the main process writes."""
    for key, value in report.user_properties:
        if key == CASE_KEY:
            record = _record(report.nodeid)  # the same record when the test ran here
            for name, item in value.items():
                setattr(record, name, item)
            record.figures = {name: tuple(figure) for name, figure in value["figures"].items()}


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    measured_cases = [r for r in CASES.values() if r.figures or r.examples]
    if not measured_cases:
        return
    terminalreporter.section("fault suite: measured figures")
    for record in measured_cases:
        parts = [f"{name} {value:g}{(' ' + unit) if unit else ''}"
                 for name, (value, unit) in record.figures.items()]
        if record.examples:
            parts.append(f"{record.examples} examples")
        terminalreporter.write_line(f"{record.nodeid.split('::', 1)[-1]}: {', '.join(parts)}")


def pytest_sessionfinish(session: pytest.Session) -> None:
    path = os.environ.get(REPORT_ENV)
    if not path or not CASES or os.environ.get("PYTEST_XDIST_WORKER"):
        return
    doc = {nodeid: {"doc": r.doc, "outcome": r.outcome, "reason": r.reason,
                    "duration_s": r.duration_s,
                    "figures": {k: list(v) for k, v in r.figures.items()},
                    "examples": r.examples}
           for nodeid, r in CASES.items()}
    Path(path).write_text(json.dumps(doc, indent=2, ensure_ascii=False) + "\n")


# -- waiting ------------------------------------------------------------------------------


def wait_for(predicate: Callable[[], bool], timeout: float, what: str | Callable[[], str],
             every: float = 0.002) -> float:
    """Poll ``predicate`` until true; return the seconds it took, fail after ``timeout``
    naming ``what`` (or what it returns then: the state that explains the wait)."""
    start = time.monotonic()
    while (elapsed := time.monotonic() - start) < timeout:
        if predicate():
            return elapsed
        time.sleep(every)
    raise AssertionError(f"timed out after {timeout:g} s waiting for "
                         f"{what() if callable(what) else what}")


@pytest.fixture
def until() -> Callable[..., float]:
    """``until(predicate, timeout, what)``: seconds until ``predicate()`` held."""
    return wait_for


def segments_of(pid: int) -> list[str]:
    """Servodesk shared-memory segments created by process ``pid`` still in /dev/shm."""
    return [n for n in shm.leftover_segments() if shm.owner_pid(n) == pid]


@pytest.fixture
def leftovers() -> Callable[[int], list[str]]:
    """``leftovers(pid)``: the ``sd_<pid>_*`` segments still present."""
    return segments_of


# -- controllers ---------------------------------------------------------------------------


@pytest.fixture
def controller(tmp_path: Path) -> Iterator[Callable[..., ControlClient]]:
    """Start real controllers (``ControlClient``) saving under ``tmp_path/runs``.

    Every client is closed at teardown, and then no segment this test made may remain in
    /dev/shm: every exit path unlinks its shared memory (one left by an earlier test of the
    worker fails that test alone).
    """
    before = set(segments_of(os.getpid()))
    clients: list[ControlClient] = []

    def start(machine: str = "unimate2000b", **options: object) -> ControlClient:
        options.setdefault("data_dir", tmp_path / "runs")
        if options.get("lockstep"):
            options.setdefault("heartbeat_timeout_s", 3.0)  # a flat-out simulator starves us
        clients.append(ControlClient(machine, **options))
        return clients[-1]

    yield start
    for client in clients:
        client.close()
    assert sorted(set(segments_of(os.getpid())) - before) == []
