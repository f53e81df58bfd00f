"""How often the controller services each joint: servodesk's timing, or the thesis's.

servodesk (the default) reads every encoder, runs eq. 5.1 for every joint and
writes every valve each tick: a sample is one tick (the machine file's
``sample_time_ms``, 1 ms).

The thesis's RT.o (section 5.1, Appendix D ``Interrupt``) serviced one joint per
interrupt: read its encoder (switched on at the end of the interrupt before),
run its ErrorCalc, set its valve, then select the next joint's encoder. A sample
k of eq. 5.1 is six interrupts (Δt = 6 interrupt periods, section 5.4.1), so at
1 ms per interrupt each joint is updated every 6 ms, and at the 6 ms per joint
that section 6.2 recommends, every 36 ms. ``Timing("thesis", interrupt_ms=1)``
runs the controller that way, so that the thesis's experiments can be re-run as
they were; ``slips`` switches on the listing's known slips (``control.rt.law.SLIPS``,
docs/errata.md) to run its law as printed.
"""

from __future__ import annotations

from dataclasses import dataclass

from control.rt.law import SLIPS
from hw.machine import Machine

TIMINGS = ("servodesk", "thesis")


@dataclass(frozen=True)
class Timing:
    name: str = "servodesk"
    interrupt_ms: float = 1.0  # thesis: the period of one interrupt, one joint serviced
    slips: tuple[str, ...] = ()  # thesis: the listing's slips to reproduce (control.rt.law.SLIPS)

    def __post_init__(self) -> None:
        if self.name not in TIMINGS:
            raise ValueError(f"timing must be one of {', '.join(TIMINGS)}, got {self.name!r}")
        if not 0.1 <= self.interrupt_ms <= 100.0:  # also refuses NaN
            raise ValueError(f"interrupt_ms must be 0.1…100 ms, got {self.interrupt_ms!r}")
        unknown = sorted(set(self.slips) - SLIPS.keys())
        if unknown:
            raise ValueError(f"unknown slip {', '.join(unknown)}: the listing's are "
                             f"{', '.join(SLIPS)}")
        if self.name == "servodesk" and self.slips:
            raise ValueError("the listing's slips run only in the thesis's timing")

    @classmethod
    def thesis(cls, interrupt_ms: float = 1.0, slips: tuple[str, ...] = ()) -> Timing:
        return cls("thesis", interrupt_ms, tuple(slips))

    def slots(self, machine: Machine) -> int:
        """Ticks per sample: each serves one joint in the thesis's timing."""
        return machine.n_joints if self.name == "thesis" else 1

    def tick_s(self, machine: Machine) -> float:
        """The controller's tick: the thesis's interrupt, or servodesk's sample."""
        return self.interrupt_ms / 1e3 if self.name == "thesis" else machine.sample_time_s

    def sample_time_s(self, machine: Machine) -> float:
        """Δt of eq. 5.1 and the time between rows of a path."""
        return self.tick_s(machine) * self.slots(machine)

    def sim_options(self, machine: Machine) -> dict[str, float]:
        """The simulated board scans its encoders as the controller reads them: in the
        thesis's timing, each encoder selected at the end of the interrupt before the one that
        reads it (section 6.2's wrong readings follow from that one interrupt of light)."""
        if self.name == "servodesk":
            return {}
        tick = self.tick_s(machine)
        return {"scan_period_s": self.sample_time_s(machine), "select_to_latch_s": tick,
                "scan_lead_s": tick}

    def describe(self, machine: Machine) -> str:
        if self.name == "servodesk":
            return f"servodesk: every joint every {machine.sample_time_s * 1e3:g} ms"
        text = (f"thesis: one joint per {self.interrupt_ms:g} ms interrupt, each every "
                f"{self.sample_time_s(machine) * 1e3:g} ms")
        return text + (f"; the listing's slips: {', '.join(self.slips)}" if self.slips else "")
