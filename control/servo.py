"""Cartesian servo: the tool moves at a velocity for as long as the operator holds a key
(issue 25 item 3), as MoveIt Servo streams it, rather than as a train of planned moves.

A thread in the client, ``SERVO_HZ`` times a second:

1. reads the commanded joints ``q`` (the controller's hold target, ``Status.desired``);
2. advances its reference along the straight line of the jog (``cartesian_jog.line_of``:
   the start pose moved by ``s`` seconds of the tool's velocity ``v``) at ``u·z·f·|v|``:
   ``u`` ramps from 0 to 1 at the machine's ``cartesian_jog_accel`` while held and back to 0
   on release, so the tool brakes along its line; ``z`` is the singularity zone's scale
   (``cartesian_jog`` docstring): every joint within its ``jog_speed``; ``f`` the operator's
   feed override, as it scales a move;
3. sends ``client.jog_velocity(q̇)`` with ``q̇ = J(q)⁻¹·(u·z·v + K·e)``: ``J`` the geometric
   Jacobian at the commanded joints (``Unimate2000B.jacobian``), ``e`` the pose error from
   the commanded tool to the reference (mm and deg), ``K = CORRECTION_PER_S``: the drift of
   integrating joint velocities is pulled back onto the line each period. ``q̇`` is scaled as
   a whole to the joints' jog speeds, so the controller's own per-joint cap never bends it.

It stops (braking along the line) when released (``release``), when not renewed within
``keepalive_s`` (a key that stopped repeating), before a joint would need more than its
``max_speed`` while the jog comes nearer a singularity (``zone``; one going away is let go
on, slowly), or before a joint limit; and at once (no more sends: the controller's
150 ms deadman brakes it) on an E-stop, a fault, or a move taking over. Its ``report`` says
how far the tool went along the line, how far the commanded tool strayed from it, and why
it stopped. A servo leaves no run: the Jog tab logs each press-and-hold.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from control.client import ControlClient, ControllerError
from control.motion.cartesian_jog import FRAMES, Line, line_of
from control.motion.robot_model import unimate_model
from control.rt.jog import rest_range
from control.rt.layout import Mode, Status
from kinematics.unimate import Unimate2000B

SERVO_HZ = 100.0
CORRECTION_PER_S = 10.0  # 1/s: a pose error is taken back at this rate (0.1 s time constant)
APPROACH_LOOK_S = 0.05  # a halt looks this far ahead to tell nearing a singularity from leaving
LIMIT_LOOK_S = 0.3  # the servo brakes when a joint would reach a soft limit within this
SETTLE_TICKS = 3  # periods of zero velocity sent after the tool stopped on its line
ARRIVED = 0.02  # mm or deg: the commanded tool is at the line's end (it caught up its lag)
CATCH_UP_S = 1.0  # at most this long after the reference stopped (10 time constants)
AFTER_S = 2.0  # the longest a servo waits for the one before it to stop


@dataclass(frozen=True)
class ServoReport:
    """How a servoed jog went: ``distance`` along the line (mm, or deg for a turn) and the
    commanded tool's largest ``drift`` from it (mm), both from the commanded joints;
    ``braked`` how far along the line it went after the release was seen (the braking
    distance, v²/2a at the Cartesian acceleration, and what the commanded tool lagged);
    ``duration`` s; ``stopped`` why it ended ('released', a singularity, a limit, …)."""

    distance: float
    drift: float
    braked: float
    duration: float
    stopped: str


class CartesianServo:
    """Move the tool at ``velocity (6,)`` ``[vx, vy, vz (mm/s), ωγ, ωβ, ωα (deg/s)]`` along
    the axes of ``frame`` from the commanded pose, until ``release`` (module docstring).

    ValueError for a bad frame or velocity, or one faster than the machine's Cartesian jog
    speed. ``start`` begins; ``renew`` keeps it going for another ``keepalive_s``."""

    def __init__(self, client: ControlClient, velocity: Sequence[float], frame: str = "world",
                 *, keepalive_s: float = math.inf) -> None:
        machine = client.machine
        self.client = client
        self.model: Unimate2000B = unimate_model(machine)
        if frame not in FRAMES:
            raise ValueError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
        v = np.asarray(velocity, dtype=float)
        if v.shape != (6,) or not np.isfinite(v).all() or not v.any():
            raise ValueError("a servo velocity is 6 finite numbers, not all 0 [vx, vy, vz "
                             f"(mm/s), ωγ, ωβ, ωα (deg/s)], got {np.asarray(velocity).tolist()}")
        lengths = np.array([np.linalg.norm(v[:3]), np.linalg.norm(v[3:])])
        top = np.array(machine.cartesian_jog_speed)
        if (lengths > top * (1 + 1e-9)).any():
            raise ValueError(f"a servo velocity of {lengths[0]:g} mm/s, {lengths[1]:g}°/s is "
                             f"faster than the Cartesian jog speed ({top[0]:g} mm/s, "
                             f"{top[1]:g}°/s, cartesian_jog_speed): ask for less")
        self.velocity, self.frame, self.keepalive_s = v, frame, keepalive_s
        accel = np.array(machine.cartesian_jog_accel)
        self.ramp = float(min(a / n for a, n in zip(accel, lengths, strict=True) if n > 0))
        self.vjog = np.array([j.jog_speed for j in machine.joints])
        self.vmax = np.array([j.max_speed for j in machine.joints])
        ranges = [rest_range(j) for j in machine.joints]  # where the controller's jog stops
        self.lower = np.array([low for low, _ in ranges])
        self.upper = np.array([high for _, high in ranges])
        self.period = 1.0 / SERVO_HZ
        self._held = threading.Event()
        self._renewed = time.monotonic()
        self._stopped = ""
        self._thread: threading.Thread | None = None
        self._after: CartesianServo | None = None
        self.report: ServoReport | None = None
        self.done = threading.Event()

    def start(self, after: CartesianServo | None = None) -> None:
        """Begin; ``after``: a servo still braking (a key let go just before), which must end
        first, so that two never stream at once and this one starts where that one stops."""
        self._held.set()
        self._renewed = time.monotonic()
        self._after = after
        self._thread = threading.Thread(target=self._run, name="cartesian-servo", daemon=True)
        self._thread.start()

    def renew(self) -> None:
        """The key is still held (a repeat): go on for another ``keepalive_s``."""
        self._renewed = time.monotonic()

    def release(self, why: str = "released") -> None:
        """Brake along the line to a stop."""
        if self._held.is_set():
            self._stopped = self._stopped or why
            self._held.clear()

    def wait(self, timeout: float | None = None) -> ServoReport:
        if not self.done.wait(timeout):
            raise TimeoutError(f"the Cartesian servo still runs after {timeout:g} s")
        assert self.report is not None
        return self.report

    @property
    def running(self) -> bool:
        return self._thread is not None and not self.done.is_set()

    # -- the loop ------------------------------------------------------------------------------

    def _run(self) -> None:
        if self._after is not None:
            self._after.done.wait(AFTER_S)
        began = self._renewed = time.monotonic()
        try:
            status = self.client.status()
        except (ControllerError, TimeoutError) as exc:  # closed as it began (the app quitting)
            self.report = ServoReport(0.0, 0.0, 0.0, 0.0, f"stopped: {exc}")
            self.done.set()
            return
        if gone := self._gone(status):  # no line to start from (manual actuation: no target)
            self.report = ServoReport(0.0, 0.0, 0.0, 0.0, gone)
            self.done.set()
            return
        q = np.array(status.desired)
        line = line_of(self.model.forward(q), self.velocity, self.frame == "tool")
        twist = np.concatenate([line.d, np.degrees(line.r0 @ line.omega if line.tool
                                                   else line.omega)])
        s = u = drift = 0.0
        released: float | None = None  # how far it had gone when the release was seen
        last, quiet, stopping = began, 0, 0.0
        try:
            while quiet < SETTLE_TICKS:
                now = time.monotonic()
                dt, last = now - last, now
                status = self.client.status()
                gone = self._gone(status)
                if gone:
                    self._stopped = self._stopped or gone
                    break
                q = np.array(status.desired)
                if now - self._renewed > self.keepalive_s:
                    self.release("the key stopped repeating")
                if released is None and not self._held.is_set():
                    released = self._along(line, q)
                u = self._ramp(u, dt)
                # the operator's feed override scales a held jog as it scales a move
                scale = self._zone(q, twist) * status.feed_override if u > 0 else 0.0
                s += u * scale * dt
                drift = max(drift, self._sideways(line, q))
                qdot, off = self._joint_velocity(q, line, s, twist * u * scale)
                if not self._held.is_set() and u == 0.0:
                    stopping = stopping or now
                    if off < ARRIVED or now - stopping > CATCH_UP_S:  # on the line's end
                        qdot[:] = 0.0
                        quiet += 1
                self.client.jog_velocity(qdot.tolist())
                time.sleep(max(0.0, self.period - (time.monotonic() - now)))
        except Exception as exc:  # the controller died or refused: the deadman brakes it
            self._stopped = self._stopped or f"stopped: {exc}"
        finally:
            with contextlib.suppress(Exception):  # closed meanwhile: the last reading stands
                last_q = np.array(self.client.status().desired)
                if np.isfinite(last_q).all():  # none once manual actuation took over
                    q = last_q
            distance = self._along(line, q)
            braked = distance - released if released is not None else 0.0
            self.report = ServoReport(distance, drift, braked, time.monotonic() - began,
                                      self._stopped or "released")
            self.done.set()

    def _gone(self, status: Status) -> str:
        """Why the servo must stop sending at once, or ''."""
        if status.estop:
            return "E-stop"
        if status.mode != Mode.HOLD:
            return f"the controller left hold ({Mode(status.mode).name.lower()})"
        if not np.isfinite(status.desired).all():
            return "no commanded position"
        return ""

    def _ramp(self, u: float, dt: float) -> float:
        """The fraction of the velocity the tool runs at: up to 1 while held, down to 0 after,
        within the Cartesian jog acceleration."""
        if self._held.is_set():
            return min(1.0, u + self.ramp * dt)
        return max(0.0, u - self.ramp * dt)

    def _zone(self, q: np.ndarray, twist: np.ndarray) -> float:
        """The singularity zone's scale at ``q``: every joint within its jog speed; a halt
        (braking begins) before a joint would need more than its max_speed while nearing a
        singularity, or before a joint limit."""
        qdot = self._qdot(q, twist)
        need = np.abs(qdot)
        over = need / self.vmax
        if (over > 1.0).any():
            step = np.nan_to_num(qdot, posinf=0.0, neginf=0.0) * APPROACH_LOOK_S / over.max()
            ahead = self._need(q + step, twist) / self.vmax
            if not np.isfinite(over).all() or ahead.max() >= over.max():
                j = int(np.argmax(over))
                joint = self.client.machine.joints[j]
                self.release(f"{joint.name} would need {need[j]:.0f}{_unit(joint.unit)}/s, over "
                             f"its max_speed {joint.max_speed:g}{_unit(joint.unit)}/s, to keep "
                             f"the tool on the line: near a singularity (Yaw {q[4]:.1f}°)")
        reach = q + qdot * LIMIT_LOOK_S
        outside = (reach < self.lower) | (reach > self.upper)
        if outside.any():
            joint = self.client.machine.joints[int(np.argmax(outside))]
            self.release(f"joint limit: {joint.name} would pass its limits {joint.limit_text()}")
        worst = float(np.max(need / self.vjog))
        return 1.0 if worst <= 1.0 else 1.0 / worst

    def _qdot(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        try:
            return np.linalg.solve(self.model.jacobian(q), twist)
        except np.linalg.LinAlgError:  # exactly singular
            return np.full(6, np.inf)

    def _need(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        return np.abs(self._qdot(q, twist))

    def _joint_velocity(self, q: np.ndarray, line: Line, s: float, feed: np.ndarray
                        ) -> tuple[np.ndarray, float]:
        """``J⁻¹·(feed + K·e)``, scaled as a whole to the joints' jog speeds, and how far the
        commanded tool is from the reference (mm, and deg counted as mm)."""
        t = self.model.forward(q)
        p_ref, r_ref = line.at(np.array([s]))
        error = np.concatenate([p_ref[0] - t[:3, 3],
                                np.degrees(_rotation_vector(r_ref[0] @ t[:3, :3].T))])
        off = float(np.abs(error).max())
        qdot = self._qdot(q, feed + CORRECTION_PER_S * error)
        if not np.isfinite(qdot).all():
            return np.zeros(6), off
        over = float(np.max(np.abs(qdot) / self.vjog))
        return (qdot / over if over > 1.0 else qdot), off

    def _sideways(self, line: Line, q: np.ndarray) -> float:
        """How far the commanded tool point is from the line's (mm)."""
        p = self.model.forward(q)[:3, 3] - line.p0
        d = line.d
        n = float(np.linalg.norm(d))
        if n == 0.0:
            return float(np.linalg.norm(p))
        return float(np.linalg.norm(p - (p @ d) / n**2 * d))

    def _along(self, line: Line, q: np.ndarray) -> float:
        """How far the commanded tool went along the line: mm, or deg for a turn."""
        t = self.model.forward(q)
        d = line.d
        n = float(np.linalg.norm(d))
        if n > 0.0:
            return float((t[:3, 3] - line.p0) @ d / n)
        omega = line.omega
        r0 = line.r0
        turned = r0.T @ t[:3, :3] if line.tool else t[:3, :3] @ r0.T
        return float(np.degrees(_rotation_vector(turned) @ omega / np.linalg.norm(omega)))


def _rotation_vector(r: np.ndarray) -> np.ndarray:
    """The rotation vector (rad) of a rotation ``r (3, 3)`` below 180°: the log map."""
    angle = math.acos(max(-1.0, min(1.0, (float(np.trace(r)) - 1.0) / 2.0)))
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return axis * (0.5 if angle < 1e-9 else angle / (2.0 * math.sin(angle)))


def _unit(unit: str) -> str:
    return " mm" if unit == "mm" else "°"

