"""Controllers for the tests of this folder: the control subprocess on the simulated Unimate,
in lockstep (as fast as it computes) or in real time; each must leave no segment behind."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from control import ControlClient
from control.rt import shm


def leftover_segments_of(pid: int) -> list[str]:
    return [n for n in shm.leftover_segments() if shm.owner_pid(n) == pid]


@pytest.fixture
def new_segments() -> Callable[[], list[str]]:
    """This process's segments made since the test began: a segment one test leaves fails
    that test alone (it failed every later test of its worker: 77 errors from one, at load
    9, the one being left by a test that failed otherwise)."""
    pid = os.getpid()
    before = set(leftover_segments_of(pid))
    return lambda: sorted(set(leftover_segments_of(pid)) - before)


@pytest.fixture
def lockstep(tmp_path: Path, new_segments: Callable[[], list[str]]) -> Iterator[ControlClient]:
    # A lockstep controller computes flat out on one core; on a loaded 2-core machine the
    # test's heartbeat thread can be starved for 250 ms. These tests are not about
    # heartbeats (the real-time ones are), so the client may stay silent longer.
    client = ControlClient("unimate2000b", lockstep=True, data_dir=tmp_path,
                           heartbeat_timeout_s=3.0)
    yield client
    client.close()
    assert new_segments() == []


@pytest.fixture
def realtime(tmp_path: Path, new_segments: Callable[[], list[str]]) -> Iterator[ControlClient]:
    client = ControlClient("unimate2000b", data_dir=tmp_path)
    yield client
    client.close()
    assert new_segments() == []
