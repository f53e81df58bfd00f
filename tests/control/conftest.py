"""Controllers for the tests of this folder: the control subprocess on the simulated Unimate,
in lockstep (as fast as it computes) or in real time; each must leave no segment behind."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from control import ControlClient
from control.rt import shm


def leftover_segments_of(pid: int) -> list[str]:
    return [n for n in shm.leftover_segments() if shm.owner_pid(n) == pid]


@pytest.fixture
def lockstep(tmp_path: Path) -> Iterator[ControlClient]:
    # A lockstep controller computes flat out on one core; on a loaded 2-core machine the
    # test's heartbeat thread can be starved for 250 ms. These tests are not about
    # heartbeats (the real-time ones are), so the client may stay silent longer.
    client = ControlClient("unimate2000b", lockstep=True, data_dir=tmp_path,
                           heartbeat_timeout_s=3.0)
    yield client
    client.close()
    assert leftover_segments_of(os.getpid()) == []


@pytest.fixture
def realtime(tmp_path: Path) -> Iterator[ControlClient]:
    client = ControlClient("unimate2000b", data_dir=tmp_path)
    yield client
    client.close()
    assert leftover_segments_of(os.getpid()) == []
