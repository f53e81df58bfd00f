"""The machines' position encoders as the hardware has them.

Rig (sections 1.3.2, 3.2.3): an incremental quadrature encoder at 0.1 mm. The
UPP card counts edges, so the count is relative to wherever the ram was at
power-up; the rig's Initialise drives to the bottom and notes the count there.

Unimate 2000B (sections 4.6.4, 5.3, 6.2): six absolute 13-bit Gray-code
encoders on one shared bus. Selecting an encoder lights its lamp; behind the
slotted disk a photocell per track conducts where its track is clear and pulls
its bus line low (0), so a dark encoder pulls no line and the six can share
the wires; an opaque track leaves the line to its pull-up (1). The simulated
I/O board scans the encoders round-robin on its own clock: encoder ``k`` is
selected at the start of its slot of ``scan_period / n`` and latched
``select_to_latch`` later (by default at the end of the slot); a read returns
the latest latched word of every joint.

Wrong readings (section 6.2, Figure 6.1), from the lamp against the scan's
timing. A lamp lit for its slot warms towards full light with time constant
``settle / 3`` and, dark for the other slots, cools with ``lamp_cool_ms``;
scanned periodically its light at the latch is

    L = 1 - (1 - L0) exp(-t_latch / heat),  L0 = b (1 - a) / (1 - a b),
    a = exp(-slot / heat),  b = exp(-(period - slot) / cool)

(L0: the light left at the select). The light also ripples from reading to
reading, a Gaussian of relative ``lamp_ripple``: the lamps' 28 V supply feeds
the six PWM amplifiers too (section 4.6.3). A clear track's cell pulls its line
low only if its light reaches ``threshold`` of the brightest cell's at full
light; the cells of one encoder differ in sensitivity by up to
``photocell_spread`` (the weakest at the low end, the rest uniform, fixed by the
seed). A dim reading therefore sets the bits of the weakest clear tracks: in
Gray code one wrong high bit is a large jump in the binary value, the isolated
spikes of Figure 6.1, and a joint whose word has fewer clear tracks risks fewer.

One set of numbers (docs/simulator.md): with the thesis's timing, 1 ms per
joint (each encoder every 6 ms), the light at the latch is 0.85 of full and
the weakest cells fail now and then, about nine readings a run of 2000 samples
over the six joints, as Figure 6.1 (1.1-2.3 a joint); at 6 ms per joint it is
0.97 and none fail; servodesk's own scan (all six every 1 ms, 1/6 ms each)
latches at 0.81 and fails more often. The board
draws the gap to the next reading dim enough to fail the weakest cell
(geometric), then keeps it with the chance the word's weakest clear cell fails,
so a scan costs one encode per slot. ``glitch_scale`` multiplies every failure
chance (0 turns them off) for fault-injection tests. The draws come from a
seeded generator, so a seed fixes every wrong reading.
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

    heat_s, cool_s: time constants of the light, lamp lit and dark, s.
    ripple: relative standard deviation of the light from reading to reading.
    spread: photocell sensitivities lie within (1 - spread)..1 of the strongest.
    threshold: light, relative to the strongest cell at full light, a clear
      track's cell needs to pull its line low.
    """

    heat_s: float
    cool_s: float
    ripple: float
    spread: float
    threshold: float

    @classmethod
    def from_machine(cls, machine: Machine) -> Lamp:
        keys = PlantKeys(machine, "plant", machine.plant, MACHINE_KEYS)
        return cls(
            heat_s=machine.encoder_settle_s / 3.0,
            cool_s=keys.number("lamp_cool_ms") / 1e3,
            ripple=keys.number("lamp_ripple"),
            spread=keys.number("photocell_spread"),
            threshold=machine.encoder_threshold,
        )

    def light(self, slot_s: float, period_s: float, latch_s: float | None = None) -> float:
        """Light at the latch, full = 1, when lit for ``slot_s`` out of every ``period_s``
        and latched ``latch_s`` after the select (default: at the end of the slot)."""
        t = slot_s if latch_s is None else latch_s
        a = math.exp(-slot_s / self.heat_s)
        b = math.exp(-(period_s - slot_s) / self.cool_s)
        left = b * (1.0 - a) / (1.0 - a * b)
        return 1.0 - (1.0 - left) * math.exp(-t / self.heat_s)

    def fail_z(self, sensitivity: float, light: float) -> float:
        """Standard-normal ripple below which a clear track's cell of ``sensitivity`` fails."""
        return (self.threshold / (sensitivity * light) - 1.0) / self.ripple


@dataclass(frozen=True)
class Scan:
    """The board's scan: ``period_s`` to read every encoder once, each latched
    ``latch_s`` after its select, within its slot of ``period_s / n``."""

    period_s: float
    latch_s: float

    @classmethod
    def of(cls, n: int, period_s: float, latch_s: float | None) -> Scan:
        if not period_s > 0.0:
            raise ValueError(f"scan_period_s must be > 0, got {period_s:g}")
        slot = period_s / n
        if latch_s is None:
            latch_s = slot
        if not 0.0 < latch_s <= slot * (1.0 + 1e-9):
            raise ValueError(f"select_to_latch_s must be in (0, {slot:g}] (the slot of a "
                             f"{period_s:g} s scan of {n} encoders), got {latch_s:g}")
        return cls(period_s, min(latch_s, slot))


class GrayEncoderBoard:
    """The I/O board's scan of the multiplexed Gray-code encoders; ``words`` holds the latches.

    ``wrong_readings`` counts, per joint, latched words that differ from what the disk showed.

    ``update`` is called as the plant advances, with the actuator positions
    (joint units) at the start and end of the step; the board latches every slot
    whose latch falls in the step at the linearly interpolated position.
    """

    def __init__(self, machine: Machine, positions: Sequence[float], *, seed: int = 0,
                 glitch_scale: float = 1.0, scan_period_s: float | None = None,
                 select_to_latch_s: float | None = None, start_ns: int = 0) -> None:
        if glitch_scale < 0.0:
            raise ValueError(f"glitch_scale must be >= 0, got {glitch_scale:g}")
        self.n = machine.n_joints
        self.scan = Scan.of(self.n, machine.sample_time_s if scan_period_s is None
                            else scan_period_s, select_to_latch_s)
        self.top = (1 << machine.encoder_bits) - 1
        self.transmission = Transmission(machine)
        self.lamp = Lamp.from_machine(machine)
        self.light = self.lamp.light(self.scan.period_s / self.n, self.scan.period_s,
                                     self.scan.latch_s)
        self._period_ns = max(round(self.scan.period_s * 1e9), self.n)
        self._latch_ns = max(round(self.scan.latch_s * 1e9), 1)
        self._origin_ns = start_ns
        self._k = 0
        self._next_ns = self._latch_time(0)
        self._rng = random.Random(seed)
        # per joint: (sensitivity, bit mask, ripple z below which it fails, failure chance)
        self._cells = [self._photocells(machine.encoder_bits, glitch_scale)
                       for _ in range(self.n)]
        self._p = [cells[0][3] for cells in self._cells]  # the weakest cell's chance
        self._gap = [self._draw_gap(j) for j in range(self.n)]
        self.words = [self.encode(j, a) for j, a in enumerate(positions)]
        self.wrong_readings = [0] * self.n

    def _photocells(self, bits: int, scale: float) -> list[tuple[float, int, float, float]]:
        """Cells weakest first: sensitivity (strongest = 1), bit, failing z and chance."""
        low = 1.0 - self.lamp.spread
        sens = [self._rng.uniform(low, 1.0) for _ in range(bits)]
        sens[self._rng.randrange(bits)] = low
        cells = []
        for s, i in sorted((s, i) for i, s in enumerate(sens)):
            z = self.lamp.fail_z(s, self.light)
            cells.append((s, 1 << i, z, min(scale * STANDARD_NORMAL.cdf(z), 1.0)))
        return cells

    def _latch_time(self, k: int) -> int:
        return self._origin_ns + k * self._period_ns // self.n + self._latch_ns

    def _draw_gap(self, joint: int) -> float:
        """Readings until the weakest cell next fails (geometric); inf if it never does."""
        p = self._p[joint]
        if p <= 0.0:
            return math.inf
        if p >= 1.0:
            return 0.0
        return float(math.floor(math.log1p(-self._rng.random()) / math.log1p(-p)))

    def encode(self, joint: int, position: float) -> int:
        """Gray word the disk shows at actuator ``position`` (joint units), clipped to the disk."""
        b = math.floor(self.transmission.count_of(joint, position) + 0.5)
        if b < 0:
            b = 0
        elif b > self.top:
            b = self.top
        return binary_to_gray(b)

    def update(self, t0_ns: int, t1_ns: int, a0: Sequence[float], a1: Sequence[float]) -> None:
        """Latch every slot whose latch falls in (t0, t1]; ``a0``/``a1`` are positions then.

        ``encode`` and ``_latch_time`` written out: the loop runs every joint every tick."""
        if self._next_ns <= t0_ns:
            self._skip_to(t0_ns)
        span = t1_ns - t0_ns
        n, top, gap, words = self.n, self.top, self._gap, self.words
        constant, gradient = self.transmission.constant, self.transmission.gradient
        origin, period, latch = self._origin_ns, self._period_ns, self._latch_ns
        k, next_ns = self._k, self._next_ns
        while next_ns <= t1_ns:
            j = k % n
            position = a0[j] + (a1[j] - a0[j]) * ((next_ns - t0_ns) / span)
            b = math.floor((position - constant[j]) / gradient[j] + 0.5)
            b = 0 if b < 0 else top if b > top else b
            word = b ^ (b >> 1)  # binary_to_gray
            if gap[j] <= 0.0:
                dimmed = self._dim(j, word)
                if dimmed != word:
                    self.wrong_readings[j] += 1
                word = dimmed
                gap[j] = self._draw_gap(j)
            else:
                gap[j] -= 1.0
            words[j] = word
            k += 1
            next_ns = origin + k * period // n + latch
        self._k, self._next_ns = k, next_ns

    def _skip_to(self, t_ns: int) -> None:
        """Move the scan on to the first latch after ``t_ns`` (time jumped)."""
        self._k = max((t_ns - self._origin_ns - self._latch_ns) * self.n // self._period_ns, 0)
        self._next_ns = self._latch_time(self._k)
        while self._next_ns <= t_ns:
            self._k += 1
            self._next_ns = self._latch_time(self._k)

    def _dim(self, joint: int, word: int) -> int:
        """``word`` as read when the ripple is low enough to fail the weakest cell: kept dim
        with the chance the word's weakest clear track's cell fails, which then reads 1
        with every clear track's cell that fails at the same light."""
        cells = self._cells[joint]
        weakest = next((c for c in cells if not word & c[1]), None)
        if weakest is None:
            return word  # every track opaque: no cell has to pull its line
        _, _, z, p = weakest
        rng = self._rng
        if rng.random() * self._p[joint] >= p:
            return word
        ripple = STANDARD_NORMAL.inv_cdf(max(rng.random() * STANDARD_NORMAL.cdf(z), 1e-300))
        for _, cell_bit, cell_z, _ in cells:
            if cell_z <= ripple:
                break
            word |= cell_bit
        return word
