"""The hydraulic supply: a power-limited pump charging a gas accumulator, feeding every valve.

Sections 3.2.5 and 4.6.1: the rig's swash pump holds a set pressure (14–20 MPa,
Figure 3.2 was measured at 13.3 MPa) through an accumulator "that allows the
actuator to operate beyond the flow capacity of the pump for short periods";
the Unimate's vane pump has a 7.5 kW motor and an accumulator precharged with
nitrogen to 3.5 MPa "so that the system pressure will be maintained when flow
demand exceeds pump output".

Model (SI, gauge pressures; the gas law uses absolute ones):

* The pump is pressure-compensated at the nominal pressure ``p_n`` and limited
  by its power and its displacement: it delivers
  ``Q_pump(p) = min(Q_max, eta P_motor / p)`` while ``p < p_n``, and only what
  is drawn at ``p_n``.
* The accumulator's gas, ``V_0`` at the precharge ``p_0``, follows
  ``(p + p_atm) V^n = const`` (n = 1 isothermal … 1.4 adiabatic). Above ``p_0``
  it holds ``V_0 - V(p)`` of oil, so its capacitance is
  ``dV_oil/dp = V(p) / (n (p + p_atm))``; at or below ``p_0`` it is empty and
  only the line's oil (``V_line / beta``) is left to buffer the valves.
* ``C(p) dp/dt = Q_pump(p) - Q_valves``. Each plant step takes the valves' draw
  of that step and advances ``p`` by backward Euler linearised about the present
  pressure (the draw treated as an orifice flow, ``dQ/dp = Q / 2p``), so an empty
  accumulator (a stiff line) cannot ring.

A machine file without ``pump_kw`` has an ideal supply: the pressure stays at
``supply_mpa`` whatever is drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

ATMOSPHERE_PA = 101_325.0


@dataclass(frozen=True, slots=True)
class PumpParams:
    """Pump, accumulator and line, SI: Pa, W, m^3, m^3/s."""

    power_w: float  # hydraulic: motor power times overall efficiency
    max_flow: float  # displacement times speed
    gas_volume: float  # accumulator gas volume at the precharge
    precharge_pa: float
    gas_exponent: float
    line_compliance: float  # line oil volume / bulk modulus, m^3/Pa

    def capacitance(self, p: float) -> float:
        """dV/dp of the oil the supply side stores at pressure ``p``, m^3/Pa."""
        if p <= self.precharge_pa:
            return self.line_compliance
        absolute = p + ATMOSPHERE_PA
        gas = self.gas_volume * ((self.precharge_pa + ATMOSPHERE_PA) / absolute) ** (
            1.0 / self.gas_exponent)
        return gas / (self.gas_exponent * absolute) + self.line_compliance


class Supply:
    """The supply pressure, Pa, advanced once a plant step from the valves' draw."""

    __slots__ = ("_pump", "nominal", "pressure")

    def __init__(self, nominal_pa: float, pump: PumpParams | None) -> None:
        self.nominal = nominal_pa
        self._pump = pump
        self.pressure = nominal_pa

    def step(self, h: float, drawn: float) -> None:
        """Advance ``h`` seconds in which the valves drew ``drawn`` m^3 (negative: returned)."""
        pump = self._pump
        if pump is None:
            return
        p = self.pressure
        demand = drawn / h
        flow = pump.max_flow
        slope = 0.0  # -dQ_pump/dp
        if p > 0.0 and pump.power_w < flow * p:
            flow = pump.power_w / p
            slope = flow / p
        if demand <= flow and p >= self.nominal:
            return  # the compensator holds the nominal pressure
        if demand > 0.0 and p > 0.0:
            slope += demand / (2.0 * p)
        p += h * (flow - demand) / (pump.capacitance(p) + h * slope)
        self.pressure = min(max(p, 0.0), self.nominal)
