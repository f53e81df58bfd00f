"""The servo valve: what the UPP card's PWM does to the spool, and what the spool lets through.

Signal path (sections 1.3.1, 3.3, 4.6.1):

1. The control side writes a signed duty in percent. The UPP card outputs it in
   whole steps of 3.25 us out of a 325 us period, 1 % steps
   (``machine.valve_resolution_pct``, ``valve_period_us``); the listings hand a
   float to ``SetSinglePWMValue``/``SetPWMValues`` as an ``int``, so C
   truncates toward zero (:func:`quantise_duty`). A new duty is loaded at the
   start of the next PWM period (:func:`next_period_ns`).
2. The amplifier's average voltage sets the spool: spool stroke in percent of
   full stroke equals the duty, reached through a first-order lag
   (``spool_time_s``; the valve filters the 3 kHz PWM ripple, which is not
   modelled). The E-stop cuts the PWM signals, so the spool springs back to
   centre and the valve closes (section 4.6.2).
3. The spool overlaps the ports by ``lap_pos_pct``/``lap_neg_pct`` of its
   stroke per direction: inside the overlap no oil flows (the minimum PWM of
   section 5.4.1, the 0.0056 m/s offset of eq. 3.1/3.2). Beyond it each
   metering edge opens in proportion: ``opening = (|spool| - lap) / 100``.
4. Each open edge is a sharp-edged orifice: ``Q = K * opening * sqrt(dp)``
   (:func:`orifice_flow`). ``K`` follows from the valve's rated flow, quoted
   (as Moog does) at a 7 MPa valve drop, 3.5 MPa per edge. A valve for a
   differential cylinder may meter its ``b`` port wider than its ``a`` port
   (``K_b = b_ratio * K_a``, 2:1 is the usual choice). A centred spool
   still leaks a little across its lands: a laminar conductance per edge,
   from the catalogue's null leakage at supply pressure.
5. With ``pressure_gain`` (a servo valve's lands, close to critically lapped)
   that leakage is not the same on every edge: as the spool moves through the
   overlap, the land that will open uncovers and leaks more, the one closing
   covers more and leaks less (a laminar leak goes as the land's clearance
   over its covered length), so the blocked-port pressure swings from half
   supply at null to supply at the overlap's edge: the valve's pressure gain
   (:meth:`Valve.edge_leaks`). Past the edge the orifice takes over and the
   leak fades out over one more overlap width, so the flow lines beyond twice
   the overlap are the orifice's alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

LPM = 1e-3 / 60.0  # one litre per minute in m^3/s


def quantise_duty(duty_pct: float, resolution_pct: float) -> float:
    """Signed duty as the UPP card outputs it: clipped to +-100 %, truncated to whole steps.

    A NaN command closes the valve rather than driving it anywhere.
    """
    if duty_pct != duty_pct:
        return 0.0
    if duty_pct > 100.0:
        duty_pct = 100.0
    elif duty_pct < -100.0:
        duty_pct = -100.0
    return math.trunc(duty_pct / resolution_pct) * resolution_pct


def next_period_ns(t_ns: int, period_ns: int) -> int:
    """Start of the first PWM period at or after ``t_ns``: when a newly written duty applies."""
    return -(-t_ns // period_ns) * period_ns


def orifice_flow(conductance: float, dp_pa: float) -> float:
    """Turbulent orifice flow in m^3/s, signed like ``dp_pa``: ``Q = g * sqrt(|dp|)``.

    ``conductance`` is ``K * opening`` in m^3/(s*sqrt(Pa)).
    """
    return math.copysign(conductance * math.sqrt(abs(dp_pa)), dp_pa)


@dataclass(frozen=True, slots=True)
class Valve:
    """One joint's servo valve.

    lap_pos_pct, lap_neg_pct: spool overlap for positive and negative duty, % of stroke.
    flow_coeff: K_a, m^3/(s*sqrt(Pa)) per metering edge of port a at full opening.
    flow_coeff_b: K_b, the same for port b.
    null_leak: laminar leakage conductance per metering edge, m^3/(s*Pa).
    spool_time_s: first-order time constant of the spool following the duty.
    """

    lap_pos_pct: float
    lap_neg_pct: float
    flow_coeff: float
    flow_coeff_b: float
    null_leak: float
    spool_time_s: float

    @classmethod
    def from_ratings(cls, *, lap_pos_pct: float, lap_neg_pct: float, rated_lpm: float,
                     rated_drop_pa: float, b_ratio: float, null_leak_lpm: float,
                     supply_pa: float, spool_time_s: float) -> Valve:
        """Build from catalogue figures.

        rated_lpm: flow through port a at full opening with ``rated_drop_pa`` across
        the valve (two edges); port b passes ``b_ratio`` times as much.
        null_leak_lpm: leakage P->T of the centred valve at ``supply_pa``; a centred
        spool passes it through two edges in series on each of two ports, so each
        edge's conductance is ``Q_null / supply``.
        """
        flow_coeff = rated_lpm * LPM / math.sqrt(rated_drop_pa / 2.0)
        return cls(
            lap_pos_pct=lap_pos_pct,
            lap_neg_pct=lap_neg_pct,
            flow_coeff=flow_coeff,
            flow_coeff_b=b_ratio * flow_coeff,
            null_leak=null_leak_lpm * LPM / supply_pa,
            spool_time_s=spool_time_s,
        )

    def edge_leaks(self, spool_pct: float, polarity: float) -> tuple[float, float]:
        """Leak conductance of the supply-to-``a`` and ``a``-to-tank edges, in units of
        ``null_leak``, with pressure gain (``b``'s edges are the same two the other way).

        ``z`` is the spool's travel towards feeding chamber ``a``, in overlap widths:
        inside the overlap the edges leak ``1 + z`` and ``1 - z``; past it the opened edge's
        leak fades from 2 to 0 over one more width and the closed edge's is 0.
        """
        lap = self.lap_pos_pct if spool_pct > 0.0 else self.lap_neg_pct
        if lap <= 0.0:
            return (0.0, 0.0) if spool_pct else (1.0, 1.0)
        z = polarity * spool_pct / lap
        if z > 1.0:
            return (4.0 - 2.0 * z if z < 2.0 else 0.0), 0.0
        if z < -1.0:
            return 0.0, (4.0 + 2.0 * z if z > -2.0 else 0.0)
        return 1.0 + z, 1.0 - z

    def opening(self, spool_pct: float) -> float:
        """Signed metering opening, fraction of full spool stroke past the overlap.

        Positive for positive duty; zero anywhere inside the overlap.
        """
        if spool_pct > self.lap_pos_pct:
            return (spool_pct - self.lap_pos_pct) / 100.0
        if spool_pct < -self.lap_neg_pct:
            return (spool_pct + self.lap_neg_pct) / 100.0
        return 0.0
