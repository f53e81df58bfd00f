"""Choose and build a backend by name: ``sim`` (default) or ``serial``."""

from __future__ import annotations

from hw.backend import Backend
from hw.machine import Machine

BACKENDS = ("sim", "serial")


def make_backend(machine: Machine, kind: str = "sim", *, port: str | None = None,
                 seed: int = 0, lockstep: bool = False, **sim_options: object) -> Backend:
    """Build (not open) a backend for ``machine``.

    ``sim`` runs the plant model in real time, or in lockstep with ``lockstep``
    (``sim_options`` go to the simulator: initial positions, load, glitches);
    ``serial`` talks to an I/O board at a pyserial URL (``/dev/ttyACM0``,
    ``socket://127.0.0.1:PORT``, or the emulator's pty path).
    """
    if kind == "sim":
        from hw.sim.backend import SimBackend

        return SimBackend(machine, seed=seed, lockstep=lockstep, **sim_options)
    if kind == "serial":
        if not port:
            raise ValueError("the serial backend needs --port URL (a device, pty path or "
                             "socket://HOST:PORT)")
        from hw.serial.backend import SerialBackend

        return SerialBackend(machine, port)
    raise ValueError(f"unknown backend {kind!r}; choose one of {', '.join(BACKENDS)}")
