"""The machines' position encoders as the hardware has them.

Rig (sections 1.3.2, 3.2.3): an incremental quadrature encoder at 0.1 mm. The
UPP card counts edges, so the count is relative to wherever the ram was at
power-up; the rig's Initialise drives to the bottom and notes the count there.

Unimate 2000B (sections 4.6.4, 5.3, 6.2): six absolute 13-bit Gray-code
encoders on one shared bus. Selecting an encoder lights its lamp; 13
photocells behind the slotted disk drive the bus lines. The simulated I/O
board scans them round-robin on its own clock, one encoder per slot of
``scan_period / 6``, and latches each word at the end of its slot; a read
returns the latest latched word of every joint.

Wrong readings (section 6.2, Figure 6.1). A lamp that was dark for the other
five slots has cooled; lit again it warms with time constant ``settle / 3``
(within 5 % of full light at the settle time, 6 ms) and cools with
``lamp_cool_ms``. Scanned periodically, the light at the end of a slot settles
to ``L = (1 - a) / (1 - a b)`` with ``a = exp(-slot / heat)``,
``b = exp(-(period - slot) / cool)``: about 0.76 of full light at the default
1 ms scan, 0.97 when each encoder gets 6 ms. The lamp's light also ripples
from reading to reading (its 28 V supply feeds the six PWM amplifiers,
section 4.6.3), a Gaussian of ``lamp_ripple``. A photocell whose light falls
under the comparator threshold reads dark (0), whatever the disk shows; the
photocells of one encoder differ in sensitivity by up to ``photocell_spread``,
so a dim reading loses the weakest cell's bit first, then more. In Gray code
one lost high bit is a large jump in the binary value: the isolated spikes of
Figure 6.1, and only when the lost bit was lit.

Calibration: the threshold is set so that at the default scan each encoder's
weakest cell drops out ``lamp_dropouts_per_s`` times a second on average. With
0.35, and only lost lit bits counting, a 12 s move (2000 samples, rtshare.h)
gives 2 to 3 wrong readings per joint, as Figure 6.1 shows. Everything else
follows from the lamp: a slower scan lights the lamp longer and the wrong
readings vanish; so does the thesis's own scan (1 ms per encoder), which in
this model is clean too: the model cannot make a slot of 1/6 ms worse than
one of 1 ms, so it is calibrated at servodesk's scan. ``glitch_scale``
multiplies the default dropout rate (0 turns it off) for fault-injection tests.
The draws come from a seeded generator, so a seed fixes every wrong reading.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

from hw.gray import binary_to_gray
from hw.machine import Machine
from hw.sim.plant import MACHINE_KEYS, PlantKeys
from hw.transmission import Transmission

STANDARD_NORMAL = NormalDist()


class QuadratureEncoder:
    """Incremental encoder: a signed count of ``resolution`` steps since power-up.

    Edges sit halfway between multiples of the resolution; the count is the
    number of edges passed, so it is 0 at the power-up position.
    """

    def __init__(self, resolution: float, power_up_position: float) -> None:
        self.resolution = resolution
        self._offset = math.floor(power_up_position / resolution + 0.5)

    def count(self, position: float) -> int:
        """Signed count at ``position`` (units of ``resolution``, whose sign sets the direction)."""
        return math.floor(position / self.resolution + 0.5) - self._offset


@dataclass(frozen=True)
class Lamp:
    """Encoder lamp and photocells of the Unimate's absolute encoders (section 6.2).

    heat_s, cool_s: filament time constants lit and dark, s.
    ripple: relative standard deviation of the light from reading to reading.
    spread: photocell sensitivities lie within (1 - spread)..1 of the strongest.
    dropouts_per_s: weakest-cell dropouts per encoder per second at the default scan.
    """

    heat_s: float
    cool_s: float
    ripple: float
    spread: float
    dropouts_per_s: float

    @classmethod
    def from_machine(cls, machine: Machine) -> Lamp:
        keys = PlantKeys(machine, "plant", machine.plant, MACHINE_KEYS)
        return cls(
            heat_s=machine.encoder_settle_s / 3.0,
            cool_s=keys.number("lamp_cool_ms") / 1e3,
            ripple=keys.number("lamp_ripple"),
            spread=keys.number("photocell_spread"),
            dropouts_per_s=keys.number("lamp_dropouts_per_s"),
        )

    def light(self, slot_s: float, period_s: float) -> float:
        """Light at the end of a slot when lit ``slot_s`` out of every ``period_s``, full = 1."""
        a = math.exp(-slot_s / self.heat_s)
        b = math.exp(-(period_s - slot_s) / self.cool_s)
        return (1.0 - a) / (1.0 - a * b)


class GrayEncoderBoard:
    """The I/O board's scan of the multiplexed Gray-code encoders; ``words`` holds the latches.

    ``wrong_readings`` counts, per joint, latched words that differ from what the disk showed.

    ``update`` is called as the plant advances, with the actuator positions
    (joint units) at the start and end of the step; the board latches every slot
    that ends in the step at the linearly interpolated position.
    """

    def __init__(self, machine: Machine, positions: Sequence[float], *, seed: int = 0,
                 glitch_scale: float = 1.0, scan_period_s: float | None = None,
                 start_ns: int = 0) -> None:
        if glitch_scale < 0.0:
            raise ValueError(f"glitch_scale must be >= 0, got {glitch_scale:g}")
        period_s = machine.sample_time_s if scan_period_s is None else scan_period_s
        if not period_s > 0.0:
            raise ValueError(f"scan_period_s must be > 0, got {period_s:g}")
        self.n = machine.n_joints
        self.top = (1 << machine.encoder_bits) - 1
        self.transmission = Transmission(machine)
        self.lamp = Lamp.from_machine(machine)
        self._period_ns = max(round(period_s * 1e9), self.n)
        self._origin_ns = start_ns
        self._k = 0
        self._next_ns = start_ns + self._period_ns // self.n
        self._rng = random.Random(seed)
        self._cells = [self._photocells(machine.encoder_bits) for _ in range(self.n)]
        self._set_threshold(machine, glitch_scale, period_s)
        self._gap = [self._draw_gap() for _ in range(self.n)]
        self.words = [self.encode(j, a) for j, a in enumerate(positions)]
        self.wrong_readings = [0] * self.n

    def _photocells(self, bits: int) -> list[tuple[float, int]]:
        """(sensitivity relative to the weakest cell, bit mask) per cell, weakest first."""
        low = 1.0 - self.lamp.spread
        sens = [self._rng.uniform(low, 1.0) for _ in range(bits)]
        sens[self._rng.randrange(bits)] = low
        return sorted((s / low, 1 << i) for i, s in enumerate(sens))

    def _set_threshold(self, machine: Machine, scale: float, period_s: float) -> None:
        """Threshold from the dropout rate at the default scan; dropout chance at this scan."""
        lamp, n = self.lamp, self.n
        self._light = lamp.light(period_s / n, period_s)
        p_default = min(scale * lamp.dropouts_per_s * machine.sample_time_s, 0.5)
        if p_default <= 0.0:
            self._threshold, self._p = 0.0, 0.0
            return
        default_light = lamp.light(machine.sample_time_s / n, machine.sample_time_s)
        self._threshold = default_light * (1.0 + lamp.ripple * STANDARD_NORMAL.inv_cdf(p_default))
        self._p = STANDARD_NORMAL.cdf((self._threshold / self._light - 1.0) / lamp.ripple)

    def _draw_gap(self) -> float:
        """Readings until the weakest cell next drops out (geometric); inf if it never does."""
        if self._p <= 0.0:
            return math.inf
        if self._p >= 1.0:
            return 0.0
        return float(math.floor(math.log1p(-self._rng.random()) / math.log1p(-self._p)))

    def encode(self, joint: int, position: float) -> int:
        """Gray word the disk shows at actuator ``position`` (joint units), clipped to the disk."""
        b = math.floor(self.transmission.count_of(joint, position) + 0.5)
        if b < 0:
            b = 0
        elif b > self.top:
            b = self.top
        return binary_to_gray(b)

    def update(self, t0_ns: int, t1_ns: int, a0: Sequence[float], a1: Sequence[float]) -> None:
        """Latch every slot ending in (t0, t1]; ``a0``/``a1`` are positions at t0 and t1."""
        if self._next_ns <= t0_ns:
            self._skip_to(t0_ns)
        span = t1_ns - t0_ns
        n = self.n
        while self._next_ns <= t1_ns:
            j = self._k % n
            frac = (self._next_ns - t0_ns) / span
            word = self.encode(j, a0[j] + (a1[j] - a0[j]) * frac)
            if self._gap[j] <= 0.0:
                dimmed = self._dropout(j, word)
                if dimmed != word:
                    self.wrong_readings[j] += 1
                word = dimmed
                self._gap[j] = self._draw_gap()
            else:
                self._gap[j] -= 1.0
            self.words[j] = word
            self._k += 1
            self._next_ns = self._origin_ns + (self._k + 1) * self._period_ns // n

    def _skip_to(self, t_ns: int) -> None:
        """Move the scan on to the first slot ending after ``t_ns`` (time jumped)."""
        self._k = (t_ns - self._origin_ns) * self.n // self._period_ns
        self._next_ns = self._origin_ns + (self._k + 1) * self._period_ns // self.n
        while self._next_ns <= t_ns:
            self._k += 1
            self._next_ns = self._origin_ns + (self._k + 1) * self._period_ns // self.n

    def _dropout(self, joint: int, word: int) -> int:
        """``word`` as read with the lamp dim enough to lose the weakest cell (and maybe more)."""
        u = max(self._rng.random() * self._p, 1e-300)
        light = self._light * (1.0 + self.lamp.ripple * STANDARD_NORMAL.inv_cdf(u))
        cutoff = self._threshold / light if light > 0.0 else math.inf
        dark = 0
        for ratio, bit in self._cells[joint]:
            if ratio >= cutoff:
                break
            dark |= bit
        return word & ~dark
