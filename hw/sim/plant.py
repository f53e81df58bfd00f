"""Actuator and joint dynamics of both machines: valve, two oil columns, load, stops.

Every joint is the same physical model with its own numbers (the machine file's
``[plant]`` and ``[joints.plant]`` sections, documented in docs/simulator.md):

* A servo valve (:mod:`hw.sim.valve`) feeds one chamber from supply ``ps`` and
  drains the other to tank. Chamber ``a`` drives the joint towards larger
  readings, chamber ``b`` towards smaller; positive duty feeds ``a`` when the
  joint's valve polarity is +1 and ``b`` when it is -1. The Unimate's In/Out
  ram has system pressure on its rod side at all times (section 4.6.1): its
  chamber ``b`` is tied to supply and the valve meters chamber ``a`` only.
* Each chamber is a column of compressible oil (section 3.6.1, Figure 3.10):
  ``dp/dt = beta / V * (Q_valve + Q_leak - dV/dt)`` with
  ``V = V_dead + D * stroke used``. ``D`` is the piston area (prismatic, m^3/m)
  or the displacement per radian of a rack-and-pinion, lever or motor drive
  (revolute, m^3/rad).
* The load: ``M dv/dt = p_a D_a - p_b D_b + F_gravity - F_viscous - F_friction``,
  Stribeck friction: stiction at rest (breakaway), falling to Coulomb with speed.
  Gravity is ``-m g sin(incline)`` on a prismatic joint
  (the rig's vertical ram: ``-(m_ram + load) g``) and ``-G cos(q + phase)`` on a
  revolute one (Up/Down lifting the arm). Hard end stops at the joint limits
  stop the load dead.

Integration is semi-implicit with plain floats (measured about eight times
faster than numpy arrays over six joints): each step solves the chamber
pressures by backward Euler in closed form, the orifice law included, so a
wide-open valve into a small volume cannot go unstable; then the velocity from
the new pressures (symplectic Euler for the mass on the oil spring), Coulomb
friction and stiction implicitly, and the position. The steady state of the
discrete equations is the steady state of the continuous ones, so the
velocity-vs-duty lines do not depend on the step.

Calibration of the rig against Figure 3.2 (eq. 3.1, 3.2; 13.3 MPa, 300 kg)
--------------------------------------------------------------------------
Rod side below the piston (``a``, A_a = 0.887e-3 m^2), full bore above
(``b``, A_b = 2.027e-3 m^2), weight W = m g hanging on the rod, Coulomb
friction F, valve edges K_a on port a and K_b on port b. In steady motion
each chamber's flow passes one metering edge, ``A v = K o sqrt(dp)``, and the
forces balance. Eliminating the pressures, with ``o = (|duty| - lap) / 100``:

    up:    v = o sqrt((ps A_a - W - F) / (A_a^3 / K_a^2 + A_b^3 / K_b^2))
    down:  v = o sqrt((ps A_b + W - F) / (A_a^3 / K_a^2 + A_b^3 / K_b^2))

Both are straight lines in the duty, as the thesis measured, crossing zero at
the overlaps: 0.0056/0.64 = 0.875 % up, 0.0056/1.19 = 0.471 % down.

* Their ratio does not depend on the valve: with 300 kg of weights and 12 kg
  of rod, piston and carrier it is 0.5395 without friction, the load and the
  areas alone (section 3.3 says as much); F = 75 N of seal and guide friction
  makes it 0.64/1.19 = 0.5378.
* With a symmetric valve the cap side would have to fall to -0.33 MPa going
  down: the oil cavitates and the down line turns into a meter-out line set
  by the load alone (slope 1.31, not 1.19). A valve whose b port passes at
  least 1.15 times the a port keeps both chambers above tank pressure; the
  rig's is taken as the usual 2:1 valve for a differential cylinder.
* The up slope 0.64 m/s then fixes K_a = 3.63e-7 m^3/(s sqrt(Pa)): port a
  rated 40.7 L/min at 7 MPa, port b 81.4 L/min.

The valve's tare flow (0.1 L/min, with pressure gain across the overlap) is
gone beyond twice the overlap, so it does not move the lines above 2 % duty;
the bounce damping (``column_loss``) does not move them at all. The supply
(:mod:`hw.sim.supply`) is the pump and accumulator's, read by every chamber
each step; each actuator adds up the oil it draws for the plant to hand on.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from hw.machine import Joint, Machine, MachineError
from hw.sim.supply import PumpParams, Supply
from hw.sim.valve import LPM, Valve
from hw.transmission import Transmission

GRAVITY = 9.81  # m/s^2
VAPOUR_PA = -1.0e5  # gauge pressure at which oil cavitates (absolute zero)
STEP_S = 1.0e-3  # nominal plant step; each actuator subdivides it as its stability needs
MIN_STEP_S = 10e-6  # an oil column stiffer than this would take 100 steps a millisecond

# machine-level [plant] keys; the lamp_* and photocell_* keys are read by hw.sim.encoders
MACHINE_KEYS = {"supply_mpa", "relief_mpa", "bulk_modulus_mpa", "column_loss_ms",
                "spool_time_ms", "valve_rated_drop_mpa", "pump_kw", "pump_efficiency",
                "pump_max_lpm", "accumulator_l", "precharge_mpa", "gas_exponent", "line_volume_l",
                "lamp_cool_ms", "lamp_ripple", "photocell_spread"}
COMMON_KEYS = {"dead_volume_a_m3", "dead_volume_b_m3", "valve_rated_lpm", "valve_b_ratio",
               "null_leak_lpm", "overlap_pos_pct", "overlap_neg_pct", "b_at_supply",
               "pressure_gain"}
PRISMATIC_KEYS = {"area_a_m2", "area_b_m2", "mass_kg", "load_kg", "load_min_kg", "load_max_kg",
                  "incline_deg", "coulomb_n", "stiction_n", "viscous_n_s_per_m",
                  "stribeck_mm_per_s"}
REVOLUTE_KEYS = {"disp_a_m3_per_rad", "disp_b_m3_per_rad", "inertia_kgm2", "gravity_nm",
                 "gravity_phase_deg", "coulomb_nm", "stiction_nm", "viscous_nm_s_per_rad",
                 "stribeck_deg_per_s"}


# The physical range of every key, in the key's units (docs/machines.md gives the reasons).
RANGES = {
    "supply_mpa": (1.0, 35.0), "relief_mpa": (1.0, 50.0), "bulk_modulus_mpa": (100.0, 2500.0),
    "column_loss_ms": (0.0, 100.0), "spool_time_ms": (0.1, 100.0),
    "valve_rated_drop_mpa": (0.5, 35.0),
    "pump_kw": (0.1, 1000.0), "pump_efficiency": (0.1, 1.0), "pump_max_lpm": (0.1, 5000.0),
    "accumulator_l": (0.01, 1000.0), "precharge_mpa": (0.1, 35.0), "gas_exponent": (1.0, 1.4),
    "line_volume_l": (0.01, 100.0),
    "lamp_cool_ms": (1.0, 1000.0), "lamp_ripple": (0.001, 0.5), "photocell_spread": (0.0, 0.9),
    "dead_volume_a_m3": (1e-6, 0.1), "dead_volume_b_m3": (1e-6, 0.1),
    "valve_rated_lpm": (0.1, 1000.0), "valve_b_ratio": (0.1, 10.0), "null_leak_lpm": (0.0, 10.0),
    "overlap_pos_pct": (0.0, 99.0), "overlap_neg_pct": (0.0, 99.0), "b_at_supply": (0.0, 1.0),
    "pressure_gain": (0.0, 1.0), "stribeck_mm_per_s": (0.0, 1e4), "stribeck_deg_per_s": (0.0, 1e4),
    "area_a_m2": (1e-5, 1.0), "area_b_m2": (1e-5, 1.0), "mass_kg": (0.1, 1e5),
    "load_kg": (0.0, 1e5), "load_min_kg": (0.0, 1e5), "load_max_kg": (0.0, 1e5),
    "incline_deg": (-90.0, 90.0), "coulomb_n": (0.0, 1e6), "stiction_n": (0.0, 1e6),
    "viscous_n_s_per_m": (0.0, 1e7),
    "disp_a_m3_per_rad": (1e-7, 0.1), "disp_b_m3_per_rad": (1e-7, 0.1),
    "inertia_kgm2": (1e-3, 1e5), "gravity_nm": (0.0, 1e6), "gravity_phase_deg": (-180.0, 180.0),
    "coulomb_nm": (0.0, 1e6), "stiction_nm": (0.0, 1e6), "viscous_nm_s_per_rad": (0.0, 1e6),
}


class PlantKeys:
    """Typed reads from one ``plant`` mapping; every error names the file and the key."""

    def __init__(self, machine: Machine, where: str, table: Mapping[str, float],
                 allowed: set[str]) -> None:
        self.file = machine.path.name
        self.machine = machine.name
        self.where = where
        self.table = table
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise MachineError(f"{self.file}: {where}: unknown key(s) {', '.join(unknown)}; "
                               f"allowed: {', '.join(sorted(allowed))}")

    def fail(self, name: str, what: str) -> MachineError:
        return MachineError(f"{self.file}: {self.where}.{name}: {what}")

    def number(self, name: str, default: float | None = None, *, at_least: str = "",
               low: float = -math.inf, high: float = math.inf) -> float:
        """Key ``name`` within its range in ``RANGES`` and within ``low``…``high``
        (``at_least`` names the key that sets ``low``)."""
        if name not in self.table:
            if default is None:
                raise self.fail(name, "missing number")
            return default
        value = self.table[name]
        low, high = max(low, RANGES[name][0]), min(high, RANGES[name][1])
        if not low <= value <= high:
            because = f", at least {at_least}" if at_least else ""
            raise self.fail(name, f"{value:g} out of range (must be in {low:g}…{high:g}"
                                  f"{because})")
        return value


@dataclass(frozen=True)
class Hydraulics:
    """Machine-wide hydraulic numbers, SI: pressures and bulk modulus in Pa, times in s.

    relief_pa: relief valve setting; a chamber pressure never exceeds it.
    column_loss_s: Kelvin-Voigt loss of the oil columns (see ``Actuator.step``).
    pump: the pump and accumulator (``hw.sim.supply``); None for an ideal supply.
    """

    supply_pa: float
    relief_pa: float
    bulk_modulus_pa: float
    column_loss_s: float
    spool_time_s: float
    rated_drop_pa: float
    pump: PumpParams | None = None
    tank_pa: float = 0.0

    @classmethod
    def from_machine(cls, machine: Machine, supply_mpa: float | None = None) -> Hydraulics:
        keys = PlantKeys(machine, "plant", machine.plant, MACHINE_KEYS)
        supply = keys.number("supply_mpa")
        if supply_mpa is not None:
            low, high = RANGES["supply_mpa"]
            if not low <= supply_mpa <= high:
                raise ValueError(f"supply pressure {supply_mpa:g} MPa is outside {low:g}…"
                                 f"{high:g} MPa (machine {machine.name})")
            supply = supply_mpa
        relief = keys.number("relief_mpa", math.inf, at_least="supply_mpa", low=supply)
        bulk = keys.number("bulk_modulus_mpa") * 1e6
        return cls(
            supply_pa=supply * 1e6,
            relief_pa=relief * 1e6,
            bulk_modulus_pa=bulk,
            column_loss_s=keys.number("column_loss_ms", 0.0) / 1e3,
            spool_time_s=keys.number("spool_time_ms") / 1e3,
            rated_drop_pa=keys.number("valve_rated_drop_mpa") * 1e6,
            pump=_pump(keys, bulk),
        )


def _pump(keys: PlantKeys, bulk_pa: float) -> PumpParams | None:
    """The file's pump and accumulator; None (an ideal supply) without ``pump_kw``."""
    pump_keys = ("pump_efficiency", "pump_max_lpm", "accumulator_l", "precharge_mpa",
                 "gas_exponent", "line_volume_l")
    if "pump_kw" not in keys.table:
        given = [k for k in pump_keys if k in keys.table]
        if given:
            raise keys.fail(given[0], "needs pump_kw (without it the supply is ideal)")
        return None
    return PumpParams(
        power_w=keys.number("pump_kw") * 1e3 * keys.number("pump_efficiency", 0.85),
        max_flow=keys.number("pump_max_lpm") * LPM,
        gas_volume=keys.number("accumulator_l") * 1e-3,
        precharge_pa=keys.number("precharge_mpa") * 1e6,
        gas_exponent=keys.number("gas_exponent", 1.4),
        line_compliance=keys.number("line_volume_l", 2.0) * 1e-3 / bulk_pa,
    )


@dataclass(frozen=True, slots=True)
class ActuatorParams:
    """One joint's actuator and load, SI: m or rad, m^3, kg or kg m^2, N or N m.

    unit_si: metres per mm or radians per degree (joint units to SI).
    disp_a, disp_b: chamber displacement, m^3 per m or per rad.
    gravity_const, gravity_cos, gravity_phase: F_gravity = const + cos_amp * cos(q + phase).
    """

    unit_si: float
    lower: float
    upper: float
    disp_a: float
    disp_b: float
    dead_a: float
    dead_b: float
    b_at_supply: bool
    mass: float
    gravity_const: float
    gravity_cos: float
    gravity_phase: float
    coulomb: float
    stiction: float
    viscous: float
    stribeck: float  # Stribeck velocity, m/s or rad/s; 0: friction drops to Coulomb at once
    pressure_gain: bool  # the leakage swings across the overlap (Valve.edge_leaks)
    polarity: float  # the transmission's: which chamber positive valve duty feeds
    valve: Valve

    @classmethod
    def from_joint(cls, machine: Machine, index: int, hyd: Hydraulics,
                   load_kg: float | None, polarity: float, *, options: bool = False
                   ) -> ActuatorParams:
        """Joint ``index``'s actuator; ``options`` says the load or the supply pressure is the
        caller's, not the file's (a joint that cannot hold is then a ValueError)."""
        joint = machine.joints[index]
        where = f"joints[{index}].plant"
        if joint.kind == "prismatic":
            keys = PlantKeys(machine, where, joint.plant, COMMON_KEYS | PRISMATIC_KEYS)
            unit_si = 1e-3
            disp_a = keys.number("area_a_m2")
            disp_b = keys.number("area_b_m2")
            bare = keys.number("mass_kg")
            lightest, load = _load(keys, joint, machine, load_kg)
            mass = bare + load
            incline = math.radians(keys.number("incline_deg", 0.0))
            gravity_const, gravity_cos, phase = -mass * GRAVITY * math.sin(incline), 0.0, 0.0
            friction = ("coulomb_n", "stiction_n", "viscous_n_s_per_m", "stribeck_mm_per_s")
        else:
            keys = PlantKeys(machine, where, joint.plant, COMMON_KEYS | REVOLUTE_KEYS)
            unit_si = math.pi / 180.0
            disp_a = keys.number("disp_a_m3_per_rad")
            disp_b = keys.number("disp_b_m3_per_rad")
            bare, lightest = keys.number("inertia_kgm2"), 0.0
            mass = bare
            gravity_const, gravity_cos = 0.0, -keys.number("gravity_nm", 0.0)
            phase = math.radians(keys.number("gravity_phase_deg", 0.0))
            friction = ("coulomb_nm", "stiction_nm", "viscous_nm_s_per_rad",
                        "stribeck_deg_per_s")
        coulomb = keys.number(friction[0])
        b_at_supply = keys.number("b_at_supply", 0.0)
        if b_at_supply not in (0.0, 1.0):
            raise keys.fail("b_at_supply", f"must be 0 or 1, got {b_at_supply:g}")
        pressure_gain = keys.number("pressure_gain", 0.0)
        if pressure_gain not in (0.0, 1.0):
            raise keys.fail("pressure_gain", f"must be 0 or 1, got {pressure_gain:g}")
        params = cls(
            unit_si=unit_si,
            lower=joint.lower * unit_si,
            upper=joint.upper * unit_si,
            disp_a=disp_a,
            disp_b=disp_b,
            dead_a=keys.number("dead_volume_a_m3"),
            dead_b=0.0 if b_at_supply else keys.number("dead_volume_b_m3"),
            b_at_supply=bool(b_at_supply),
            mass=mass,
            gravity_const=gravity_const,
            gravity_cos=gravity_cos,
            gravity_phase=phase,
            coulomb=coulomb,
            stiction=keys.number(friction[1], coulomb, at_least=friction[0], low=coulomb),
            viscous=keys.number(friction[2], 0.0),
            stribeck=keys.number(friction[3], 0.0) * unit_si,
            pressure_gain=bool(pressure_gain),
            polarity=polarity,
            valve=_valve(keys, joint, machine, hyd),
        )
        params.check_stiffness(hyd, bare + lightest, keys)
        params.check_holds(hyd, joint, keys, options)
        return params

    def stable_step(self, hyd: Hydraulics, mass: float) -> float:
        """Longest step, s, that integrates the stiffest oil column on ``mass`` stably with
        margin 2.

        The step is symplectic Euler on the mass and oil spring plus an explicit
        loss term; it is stable while ``omega^2 h (h + 2 loss) < 4``, and omega is
        largest at an end of the stroke, where a chamber holds only its dead volume.
        """
        stiffness = (self.disp_a**2 / self.dead_a
                     + (0.0 if self.b_at_supply else self.disp_b**2 / self.dead_b))
        omega2 = hyd.bulk_modulus_pa * stiffness / mass
        loss = hyd.column_loss_s
        return -loss + math.sqrt(loss**2 + 2.0 / omega2)

    def check_stiffness(self, hyd: Hydraulics, lightest: float, keys: PlantKeys) -> None:
        """Refuse oil columns too stiff to simulate: they must take steps of ``MIN_STEP_S``
        or longer, even with the lightest load the file allows (``lightest``, kg or kg m²)."""
        step = self.stable_step(hyd, lightest)
        if step < MIN_STEP_S:
            raise MachineError(f"{keys.file}: {keys.where}: its oil columns ring too fast to "
                               f"simulate: they need steps of {step * 1e6:.3g} µs, the "
                               f"simulator's shortest is {MIN_STEP_S * 1e6:g} µs: more mass or "
                               f"dead volume, or less area, bulk_modulus_mpa or column_loss_ms")

    def check_holds(self, hyd: Hydraulics, joint: Joint, keys: PlantKeys, options: bool) -> None:
        """Raise if the supply cannot hold the joint against its largest gravity load: a
        MachineError naming the key when the numbers are the file's, else a ValueError."""
        if self.b_at_supply and self.disp_a <= self.disp_b:
            raise MachineError(f"{keys.file}: {keys.where}: with b_at_supply the a side must "
                               f"be the larger")
        push_up = hyd.supply_pa * (self.disp_a - self.disp_b if self.b_at_supply else self.disp_a)
        push_down = hyd.supply_pa * self.disp_b
        pull_down = abs(self.gravity_cos) - self.gravity_const
        pull_up = abs(self.gravity_cos) + self.gravity_const
        ratio = max(pull_down / push_up, pull_up / push_down)
        if ratio < 1.0:
            return
        needs = (f"{joint.name} cannot hold its load: it needs more than "
                 f"{ratio * hyd.supply_pa / 1e6:.1f} MPa, the supply is "
                 f"{hyd.supply_pa / 1e6:g} MPa")
        if options:
            raise ValueError(f"{needs} (machine {keys.machine})")
        raise MachineError(f"{keys.file}: {keys.where}: {needs} (plant.supply_mpa): raise the "
                           f"supply, or give the joint more area or less load")

    def gravity(self, q: float) -> float:
        """Gravity force or moment on the joint at position ``q`` (SI), towards larger readings."""
        return self.gravity_const + self.gravity_cos * math.cos(q + self.gravity_phase)


def _load(keys: PlantKeys, joint: Joint, machine: Machine, load_kg: float | None
          ) -> tuple[float, float]:
    """The lightest payload the file allows on a prismatic joint, and the one it carries: the
    option's, else the file's ``load_kg`` (default the lightest)."""
    low = keys.number("load_min_kg", 0.0)
    high = keys.number("load_max_kg", RANGES["load_max_kg"][1], at_least="load_min_kg", low=low)
    load = (keys.number("load_kg", low, at_least="load_min_kg", low=low, high=high)
            if load_kg is None else load_kg)
    if not low <= load <= high:
        raise ValueError(f"{joint.name} load {load:g} kg is outside {low:g}…{high:g} kg "
                         f"(machine {machine.name})")
    return low, load


def _valve(keys: PlantKeys, joint: Joint, machine: Machine, hyd: Hydraulics) -> Valve:
    """The joint's valve; the overlap defaults to the measured minimum PWM (section 5.4.1).

    A joint starts moving at ``min_pwm`` and not one PWM step below it, so the
    overlap sits half a step under it.
    """
    half_step = machine.valve_resolution_pct / 2.0
    return Valve.from_ratings(
        lap_pos_pct=keys.number("overlap_pos_pct", max(joint.min_pwm_pos - half_step, 0.0)),
        lap_neg_pct=keys.number("overlap_neg_pct", max(joint.min_pwm_neg - half_step, 0.0)),
        rated_lpm=keys.number("valve_rated_lpm"),
        rated_drop_pa=hyd.rated_drop_pa,
        b_ratio=keys.number("valve_b_ratio", 1.0),
        null_leak_lpm=keys.number("null_leak_lpm", 0.0),
        supply_pa=hyd.supply_pa,
        spool_time_s=hyd.spool_time_s,
    )


class Actuator:
    """State and integration step of one valve-controlled actuator and its load.

    State: ``q`` position (m or rad), ``v`` velocity, ``pa``/``pb`` chamber
    pressures (Pa), ``spool`` in % of stroke (= duty). The spool follows
    ``target``; a new command waits ``switch_in`` seconds (the rest of the
    current PWM period) before it becomes the target. The valve is fed from
    ``supply``; ``drawn`` adds up the oil it took from it (m^3) until the plant
    collects it.
    """

    __slots__ = ("_beta", "_decay", "_decay_h", "_force", "_loss", "_max_h", "_p", "_pt",
                 "_relief", "_supply", "drawn", "next_target", "pa", "pb", "q", "spool",
                 "switch_in", "target", "v")

    def __init__(self, params: ActuatorParams, hyd: Hydraulics, q: float,
                 supply: Supply | None = None) -> None:
        self._p = params
        self._supply = Supply(hyd.supply_pa, None) if supply is None else supply
        self.drawn = 0.0
        self._pt = hyd.tank_pa
        self._relief = hyd.relief_pa
        self._beta = hyd.bulk_modulus_pa
        self._loss = hyd.column_loss_s
        self._decay_h = 0.0
        self._decay = 1.0
        self.q = q
        self.v = 0.0
        self.spool = 0.0
        self.target = 0.0
        self.next_target = 0.0
        self.switch_in = math.inf
        self.pa, self.pb = self.holding_pressures(q)
        self._force = self.pa * params.disp_a - self.pb * params.disp_b
        self._max_h = params.stable_step(hyd, params.mass)

    def holding_pressures(self, q: float) -> tuple[float, float]:
        """Chamber pressures that hold the load still at ``q``, nearest to half supply each."""
        p, ps = self._p, self._supply.nominal
        load = -p.gravity(q)
        if p.b_at_supply:
            return min(max((load + ps * p.disp_b) / p.disp_a, 0.0), ps), ps
        mu = (load - 0.5 * ps * (p.disp_a - p.disp_b)) / (p.disp_a**2 + p.disp_b**2)
        return (min(max(0.5 * ps + mu * p.disp_a, 0.0), ps),
                min(max(0.5 * ps - mu * p.disp_b, 0.0), ps))

    def command(self, spool_pct: float, delay_s: float) -> None:
        """Make ``spool_pct`` the spool's target after ``delay_s`` seconds (0: at once)."""
        if delay_s <= 0.0:
            self.target = spool_pct
            self.switch_in = math.inf
        else:
            self.next_target = spool_pct
            self.switch_in = delay_s

    def step(self, h: float) -> None:
        """Advance by ``h`` seconds, in as many equal steps as stability needs."""
        if h <= self._max_h:
            self._step(h)
            return
        n = math.ceil(h / self._max_h)
        for _ in range(n):
            self._step(h / n)

    def _step(self, h: float) -> None:
        """One integration step of ``h`` seconds.

        The oil columns push with ``F = p_a D_a - p_b D_b`` plus a loss term
        ``column_loss * dF/dt`` (a Kelvin-Voigt column: hose walls and entrained
        air dissipate as the oil is compressed). It damps the mass on the oil
        spring, ``zeta = omega_h * column_loss / 2``, and vanishes in any steady
        state, so it leaves the velocity-vs-duty lines alone.
        """
        p = self._p
        valve = p.valve
        self._step_spool(h, valve.spool_time_s)
        opening = valve.opening(self.spool) * p.polarity
        open_fraction = abs(opening)
        ps, pt, q, v = self._supply.pressure, self._pt, self.q, self.v
        leak = valve.null_leak
        a_in = a_out = b_in = b_out = leak
        if p.pressure_gain:
            feed, drain = valve.edge_leaks(self.spool, p.polarity)
            a_in, a_out, b_in, b_out = leak * feed, leak * drain, leak * drain, leak * feed
        g_a = valve.flow_coeff * open_fraction
        pa = _chamber(self.pa, h * self._beta / (p.dead_a + p.disp_a * (q - p.lower)),
                      a_in, a_out, ps, pt, p.disp_a * v, g_a, ps if opening > 0.0 else pt)
        pa = pa if pa < self._relief else self._relief
        drawn = a_in * (ps - pa)
        if opening > 0.0:
            drawn += math.copysign(g_a * math.sqrt(abs(ps - pa)), ps - pa)
        self.pa = pa
        if p.b_at_supply:
            self.pb = ps
        else:
            g_b = valve.flow_coeff_b * open_fraction
            pb = _chamber(self.pb, h * self._beta / (p.dead_b + p.disp_b * (p.upper - q)),
                          b_in, b_out, ps, pt, -p.disp_b * v, g_b, ps if opening < 0.0 else pt)
            pb = pb if pb < self._relief else self._relief
            drawn += b_in * (ps - pb)
            if opening < 0.0:
                drawn += math.copysign(g_b * math.sqrt(abs(ps - pb)), ps - pb)
            self.pb = pb
        column = self.pa * p.disp_a - self.pb * p.disp_b
        force = column + self._loss * (column - self._force) / h + p.gravity_const
        self._force = column
        if p.gravity_cos:
            force += p.gravity_cos * math.cos(q + p.gravity_phase)
        v = _friction_step(v, force, h, p.mass, p.coulomb, p.stiction, p.viscous, p.stribeck)
        q += h * v
        if q < p.lower:
            q, v = p.lower, 0.0
        elif q > p.upper:
            q, v = p.upper, 0.0
        if p.b_at_supply:
            drawn -= p.disp_b * v  # the rod side, tied to supply, fills or gives back
        self.drawn += h * drawn
        self.q, self.v = q, v

    def _step_spool(self, h: float, tau: float) -> None:
        """First-order lag toward the target, switching target mid-step when the PWM period ends."""
        if self.switch_in <= h + 1e-12:  # the clock's ns grid, seen through float seconds
            t1 = self.switch_in
            s = self.target + (self.spool - self.target) * math.exp(-t1 / tau)
            self.target = self.next_target
            self.switch_in = math.inf
            self.spool = self.target + (s - self.target) * math.exp((t1 - h) / tau)
            return
        self.switch_in -= h
        if h != self._decay_h:
            self._decay_h, self._decay = h, math.exp(-h / tau)
        self.spool = self.target + (self.spool - self.target) * self._decay


def _chamber(p0: float, c: float, leak_in: float, leak_out: float, ps: float, pt: float,
             dvdt: float, conductance: float, source: float) -> float:
    """Backward-Euler chamber pressure after one step, solved in closed form.

    The orifice term is :func:`hw.sim.valve.orifice_flow` from ``source`` into the chamber.

    Solves ``p = p0 + c * (g_in (ps - p) + g_out (pt - p) - dV/dt + g sign(src - p) sqrt|src - p|)``
    with ``c = h beta / V``: the leak terms fold into ``p0`` and ``c``, the orifice
    term is a quadratic in ``s = sqrt|src - p|``, taken with its stable root.
    """
    den = 1.0 + c * (leak_in + leak_out)
    free = (p0 + c * (leak_in * ps + leak_out * pt - dvdt)) / den
    a = c * conductance / den
    d = free - source
    if d > 0.0:
        s = 2.0 * d / (a + math.sqrt(a * a + 4.0 * d))
        p = source + s * s
    elif d < 0.0:
        s = -2.0 * d / (a + math.sqrt(a * a - 4.0 * d))
        p = source - s * s
    else:
        p = source
    return p if p > VAPOUR_PA else VAPOUR_PA


def _friction_step(v: float, force: float, h: float, mass: float, coulomb: float,
                   stiction: float, viscous: float, stribeck: float) -> float:
    """New velocity under ``force`` with Stribeck and viscous friction, implicitly in v.

    At rest the load stays stuck while |force| <= stiction (breakaway); moving,
    the friction falls from stiction to Coulomb as ``exp(-(v / stribeck)^2)``
    (``stribeck`` 0: at once), plus ``viscous * v``; a step that would reverse
    the velocity ends at rest instead.
    """
    if v == 0.0:
        if -stiction <= force <= stiction:
            return 0.0
        level = stiction if stribeck > 0.0 else coulomb
        return h * (force - math.copysign(level, force)) / (mass + h * viscous)
    level = coulomb
    if stribeck > 0.0:
        r = v / stribeck
        if -6.0 < r < 6.0:  # beyond, exp(-r^2) < 1e-15
            level += (stiction - coulomb) * math.exp(-r * r)
    v1 = (mass * v + h * (force - math.copysign(level, v))) / (mass + h * viscous)
    return 0.0 if v1 * v < 0.0 else v1


class Plant:
    """All joints of a machine: actuator coordinates, transmissions and one ``step`` for all.

    Actuator coordinates are what each encoder measures; the machine's
    transmission (``hw.transmission``) maps them to joint readings (the Yaw
    chain drive runs through the Bend joint) and gives each valve's polarity.
    Hard end stops act on the actuator, at the joint's limits.
    """

    def __init__(self, machine: Machine, *, initial: Sequence[float] | None = None,
                 load_kg: float | None = None, supply_mpa: float | None = None) -> None:
        self.transmission = Transmission(machine)
        self.hydraulics = Hydraulics.from_machine(machine, supply_mpa)
        self.supply = Supply(self.hydraulics.supply_pa, self.hydraulics.pump)
        options = load_kg is not None or supply_mpa is not None
        self.params = tuple(ActuatorParams.from_joint(machine, i, self.hydraulics, load_kg,
                                                      self.transmission.polarity[i],
                                                      options=options)
                            for i in range(machine.n_joints))
        start = self.actuator_start(machine, initial)
        self.actuators = tuple(Actuator(p, self.hydraulics, a * p.unit_si, self.supply)
                               for p, a in zip(self.params, start, strict=True))
        self._actuator = [0.0] * machine.n_joints

    def actuator_start(self, machine: Machine, initial: Sequence[float] | None) -> list[float]:
        """Actuator coordinates (joint units) of joint positions ``initial``, default mid-range."""
        if initial is None:
            q = [0.5 * (j.lower + j.upper) for j in machine.joints]
        else:
            q = [float(v) for v in initial]
            if len(q) != machine.n_joints:
                raise ValueError(f"expected {machine.n_joints} initial positions for "
                                 f"{machine.name}, got {len(q)}")
        a = [0.0] * machine.n_joints
        self.transmission.actuators_from_joints(q, a)
        for i, (joint, value) in enumerate(zip(machine.joints, a, strict=True)):
            if joint.lower <= value <= joint.upper:
                continue
            outside = (f"{joint.name} initial actuator position {value:g}{joint.symbol} is "
                       f"outside {joint.limit_text()}")
            if initial is not None:
                raise ValueError(f"{outside} (machine {machine.name})")
            raise MachineError(f"{machine.path.name}: joints[{i}].encoder.coupling: {outside} "
                               f"with every joint mid-range, where the simulator starts: the "
                               f"coupling is too large for these limits")
        return a

    def step(self, h: float) -> None:
        """Advance every joint by ``h`` seconds, then the supply by what they drew."""
        drawn = 0.0
        for actuator in self.actuators:
            if h <= actuator._max_h:  # Actuator.step's one step, without its call
                actuator._step(h)
            else:
                actuator.step(h)
            drawn += actuator.drawn
            actuator.drawn = 0.0
        self.supply.step(h, drawn)

    def actuator_positions(self, out: list[float]) -> None:
        """Fill ``out`` with actuator positions in joint units (mm, degrees)."""
        for i, (actuator, p) in enumerate(zip(self.actuators, self.params, strict=True)):
            out[i] = actuator.q / p.unit_si

    def joint_positions(self, out: list[float]) -> None:
        """Fill ``out`` with joint positions in joint units, couplings included."""
        self.actuator_positions(self._actuator)
        self.transmission.joints_from_actuators(self._actuator, out)

    def joint_velocities(self, out: list[float]) -> None:
        """Fill ``out`` with joint velocities in joint units per second, couplings included."""
        for i, (actuator, p) in enumerate(zip(self.actuators, self.params, strict=True)):
            self._actuator[i] = actuator.v / p.unit_si
        self.transmission.joints_from_actuators(self._actuator, out)
