"""Plant dynamics: the thesis's measured numbers come out of the model."""

from __future__ import annotations

from pathlib import Path

import pytest

from hw.machine import Machine, MachineError, load_machine, parse_machine
from hw.sim import check_plant
from hw.sim.plant import Plant, _friction_step
from hw.sim.valve import quantise_duty

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
MACHINES = Path(__file__).resolve().parents[3] / "hw" / "machines"
STEP = 1e-3


def drive(plant: Plant, duty: dict[int, float], seconds: float) -> list[list[float]]:
    """Hold ``duty`` (joint -> %) for ``seconds``; joint positions, joint units, every step."""
    for j, d in duty.items():
        plant.actuators[j].command(quantise_duty(d, 1.0), 0.0)
    out = []
    for _ in range(round(seconds / STEP)):
        plant.step(STEP)
        q = [0.0] * len(plant.actuators)
        plant.joint_positions(q)
        out.append(q)
    return out


def steady_speed(machine: Machine, joint: int, duty: float, start: list[float],
                 seconds: float, **options: float) -> float:
    """Velocity over the last 40 % of a run at constant duty, joint units per second."""
    q = [row[joint] for row in drive(Plant(machine, initial=start, **options), {joint: duty},
                                      seconds)]
    i0 = int(len(q) * 0.6)
    return (q[-1] - q[i0]) / ((len(q) - 1 - i0) * STEP)


# -- the rig, Figure 3.2 ---------------------------------------------------------------------

@pytest.mark.parametrize("pwm", [5, 10, 20, 40, 60, 80, 100])
def test_rig_follows_figure_3_2_within_1_percent(pwm: int) -> None:
    # the pump and accumulator feed it: the full-bore side takes 145 L/min at 100 % down
    up = steady_speed(RIG, 0, pwm, [100.0], min(0.9, 0.35 / (0.0064 * pwm))) / 1e3
    down = steady_speed(RIG, 0, -pwm, [1150.0], min(0.9, 0.35 / (0.0119 * pwm))) / 1e3
    assert up == pytest.approx(0.64 * pwm / 100 - 0.0056, rel=0.01)  # eq. 3.1
    assert down == pytest.approx(1.19 * -pwm / 100 + 0.0056, rel=0.01)  # eq. 3.2


def test_rig_load_changes_the_speeds() -> None:
    light_up = steady_speed(RIG, 0, 40, [100.0], 0.6, load_kg=50.0)
    heavy_up = steady_speed(RIG, 0, 40, [100.0], 0.6, load_kg=300.0)
    light_down = steady_speed(RIG, 0, -40, [1150.0], 0.6, load_kg=50.0)
    heavy_down = steady_speed(RIG, 0, -40, [1150.0], 0.6, load_kg=300.0)
    assert light_up > heavy_up * 1.05
    assert -heavy_down > -light_down * 1.02


def test_higher_supply_is_faster() -> None:
    assert (steady_speed(RIG, 0, 40, [100.0], 0.6, supply_mpa=20.0)
            > 1.1 * steady_speed(RIG, 0, 40, [100.0], 0.6))


def test_rig_mass_bounces_on_the_oil_column() -> None:
    # Figure 3.10: halted quickly, the load oscillates against the compressed oil
    plant = Plant(RIG, initial=[1100.0])
    drive(plant, {0: -40.0}, 0.3)
    q = [row[0] for row in drive(plant, {0: 0.0}, 0.4)]
    low = min(range(len(q)), key=q.__getitem__)
    rebound = max(q[low:]) - q[low]
    assert rebound > 1.0
    assert q[-1] == pytest.approx(q[-20], abs=0.01)


def test_rig_sags_slowly_with_the_valve_closed() -> None:
    # the centred servo valve's tare flow lets the weight creep down, 0.1-1 mm/s
    q = [row[0] for row in drive(Plant(RIG), {0: 0.0}, 5.0)]
    assert -5.0 < q[-1] - 600.0 < -0.5


def starting_spool(load_kg: float) -> float:
    """The least spool opening, % (the amplifier's analogue value, finer than the UPP card's
    1 % steps), that lifts the rig's load at least one encoder count in 2 s, to 0.01 %."""
    def lifts(spool: float) -> bool:
        plant = Plant(RIG, load_kg=load_kg)
        before = drive(plant, {}, 0.3)[-1][0]
        plant.actuators[0].command(spool, 0.0)  # not quantised
        return drive(plant, {}, 2.0)[-1][0] - before >= 0.1
    low, high = 0.0, 2.0
    while high - low > 0.01:
        low, high = (low, (low + high) / 2) if lifts((low + high) / 2) else ((low + high) / 2, high)
    return high


def test_rig_starting_duty_rises_with_load() -> None:
    # section 5.4.1 blames friction for the minimum PWM: breaking the load away needs the
    # chamber pressures to beat weight and stiction, and the valve's pressure gain sets how
    # far into its overlap the spool must go for them
    starts = [starting_spool(load) for load in (50.0, 150.0, 300.0)]
    assert starts[0] < starts[1] < starts[2] < 0.875  # all inside the 0.875 % overlap
    assert starts[2] - starts[0] > 0.05


def test_friction_breaks_away_at_stiction_and_falls_to_coulomb() -> None:
    p = Plant(RIG).params[0]
    assert p.stiction > p.coulomb and p.stribeck > 0
    held = _friction_step(0.0, 0.99 * p.stiction, STEP, p.mass, p.coulomb, p.stiction,
                          p.viscous, p.stribeck)
    assert held == 0.0
    h = 1e-6
    slow = _friction_step(1e-4, 0.0, h, p.mass, p.coulomb, p.stiction, 0.0, p.stribeck)
    fast = _friction_step(0.5, 0.0, h, p.mass, p.coulomb, p.stiction, 0.0, p.stribeck)
    # the friction, from the deceleration: stiction just after breakaway, Coulomb when fast
    assert (1e-4 - slow) * p.mass / h == pytest.approx(p.stiction, rel=1e-3)
    assert (0.5 - fast) * p.mass / h == pytest.approx(p.coulomb, rel=1e-3)


# -- the supply: pump and accumulator --------------------------------------------------------

def test_six_joints_at_full_duty_sag_the_supply_and_it_recovers() -> None:
    # section 4.6.1: a 7.5 kW pump; six joints at full duty draw more than it gives
    plant = Plant(UNIMATE, initial=[1100.0, -100.0, -20.0, -100.0, -100.0, -170.0])
    nominal = plant.supply.pressure
    speeds = []
    for _ in range(6):
        drive(plant, {j: -100.0 for j in range(6)}, 0.25)
        v = [0.0] * 6
        plant.joint_velocities(v)
        speeds.append(v[0])
    assert plant.supply.pressure < nominal - 0.2e6
    assert speeds[-1] < speeds[1] * 0.99  # In/Out slows as the pressure falls
    drive(plant, {j: 0.0 for j in range(6)}, 1.0)
    assert plant.supply.pressure == nominal


# -- the Unimate ------------------------------------------------------------------------------

def home() -> list[float]:
    return [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("joint", range(6))
def test_minimum_pwm_starts_each_joint_each_way(joint: int) -> None:
    # section 5.4.1; polarity -1: positive duty moves towards smaller readings
    spec = UNIMATE.joints[joint]
    for sign, minimum in ((1, spec.min_pwm_pos), (-1, spec.min_pwm_neg)):
        below = drive(Plant(UNIMATE, initial=home()), {joint: sign * (minimum - 1)}, 0.5)
        at = drive(Plant(UNIMATE, initial=home()), {joint: sign * minimum}, 0.5)
        assert below[-1][joint] == pytest.approx(home()[joint], abs=1e-3)
        moved = at[-1][joint] - home()[joint]
        assert moved * sign * spec.polarity > 0.02


@pytest.mark.parametrize("joint", range(6))
def test_full_duty_gives_about_the_rated_speed(joint: int) -> None:
    spec = UNIMATE.joints[joint]
    span = spec.upper - spec.lower
    seconds = 0.3 * span / spec.max_speed
    for duty in (100.0, -100.0):
        start = home()
        towards_lower = duty * spec.polarity < 0
        start[joint] = spec.upper - 0.1 * span if towards_lower else spec.lower + 0.1 * span
        speed = abs(steady_speed(UNIMATE, joint, duty, start, seconds))
        assert speed == pytest.approx(spec.max_speed, rel=0.25)


@pytest.mark.parametrize("joint", range(6))
def test_end_stops_hold_at_the_limits(joint: int) -> None:
    spec = UNIMATE.joints[joint]
    for duty, limit in ((100.0, spec.lower), (-100.0, spec.upper)):
        q = [row[joint] for row in drive(Plant(UNIMATE, initial=home()), {joint: duty},
                                          1.3 * (spec.upper - spec.lower) / spec.max_speed + 0.5)]
        assert q[-1] == pytest.approx(limit, abs=1e-9)
        assert q[-100] == pytest.approx(limit, abs=1e-9)


def test_up_down_gravity_helps_down_and_hinders_up() -> None:
    start = home()
    down = steady_speed(UNIMATE, 2, 60.0, start, 0.4)
    up = steady_speed(UNIMATE, 2, -60.0, start, 0.4)
    assert down < 0 < up
    assert -down > 1.1 * up


def test_up_down_sags_with_the_valves_closed() -> None:
    q = drive(Plant(UNIMATE, initial=home()), {}, 10.0)
    assert -0.1 < q[-1][2] < -0.002
    assert q[-1][:2] + q[-1][3:] == home()[:2] + home()[3:]


def test_yaw_reading_includes_bend() -> None:
    # rtshare.h joint_dep: bending the wrist turns the yaw reading with it
    plant = Plant(UNIMATE, initial=home())
    q = drive(plant, {3: -60.0}, 0.5)[-1]
    assert q[3] > 10.0
    assert q[4] == pytest.approx(q[3])


def test_initial_positions_are_checked_against_the_limits() -> None:
    with pytest.raises(ValueError, match=r"Up/Down initial actuator position 40° is outside"):
        Plant(UNIMATE, initial=[1500.0, 0.0, 40.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="expected 6 initial positions"):
        Plant(UNIMATE, initial=[0.0])


# -- parameters ---------------------------------------------------------------------------

def edited(name: str, old: str, new: str) -> Machine:
    """The machine of built-in file ``name`` with ``old`` replaced, its plant checked as the
    simulator checks it (``check_plant``, before a controller starts): a bad plant number is
    refused there."""
    text = (MACHINES / name).read_text()
    assert old in text
    machine = parse_machine(text.replace(old, new, 1), MACHINES / name)
    check_plant(machine)
    return machine


def test_missing_key_names_file_and_key() -> None:
    with pytest.raises(MachineError,
                       match=r"unimate2000b.toml: joints\[2\].plant.inertia_kgm2: missing number"):
        edited("unimate2000b.toml", "inertia_kgm2 = 120.0\n", "")


def test_key_of_the_wrong_joint_kind_is_refused_with_the_allowed_list() -> None:
    with pytest.raises(MachineError, match=r"rig.toml: joints\[0\].plant: unknown key\(s\) "
                                           r"coulomb_nm; allowed: .*coulomb_n,"):
        edited("rig.toml", "coulomb_n = 75.0", "coulomb_nm = 75.0")


def test_bad_machine_level_value() -> None:
    with pytest.raises(MachineError, match=r"rig.toml: plant.bulk_modulus_mpa: -3 out of range "
                                           r"\(must be in 100…2500\)"):
        edited("rig.toml", "bulk_modulus_mpa = 1000.0", "bulk_modulus_mpa = -3.0")


def test_load_and_supply_options_are_checked() -> None:
    with pytest.raises(ValueError, match=r"Ram load 400 kg is outside 50…300 kg"):
        Plant(RIG, load_kg=400.0)
    with pytest.raises(ValueError, match=r"Ram cannot hold its load: it needs more than 3\.\d MPa"):
        Plant(RIG, supply_mpa=3.0)


def test_pump_keys_need_the_pump() -> None:
    with pytest.raises(MachineError, match=r"unimate2000b.toml: plant.pump_efficiency: needs "
                                           r"pump_kw \(without it the supply is ideal\)"):
        edited("unimate2000b.toml", "pump_kw = 7.5\n", "")
    with pytest.raises(MachineError, match=r"rig.toml: joints\[0\].plant.pressure_gain: must be "
                                           r"0 or 1, got 0.5"):
        edited("rig.toml", "pressure_gain = 1 ", "pressure_gain = 0.5 ")


def full_duty_speed(machine: Machine, joint: int, duty: float) -> float:
    """Steadiest speed of ``joint`` at ``duty`` %: the fastest over 10–90 % of a stroke run
    from the end it leaves (units/s), the other joints shut."""
    spec = machine.joints[joint]
    span = spec.upper - spec.lower
    start = spec.lower + 0.02 * span if duty * spec.polarity > 0 else spec.upper - 0.02 * span
    initial = [0.5 * (j.lower + j.upper) for j in machine.joints]
    initial[joint] = start
    plant = Plant(machine, initial=initial)
    actuator, params = plant.actuators[joint], plant.params[joint]
    actuator.command(quantise_duty(duty, 1.0), 0.0)
    fastest = 0.0
    for _ in range(round(2.0 * span / spec.max_speed / STEP)):
        plant.step(STEP)
        if spec.lower + 0.1 * span < actuator.q / params.unit_si < spec.upper - 0.1 * span:
            fastest = max(fastest, abs(actuator.v / params.unit_si))
    return fastest


@pytest.mark.parametrize("machine", [UNIMATE, RIG], ids=["unimate2000b", "rig"])
def test_full_duty_speed_is_what_the_plant_reaches(machine: Machine) -> None:
    # the glitch filter's bound (docs/machines.md): the faster way at 100 % is within 2 %
    # below the machine file's full_duty_speed, and never above it
    for j, spec in enumerate(machine.joints):
        fastest = max(full_duty_speed(machine, j, d) for d in (100.0, -100.0))
        assert 0.98 * spec.full_duty_speed <= fastest <= spec.full_duty_speed, (spec.name,
                                                                               fastest)
