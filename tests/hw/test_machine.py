"""Machine descriptions: the built-in files carry the thesis's numbers; bad files say where."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hw.machine import MachineError, load_machine, parse_machine

MACHINES = Path(__file__).resolve().parents[2] / "hw" / "machines"
UNIMATE_TEXT = (MACHINES / "unimate2000b.toml").read_text()
RIG_TEXT = (MACHINES / "rig.toml").read_text()


def test_unimate_carries_the_thesis_numbers() -> None:
    m = load_machine("unimate2000b")
    assert [j.name for j in m.joints] == ["In/Out", "Rotate", "Up/Down", "Bend", "Yaw", "Swivel"]
    assert [j.kind for j in m.joints] == ["prismatic"] + ["revolute"] * 5
    # section 5.4.1
    assert [(j.min_pwm_pos, j.min_pwm_neg) for j in m.joints] == [
        (26, 17), (22, 18), (14, 26), (25, 28), (21, 16), (20, 20)]
    # rtshare.h limit_neg / limit_pos
    assert m.lower == (976, -110, -27, -110, -169, -180)
    assert m.upper == (2041, 110, 30, 110, 174, 180)
    # rtshare.h metric_gradient / metric_constant / joint_dep
    assert [j.encoder.gradient for j in m.joints] == [
        -0.2617, -0.0295, 0.01432, 0.06057, 0.08877, -0.09595]
    assert [j.encoder.constant for j in m.joints] == [2041, 120.277, -27, -110, -169, 243.8]
    yaw = m.joints[m.joint_index("yaw")].encoder
    assert (yaw.coupled_to, yaw.coupling) == (m.joint_index("bend"), 1.0)
    assert m.encoder_kind == "gray" and m.encoder_bits == 13
    # section 5.4.2 P.I. gains and option.c's hold/track sets
    pi = m.coefficients["thesis_pi"]
    assert [k[0] for k in pi.kp] == [20, 25, 30, 3, 4, 20]
    assert pi.ki == (200, 20, 90, 3, 20, 80)
    assert [k[0] for k in m.hold.kp] == [10, 10, 11, 0.5, 1, 2]
    assert [k[0] for k in m.track.kp] == [20, 20, 31, 3, 2, 4]
    assert m.hold.ki == m.track.ki == (200, 29, 100, 3, 14, 80)
    assert m.hold.integral_limit == 50


def test_rig_carries_the_thesis_numbers() -> None:
    m = load_machine("rig")
    (ram,) = m.joints
    assert (ram.lower, ram.upper) == (0, 1200)
    assert ram.down_scale == 0.538  # errata #11
    assert ram.encoder.gradient == 0.1 and m.encoder_kind == "quadrature"
    t = m.track  # eq. 3.3, {Kp, Kd, Ki} = {0.75, 0.002, 0.01}
    assert (t.kp[0][0], t.kd[0], t.ki[0]) == (0.75, 0.002, 0.01)
    assert t.filter == (11, -18, 9, -2) and t.filter_divisor == 6
    assert m.coefficients["observer"].w[0] == (95.1, -11.1)


def test_user_machine_from_a_path(tmp_path: Path) -> None:
    path = tmp_path / "gantry.toml"
    path.write_text(RIG_TEXT.replace('name = "rig"', 'name = "gantry"'))
    assert load_machine(path).name == "gantry"
    assert load_machine(str(path)).path == path


def test_missing_file_names_the_builtins(tmp_path: Path) -> None:
    with pytest.raises(MachineError, match=r"no such machine file .*rig, unimate2000b"):
        load_machine(tmp_path / "nope.toml")


BAD = [
    (("limits = [976.0, 2041.0]", "limits = [2041.0, 976.0]"),
     r"joints\[0\]\.limits: lower 2041 must be below"),
    (('kind = "revolute"\nunit = "deg"\nlimits = [-110.0, 110.0]',
      'kind = "revolute"\nunit = "mm"\nlimits = [-110.0, 110.0]'),
     r"joints\[1\]\.unit: 'mm' is not one of deg"),
    (("min_pwm = [14.0, 26.0]", "min_pwm = [14.0]"), r"joints\[2\]\.min_pwm: must have 2 entries"),
    (("min_pwm = [14.0, 26.0]", "min_pwm = [14.0, 126.0]"),
     r"joints\[2\]\.min_pwm: negative minimum 126 must be in 0…100 %"),
    (("polarity = -1\nmax_speed = 25.0", "polarity = 0\nmax_speed = 25.0"),
     r"joints\[2\]\.polarity: must be 1 or -1"),
    (('coupled_to = "bend"', 'coupled_to = "elbow"'),
     r"joints\[4\]\.encoder\.coupled_to: 'elbow' is not a joint key"),
    (("ki = [200.0, 29.0, 100.0, 3.0, 14.0, 80.0]", "ki = [200.0, 29.0]"),
     r"coefficients\.hold\.ki: must have 6 entries, got 2"),
    (("tolerance = 0.3", 'tolerance = "tight"'), r"joints\[2\]\.tolerance: must be a number"),
    (("tolerance = 0.3", "tolerance = nan"), r"joints\[2\]\.tolerance: must be finite"),
    (("tolerance = 0.3", "tolerence = 0.3"), r"joints\[2\]: unknown key\(s\) tolerence"),
    (('key = "swivel"', 'key = "bend"'), r"joints\[5\]\.key: duplicate joint key 'bend'"),
    (('{ joint = "bend", alpha = 90.0', '{ joint = "yaw", alpha = 90.0'),
     r"kinematics\.dh\[4\]\.joint: joint 'yaw' drives more than one DH row"),
    (("[coefficients.track]", "[coefficients.tracking]"), r"coefficients\.track: missing"),
    (("sample_time_ms = 1.0", "sample_time_ms = 0.0"), r"machine\.sample_time_ms: 0 out of range"),
    (("[valve]", "valve = 3\n[valves]"), r"unknown key\(s\) valves"),
    (("bits = 13", "bits = 13.5"), r"encoder\.bits: must be a whole number"),
    (("[machine]", "[machine"), r"not valid TOML"),
]


@pytest.mark.parametrize(("edit", "message"), BAD, ids=[m for _, m in BAD])
def test_bad_file_names_file_key_and_problem(edit: tuple[str, str], message: str) -> None:
    old, new = edit
    assert old in UNIMATE_TEXT, f"test edit {old!r} no longer matches the file"
    text = UNIMATE_TEXT.replace(old, new, 1)
    with pytest.raises(MachineError, match=r"^unimate2000b\.toml: .*" + message):
        parse_machine(text, MACHINES / "unimate2000b.toml")


def test_feed_forward_gains_are_optional_and_checked() -> None:
    assert load_machine("unimate2000b").track.kv == ()
    text = UNIMATE_TEXT.replace('note = "option.c track_coeff"',
                                'note = "option.c track_coeff"\nkv = [0.2, 1, 2, 0.5, 0.5, 0.4]')
    assert parse_machine(text, Path("ff.toml")).track.kv == (0.2, 1, 2, 0.5, 0.5, 0.4)
    with pytest.raises(MachineError, match=r"coefficients\.track\.kv: must have 6 entries"):
        parse_machine(text.replace("kv = [0.2, 1, 2,", "kv = [0.2,"), Path("ff.toml"))


def test_check_targets_names_the_joint() -> None:
    m = load_machine("unimate2000b")
    with pytest.raises(ValueError, match=r"Up/Down target 35° is outside -27…30° "
                                         r"\(machine unimate2000b\)"):
        m.check_targets([1500, 0, 35, 0, 0, 0])
    with pytest.raises(ValueError, match="Rotate target nan is not a number"):
        m.check_targets([1500, float("nan"), 0, 0, 0, 0])
    assert m.check_targets([1500, 0, 0, 0, 0, 0])[0] == 1500


@settings(max_examples=300, deadline=None)
@given(position=st.integers(0, len(UNIMATE_TEXT) - 1), junk=st.text(max_size=8))
def test_any_corruption_gives_a_machine_error_or_a_valid_machine(position: int, junk: str) -> None:
    text = UNIMATE_TEXT[:position] + junk + UNIMATE_TEXT[position + len(junk):]
    try:
        machine = parse_machine(text, Path("fuzzed.toml"))
    except MachineError as exc:
        assert str(exc).startswith("fuzzed.toml: ")
    else:
        assert machine.n_joints == len(tomllib.loads(text)["joints"])
