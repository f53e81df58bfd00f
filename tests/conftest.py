"""Suite-wide settings, what each test costs, the I/O board emulator every serial test starts,
and the files that are no machine description (the loader, the CLI and the client refuse them).

Under CI, hypothesis replays a fixed set of examples. Locally every run explores
new examples (that is how the bugs in docs/errata.md and the fault suite were
found); in CI a run must not fail on an example no one has seen, so ``CI=true``
selects a derandomized profile. The deep variants of the file-parser properties
(tests/faults/test_bad_input.py, ``deep_fuzz``: 10,000 examples each locally) and
of the machine-file property (tests/hw/test_machine_fuzz.py) replay only 200
there, to keep CI short.

Cost: a test that starts a process (the control subprocess through
``ControlClient``, the emulator, a CLI, tmux) or the TUI, or that takes seconds
without one (a file at its size bound, a deep fuzz), is marked ``slow`` here,
centrally (``pytest_collection_modifyitems``), so that ``pytest -m "not slow" -n 2``
is the inner loop. Every other test is watched: one that starts a process
anyway fails at teardown, naming what it started and where to mark it.
"""

from __future__ import annotations

import contextlib
import gc
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
EMULATOR_START_S = 60.0

# Bytecode is written, as Python does unless asked not to. Where the environment asks not to
# (PYTHONDONTWRITEBYTECODE, as this machine's does), every one of the suite's few hundred
# processes (controllers, CLIs, services, emulators) compiled the project's modules from source
# again (0.07 s of CPU a controller, 0.13 s the app), and pytest rewrote every test module on
# every run. git ignores __pycache__. Set before xdist starts its workers, which inherit it.
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False


def pytest_configure(config: pytest.Config) -> None:
    """The hypothesis profile, where tests run: not in xdist's controller, which runs none
    and waited 0.3 s for hypothesis before starting its workers."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        return
    from hypothesis import settings

    settings.register_profile("ci", derandomize=True, deadline=None)
    if os.environ.get("CI"):
        settings.load_profile("ci")


# -- cost: the slow marker -------------------------------------------------------------------

# Folders and modules where every test starts a process or the TUI.
SLOW_PATHS = (
    "tests/faults/",                   # real controllers and emulators, faults injected
    "tests/app/test_smoke_tmux.py",    # the app in a tmux session
    "tests/app/test_typing_tmux.py",   # the app in a tmux session, typed into fast
    "tests/app/test_typing_pilot.py",  # the TUI under Pilot, every Moves form typed into
    "tests/app/test_cli_move.py",      # servodesk move: a controller (and an emulator) each
    "tests/app/test_cli_runs.py",      # servodesk runs in subprocesses
    "tests/app/test_cli_plot.py",      # servodesk move --plot and runs show --plot in subprocesses
    "tests/app/test_cli_program.py",   # servodesk run PROGRAM in subprocesses
    "tests/control/program/test_runner.py",  # programs run on the control subprocess
    "tests/control/test_client.py",    # the control subprocess, for real
    "tests/control/test_launcher.py",  # control processes forked by their server
    "tests/control/test_timing.py",    # the thesis's timing on the control subprocess
    "tests/control/test_settle_and_rest.py",  # fast moves and rest on both machines
    "tests/control/test_two_khz.py",   # both machines at a 500 µs period
    "tests/control/identify/test_proposal_settles.py",  # identify, apply, move: both machines
    "tests/control/test_feed.py",      # feed override and hold on the control subprocess
    "tests/control/test_speed_mode.py",  # reduced speed (T1) on the control subprocess
    "tests/control/test_client_cartesian_jog.py",  # Cartesian jogs on it
    "tests/control/test_servo.py",     # the Cartesian servo on a real-time one
    "tests/control/rt/test_process.py",   # the control subprocess's imports
    "tests/control/test_service.py",   # servodesk controller and clients attached to it
    "tests/control/test_service_trust.py",  # the same, tried as an attacker would
    "tests/control/test_run_keeper.py",  # a 600 s run saved beside a real controller
    "tests/app/test_tui_attach.py",    # TUIs attached to servodesk controller
    "tests/app/test_tui_observer_files.py",  # and what their observers may not change
    "tests/app/test_serve.py",         # servodesk serve in a headless Chromium
)
# Fixtures that start one, with the file that defines them (they are visible in its folder
# when it is a conftest.py, in that file alone otherwise).
SLOW_FIXTURES = {
    "emulator": "tests/conftest.py",                   # servodesk emulate
    "controller_service": "tests/conftest.py",         # servodesk controller
    "controller": "tests/faults/conftest.py",          # ControlClient
    "tui": "tests/app/conftest.py",                    # the TUI under Pilot, and its controller
    "lockstep": "tests/control/conftest.py",           # ControlClient, lockstep
    "realtime": "tests/control/conftest.py",           # ControlClient, real time
    "runs": "tests/control/identify/test_sysid.py",    # ControlClient's excitation runs
    "robot": "tests/control/identify/test_tuning.py",  # ControlClient
}
# Single tests that start one in their body, or that take seconds without one.
SLOW_TESTS = (
    # the app in a fresh interpreter, and servodesk in tmux
    "tests/app/test_ui_cost.py::test_servodesk_starts_its_controller_before_it_imports_the_screen",
    "tests/app/test_arm_view.py::test_an_idle_view_draws_once_and_a_new_pose_draws_again",  # Pilot
    "tests/app/test_arm_view.py::test_the_full_view_works_in_the_browser",  # serve, Chromium
    "tests/control/rt/test_seqlock.py::test_reader_never_sees_a_torn_record",  # spawned writer
    "tests/control/rt/test_realtime.py::test_a_claim_ends_with_its_process",  # a claim's holder
    "tests/control/rt/test_realtime.py::test_two_controllers_run_on_two_cores",
    "tests/control/rt/test_realtime.py::test_a_controller_on_a_shared_core_runs_no_warm_up_"
    "and_says_so",
    "tests/control/rt/test_realtime.py::test_a_clients_threads_keep_off_its_real_time_"
    "controllers_core",
    "tests/control/rt/test_shm.py::test_orphan_of_a_killed_process_is_cleaned_up",
    "tests/control/test_boundaries_host.py::test_a_link_another_user_left_in_dev_shm_stops_no_"
    "start",  # a start's clean-up as another user (setpriv)
    "tests/control/test_boundaries_host.py::test_segment_names_another_user_made_first_stop_no_"
    "start",  # a controller started beside names made first
    "tests/control/test_recorder.py::test_a_read_only_directory_raises_and_leaves_nothing",
    "tests/app/test_priority.py::"
    "test_without_the_privilege_the_ui_says_so_and_runs_at_its_own_priority",  # under setpriv
    "tests/control/motion/test_positions.py::"
    "test_a_writer_killed_between_temporary_and_rename_leaves_the_old_file",  # a killed writer
    # files at their size bound: 600,001 points parsed, 2-4 s each
    "tests/control/motion/test_path_files.py::test_a_path_file_at_its_bound_loads",
    "tests/control/motion/test_cartesian.py::test_a_pose_file_at_its_bound_is_read",
    # 10,000 hypothesis examples each, about a minute (slow under tests/faults/ already; listed
    # for their own cost, should the file-parser properties ever leave that folder)
    "tests/faults/test_bad_input.py::test_tsv_path_files_deeply",
    "tests/faults/test_bad_input.py::test_csv_path_files_deeply",
    "tests/faults/test_bad_input.py::test_pose_files_deeply",
    # a run's tables against the old writer's, 100 random runs; saved runs played as paths
    "tests/control/test_recorder.py::test_the_tables_are_the_old_writers_byte_for_byte",
    "tests/control/test_recorder.py::test_what_is_written_loads_back_and_plays_as_a_path",
    # 1,000 Cartesian jogs planned and checked sample by sample, about 10 s
    "tests/control/motion/test_cartesian_jog.py::"
    "test_random_jogs_keep_the_branch_and_the_line_or_are_refused_with_a_reason",
    # half a second or more each on a quiet machine (pytest --durations): out of the inner loop
    "tests/hw/serial/test_frame.py::"
    "test_a_damaged_stream_delivers_only_what_was_sent_and_every_intact_frame",
    "tests/control/rt/test_jog.py::test_the_target_never_jumps_and_stops_on_the_goal",
    "tests/hw/test_machine.py::test_any_corruption_gives_a_machine_error_or_a_valid_machine",
    "tests/hw/sim/test_encoders.py::test_thesis_timing_gives_figure_6_1",
    "tests/hw/test_machine_fuzz.py::test_a_changed_machine_file_loads_and_runs_or_names_its_key",
    "tests/hw/sim/test_plant.py::test_full_duty_speed_is_what_the_plant_reaches",
    "tests/control/motion/test_acceptance.py::"
    "test_a_move_longer_than_the_move_limit_is_refused_approach_and_all",
    # every module's classes parsed for the names the docs cite (the first doc pays: 0.8 s)
    "tests/test_docs.py::test_every_name_a_doc_cites_exists",
    "tests/test_docs.py::test_the_check_finds_what_is_not_there",
    # 4,500 lockstep ticks with and without the warm-up, 0.8 s
    "tests/control/test_warm_up.py::test_the_live_loop_is_bit_for_bit_the_same_with_the_warm_up",
    # 10,000 machine files changed and run on a controller, about a minute
    "tests/hw/test_machine_fuzz.py::"
    "test_ten_thousand_changed_machine_files_load_and_run_or_name_their_key",
)
# Parallel runs (pytest-xdist, ``-n 2 --dist loadgroup``: README's test command). Tests that
# load the machine on purpose (burners of their own, twenty browser sessions, a starved
# controller), that measure it, or that run the I/O board emulator (at SCHED_FIFO, with its
# 50 ms watchdog) run on one worker, one after another, so no two of them ever overlap; the
# other worker runs the rest beside them, as a sequential suite runs beside a burner. The
# tests of a module that share a module-scoped fixture (one controller for the module) run
# on one worker too, so that it is set up once.
ONE_AT_A_TIME_FIXTURES = frozenset({"emulator"})
ONE_AT_A_TIME = (
    "tests/faults/test_cpu_starvation.py",   # every core burning
    "tests/faults/test_stale_words.py::test_resets_after_watchdog_trips_hold_where_the_arm_is_"
    "beside_a_cpu_burner",
    "tests/faults/test_serial_link.py::test_losing_a_tcp_link_does_not_stall_the_loop",
    "tests/app/test_tui_heartbeat.py",       # every tab opened beside a burner, 250 ms heartbeat
    "tests/app/test_serve.py",               # headless Chromium, twenty sessions beside a burner
    "tests/app/test_smoke_tmux.py",          # the app in tmux
    "tests/app/test_typing_tmux.py",         # the app in tmux, keys 5 ms apart
    "tests/control/test_run_keeper.py",      # an E-stop's delivery timed while a run saves
)
# Audit events (PEP 578) of a process start. A multiprocessing "spawn" start raises none
# (CPython 3.11): such a test must be listed above by hand, as test_seqlock's is. A controller
# forked by the fork server (control/launcher.py) is said by the launcher's own event.
PROCESS_EVENTS = frozenset({"subprocess.Popen", "os.fork", "os.forkpty", "os.posix_spawn",
                            "os.spawn", "os.system", "os.exec", "control.launch"})


def _starts_processes(item: pytest.Item) -> bool:
    path = item.path.relative_to(ROOT).as_posix()
    if path.startswith(SLOW_PATHS) or item.nodeid.split("[")[0] in SLOW_TESTS:
        return True
    for name in set(getattr(item, "fixturenames", ())) & SLOW_FIXTURES.keys():
        defined = SLOW_FIXTURES[name]
        scope = defined.removesuffix("conftest.py") if defined.endswith("conftest.py") else defined
        if path.startswith(scope):
            return True
    return False


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's, which reads the groups
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if _starts_processes(item):
            item.add_marker(pytest.mark.slow)
        if (item.nodeid.startswith(ONE_AT_A_TIME)
                or ONE_AT_A_TIME_FIXTURES & set(getattr(item, "fixturenames", ()))):
            item.add_marker(pytest.mark.xdist_group("one_at_a_time"))
        elif _shares_a_module_fixture(item):
            item.add_marker(pytest.mark.xdist_group(item.path.relative_to(ROOT).as_posix()))


def pytest_collection_finish(session: pytest.Session) -> None:
    """Move what collection built (every module imported, every item) to the collector's
    permanent generation: it lives to the end, and each full collection during the run
    scanned all of it again."""
    gc.freeze()


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """Under ``-m "not slow"`` (the inner loop) the folders and modules of ``SLOW_PATHS`` are
    not collected: every test in them would be deselected, and importing them cost each
    worker 0.46 s (a collection error there shows in the full suite)."""
    if config.getoption("markexpr", "").strip() != "not slow":
        return None
    if not collection_path.is_relative_to(ROOT):
        return None
    path = collection_path.relative_to(ROOT).as_posix()
    return True if f"{path}/".startswith(SLOW_PATHS) else None  # a folder's path, or a module's


def _shares_a_module_fixture(item: pytest.Item) -> bool:
    """Whether ``item`` uses a fixture set up once for its module (or package)."""
    definitions = getattr(getattr(item, "_fixtureinfo", None), "name2fixturedefs", {})
    return any(defs[-1].scope in ("module", "package") for defs in definitions.values())


class ProcessWatch:
    """The process starts seen while a test not marked slow runs (an audit hook, PEP 578)."""

    def __init__(self) -> None:
        self.watching = False
        self.started: list[str] = []

    def __call__(self, event: str, args: tuple[Any, ...]) -> None:
        if self.watching and event in PROCESS_EVENTS:
            self.started.append(f"{event} {args!r:.160}")


WATCH = ProcessWatch()
sys.addaudithook(WATCH)


@pytest.fixture(autouse=True)
def _says_its_cost(request: pytest.FixtureRequest) -> Iterator[None]:
    """Fail a test that starts a process without being marked slow."""
    if request.node.get_closest_marker("slow"):
        yield
        return
    WATCH.started.clear()
    WATCH.watching = True
    try:
        yield
    finally:
        WATCH.watching = False
    if WATCH.started:
        pytest.fail(f"{request.node.nodeid} started a process but is not marked slow: "
                    f"{'; '.join(WATCH.started)}. Add it to tests/conftest.py's SLOW_PATHS, "
                    "SLOW_FIXTURES or SLOW_TESTS, so that `pytest -m \"not slow\"` stays fast",
                    pytrace=False)


# -- the controllers' wake-up: slept, not spun, unless timing is tested -----------------------

# A real-time controller spins the last 150 µs before each deadline and ticks its warm-up's
# shadow in the last 30 % of each period (control/rt/warmup.py): at rest it uses 35 % of a core,
# 12.6 % with neither (`SERVODESK_SPIN=0 SERVODESK_WARM_UP=0`). Most tests check what the
# controller does, not how punctually it wakes; these check the timing, and run it as shipped.
TIMED = (
    "tests/control/test_timing.py",
    "tests/control/test_two_khz.py",
    "tests/control/test_warm_up.py",
    "tests/faults/test_cpu_starvation.py",
    "tests/faults/test_controller_freeze.py",
    "tests/app/test_tui_log.py",
)
SLEPT = {"SERVODESK_SPIN": "0", "SERVODESK_WARM_UP": "0"}


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Every controller a test starts (its own, a service's, a CLI's; its module's shared
    one, set up after this) sleeps to each deadline, without spin or warm-up, unless its
    module is in ``TIMED``. A hook, not a fixture: a module-scoped one would put every
    module in an xdist group of its own (``_shares_a_module_fixture``)."""
    timed = item.path.relative_to(ROOT).as_posix() in TIMED
    for name, value in SLEPT.items():
        if timed:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


# -- the I/O board emulator -------------------------------------------------------------------


class EmulatorProcess:
    """``servodesk emulate ARGS`` in a child process; ``url`` is the first line it prints."""

    def __init__(self, args: Sequence[str], log: Path) -> None:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        self.log = log
        with log.open("wb") as err:
            self.proc = subprocess.Popen([sys.executable, "-m", "app", "emulate", *args],
                                         cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=err)
        assert self.proc.stdout is not None
        ready = select.select([self.proc.stdout], [], [], EMULATOR_START_S)[0]
        self.url = self.proc.stdout.readline().decode().strip() if ready else ""
        if not self.url:
            self.kill()
            raise RuntimeError(f"the emulator did not start: {log.read_text()}")
        self._realtime()

    @property
    def pid(self) -> int:
        return self.proc.pid

    def _realtime(self) -> None:
        """Below the controller's SCHED_FIFO 80 but above the test and its helpers, where allowed.

        The emulator stands in for a microcontroller that never stalls; at normal
        priority on a loaded two-core machine it can pause past the 50 ms
        watchdog, which would test the VM's scheduler, not servodesk.
        """
        with contextlib.suppress(OSError):
            os.sched_setscheduler(self.pid, os.SCHED_FIFO, os.sched_param(70))

    def send(self, sig: int) -> None:
        self.proc.send_signal(sig)

    def stop(self) -> dict[str, object]:
        """SIGTERM, then the JSON summary of its counts it prints on the way out."""
        self.proc.send_signal(signal.SIGTERM)
        out, _ = self.proc.communicate(timeout=30)
        assert self.proc.returncode == 0, self.log.read_text()
        return json.loads(out.decode().strip().splitlines()[-1])

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(timeout=30)
        if self.proc.stdout is not None:
            self.proc.stdout.close()


@pytest.fixture
def emulator(tmp_path: Path) -> Iterator[Callable[..., EmulatorProcess]]:
    """Start emulators: ``emulator("--glitch-scale", "0")``; all are killed at teardown."""
    started: list[EmulatorProcess] = []

    def start(*args: str) -> EmulatorProcess:
        started.append(EmulatorProcess(args, tmp_path / f"emulator{len(started)}.log"))
        return started[-1]

    yield start
    for process in started:
        process.kill()


# -- the controller as a service -------------------------------------------------------------

SERVICE_START_S = 60.0


class ServiceProcess:
    """``servodesk controller`` in a private runtime directory (short: a socket's path has at
    most 107 bytes), saving runs in ``data_dir``; ``socket`` appears when it is ready."""

    def __init__(self, tmp_path: Path, *args: str, socket: Path | None = None) -> None:
        self.runtime = Path(tempfile.mkdtemp(prefix="sd-"))
        self.socket = socket or self.runtime / "servodesk" / "controller.sock"
        if socket is not None:
            args = (*args, "--socket", str(socket))
        self.data_dir = tmp_path / "runs"
        self.log = tmp_path / ("controller.log" if socket is None else f"{socket.name}.log")
        env = {**os.environ, "PYTHONPATH": str(ROOT), "XDG_RUNTIME_DIR": str(self.runtime)}
        with self.log.open("wb") as err:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "app", "controller", "--data-dir", str(self.data_dir),
                 *args], cwd=ROOT, env=env, stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=err)
        self.started_s = self.wait_ready()

    def wait_ready(self) -> float:
        """Wait for the socket (not for a time); how long it took."""
        start = time.monotonic()
        while not self.socket.exists():
            if self.proc.poll() is not None or time.monotonic() - start > SERVICE_START_S:
                self.kill()
                raise RuntimeError(f"servodesk controller did not start: {self.log.read_text()}")
            time.sleep(0.01)
        return time.monotonic() - start

    def stop(self) -> int:
        """SIGTERM; its exit code."""
        self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(timeout=30)
        finally:
            self.kill()

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=30)
        shutil.rmtree(self.runtime, ignore_errors=True)


@pytest.fixture
def controller_service(tmp_path: Path) -> Iterator[ServiceProcess]:
    """A running ``servodesk controller`` (a 2 s heartbeat allowance: a loaded two-core
    machine can pause a client's heartbeat thread); stopped at teardown."""
    service = ServiceProcess(tmp_path, "--heartbeat-timeout", "2", "--release-after", "3")
    yield service
    service.kill()


# -- files that are no machine description ---------------------------------------------------

MACHINE_BYTES = (ROOT / "hw" / "machines" / "unimate2000b.toml").read_bytes()


def _written(tmp_path: Path, name: str, data: bytes) -> Path:
    (tmp_path / name).write_bytes(data)
    return tmp_path / name


def _edited(tmp_path: Path, name: str, old: bytes, new: bytes) -> Path:
    assert MACHINE_BYTES.count(old) == 1, old
    return _written(tmp_path, name, MACHINE_BYTES.replace(old, new))


def _directory(tmp_path: Path) -> Path:
    (tmp_path / "machines.toml").mkdir()
    return tmp_path / "machines.toml"


def _fifo(tmp_path: Path) -> Path:
    os.mkfifo(tmp_path / "fifo.toml")  # opened for reading, it would wait for a writer
    return tmp_path / "fifo.toml"


SAMPLE = b"sample_time_ms = 1.0"
TITLE = b'"Unimate 2000B six-axis hydraulic robot"'
# What a hostile tester gave for a machine file (issue 12): how to make it, and the error it
# must be refused with (a regex searched in the one line; the CLI puts "servodesk: " first).
NOT_MACHINES: dict[str, tuple[Callable[[Path], Path], str]] = {
    "not-utf8": (lambda d: _edited(d, "latin1.toml", TITLE, b'"Unimate 2000B \xe9"'),
                 r"latin1\.toml: line 7: byte 0xe9 is not UTF-8 text: save the file as UTF-8"),
    "directory": (_directory, r"machines\.toml: is a directory"),
    "fifo": (_fifo, r"fifo\.toml: not a regular file"),
    "io-error": (lambda d: Path("/proc/self/mem"),  # reading it fails, even for root
                 r"^/proc/self/mem: cannot read it: Input/output error$"),
    "missing": (lambda d: d / "nope.toml", r"nope\.toml: no such machine file"),
    "over-1MB": (lambda d: _written(d, "big.toml", MACHINE_BYTES + b"#" * (1 << 20) + b"\n"),
                 r"big\.toml: larger than 1024 kB"),
    "nested-5000-deep": (lambda d: _edited(d, "deep.toml", SAMPLE,
                                           b"sample_time_ms = " + b"[" * 5000 + b"]" * 5000),
                         r"^deep\.toml: arrays or tables nested too deeply"),
    "int-of-5000-digits": (lambda d: _edited(d, "long.toml", SAMPLE,
                                             b"sample_time_ms = " + b"9" * 5000),
                           r"^long\.toml: line 8: an integer of thousands of digits"),
    "int-wider-than-a-float": (lambda d: _edited(d, "wide.toml", SAMPLE,
                                                 b"sample_time_ms = 1" + b"0" * 400),
                               r"^wide\.toml: machine\.sample_time_ms: <an integer of 1329 "
                               r"bits> is larger than any machine value"),
    "escape-in-title": (lambda d: _edited(d, "title.toml", TITLE, b'"Unimate\\u001b[2J"'),
                        r"^title\.toml: machine\.title: 'Unimate\\x1b\[2J': character 7 is "
                        r"'\\x1b', which does not print"),
    "escape-in-path": (lambda d: _written(d, "bad\x1b[2J.toml", MACHINE_BYTES),
                       r"^'.*/bad\\x1b\[2J\.toml': a machine file's path must print as text"),
}


@pytest.fixture(params=sorted(NOT_MACHINES))
def not_a_machine(request: pytest.FixtureRequest, tmp_path: Path) -> tuple[Path, str]:
    """A file that is no machine description, and the regex its refusal must match."""
    make, message = NOT_MACHINES[request.param]
    return make(tmp_path), message
