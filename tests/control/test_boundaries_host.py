"""What another local user can put where servodesk looks for its own files and names: the
controller service's socket directory and key, and /dev/shm. Each test plays that user with
real files it owns (made here as root and given to ``nobody``) or a real process run as it
(``setpriv``), and a real socket."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from control import rendezvous
from control.client import ControlClient, ControllerError
from control.rt import shm
from control.rt.wire import Broken, Wire
from tests.conftest import ROOT

ATTACKER = 65534  # nobody
VICTIM = 65533  # a user of servodesk who is not root (one who is may unlink anything)
PAST_PID_MAX = 4_194_305  # no process ever has this pid (pid_max is at most 2**22)

as_root = pytest.mark.skipif(os.geteuid() != 0 or shutil.which("setpriv") is None,
                             reason="plays two users: needs root and setpriv (util-linux)")


@pytest.fixture
def attackers_dir() -> Iterator[Path]:
    """A directory another user made and owns, not writable by others (0755): one they made
    at /tmp/servodesk-<uid> before this user's first ``servodesk controller``."""
    made = Path(tempfile.mkdtemp(prefix="sd-"))  # short: a socket's path has at most 107 bytes
    made.chmod(0o755)
    os.chown(made, ATTACKER, ATTACKER)
    yield made
    shutil.rmtree(made, ignore_errors=True)


@as_root
def test_a_service_whose_key_another_user_wrote_is_not_attached_to(attackers_dir: Path) -> None:
    """The other user's fake service, with a key they wrote (0644) beside it: before, the
    client read that key, both sides proved they held it, and the client joined the fake
    service (which would then get its commands, the E-stop's included, and show it any arm it
    likes). Now the key is refused (not this user's), and nothing reaches the fake service."""
    path = attackers_dir / "controller.sock"
    key = b"k" * 32
    rendezvous.key_path(path).write_bytes(key)
    os.chown(rendezvous.key_path(path), ATTACKER, ATTACKER)
    heard: list[str] = []
    with socket.socket(socket.AF_UNIX) as fake:
        fake.bind(str(path))
        os.chown(path, ATTACKER, ATTACKER)
        fake.listen(1)
        fake.settimeout(10)
        serving = threading.Thread(target=serve_fake, args=(fake, key, heard), daemon=True)
        serving.start()
        with pytest.raises(ControllerError, match="is not a key file of this user's"):
            ControlClient.attach(path, name="operator", timeout_s=3)
        with socket.socket(socket.AF_UNIX) as last:  # the fake service's last caller: a probe
            last.connect(str(path))
            serving.join(10)
    assert heard == ["no handshake"], heard


def serve_fake(listener: socket.socket, key: bytes, heard: list[str]) -> None:
    """The other user's service: it takes one connection, proves it holds ``key`` and notes
    the client's join; a connection that does not answer the handshake is noted too."""
    connection, _ = listener.accept()
    with connection:
        wire = Wire(connection, rendezvous.CODEC, rendezvous.REQUEST_LIMIT, frame_s=1.0)
        deadline = time.monotonic() + 1.0
        try:
            rendezvous.authenticate(wire, key, deadline, serving=True)
            join = rendezvous.receive(wire, rendezvous.Join, deadline, "join")
        except (Broken, TimeoutError, PermissionError):
            heard.append("no handshake")
            return
        heard.append(f"joined by {join.name}")


@as_root
def test_a_socket_directory_another_user_owns_is_refused(attackers_dir: Path) -> None:
    """Before, one they made but others may not write in was taken: its owner may still replace
    the socket and its key at will."""
    with pytest.raises(PermissionError, match=f"belongs to another user \\(uid {ATTACKER}\\)"):
        rendezvous.socket_dir(attackers_dir)


@as_root
def test_a_link_another_user_left_in_dev_shm_stops_no_start() -> None:
    """Their symbolic link named as a dead servodesk's segment, pointing at ``/proc/self``
    (which is whoever looks's own): the start's clean-up (``shm.cleanup_orphans``, which every
    controller's start runs) took it for the starting user's and unlinked it, which the sticky
    /dev/shm refuses: PermissionError ended every start of a user who is not root. Now it is
    another user's, left alone with a notice."""
    link = shm.SHM_DIR / shm.segment_name("ctl1", PAST_PID_MAX)
    link.symlink_to("/proc/self/status")
    os.lchown(link, ATTACKER, ATTACKER)
    start = "from control.rt import shm\nprint(*shm.cleanup_orphans()[1], sep='\\n')"
    try:
        done = subprocess.run(
            ["setpriv", f"--reuid={VICTIM}", f"--regid={VICTIM}", "--clear-groups",
             sys.executable, "-c", start], cwd=ROOT, capture_output=True, text=True, timeout=60,
            env={**os.environ, "PYTHONPATH": str(ROOT)})
        assert done.returncode == 0, done.stderr
        assert f"left {link.name} alone: it belongs to another user" in done.stdout
        assert link.is_symlink()
    finally:
        link.unlink(missing_ok=True)


def test_segment_names_another_user_made_first_stop_no_start(tmp_path: Path) -> None:
    """They see a servodesk process start (its pid is public) and make the names its segments
    had, ``sd_<pid>_ctl1`` and ``sd_<pid>_mv1``, before it does: its controller's start failed
    (FileExistsError). Now each name has a random part they cannot make first; the controller
    starts and moves."""
    script = f"""
from control import ControlClient
from control.motion import moves
from hw.machine import load_machine
arm = load_machine("unimate2000b")
input()
with ControlClient(arm, lockstep=True, data_dir={str(tmp_path)!r}) as client:
    print(client.segment_name, flush=True)
    start = client.status().position
    path = moves.step(start, 1, start[1] + 5.0, duration=1.0, machine=arm)
    print(client.wait(client.move(path, kind="step"), timeout=60).status, flush=True)
"""
    with subprocess.Popen([sys.executable, "-c", script], cwd=ROOT, stdin=subprocess.PIPE,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) as victim:
        assert victim.stdin is not None
        planted = [shm.SHM_DIR / shm.segment_name(tag, victim.pid) for tag in ("ctl1", "mv1")]
        try:
            for path in planted:
                path.touch(mode=0o600)
                os.chown(path, ATTACKER, ATTACKER)
            out, err = victim.communicate("\n", timeout=120)
        finally:
            for path in planted:
                path.unlink(missing_ok=True)
    assert victim.returncode == 0, err
    segment, status = out.split(maxsplit=1)
    assert segment.startswith(f"sd_{victim.pid}_ctl1_") and status.strip() == "complete", out
