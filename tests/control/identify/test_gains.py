"""Gain checks: finite numbers, and every joint's loop stable with margin on its model (the
machine file's nominal one, or an identified one)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from control.identify import gains, tuning
from control.identify.gains import MAX_MS_IDENTIFIED, MAX_MS_NOMINAL, GainError
from control.identify.sysid import DeadbandModel
from control.rt.commands import CommandError
from hw.machine import Coefficients, Machine, load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
THESIS_TRACK = UNIMATE.coefficients["thesis_track"]  # option.c's, the thesis's track set
BEND = 3
# Bend as identified on the simulator (docs/identification.md): a 35 Hz oil column where the
# nominal model guesses 20 Hz
IDENTIFIED_BEND = DeadbandModel("Bend", "deg", k_pos=1.211, d_pos=27.5, k_neg=1.19, d_neg=24.3,
                                wn=2 * math.pi * 35.2, zeta=0.49)


def with_kp(c: Coefficients, kp: float, joints: tuple[int, ...] | None = None) -> Coefficients:
    chosen = range(len(c.kp)) if joints is None else joints
    return replace(c, name=f"kp {kp:g}",
                   kp=tuple((kp,) if j in chosen else taps for j, taps in enumerate(c.kp)))


@pytest.mark.parametrize(("machine", "name", "worst"), [
    (UNIMATE, "hold", ("Swivel", 2.14)), (UNIMATE, "track", ("Swivel", 2.14)),
    (UNIMATE, "thesis_hold", ("Swivel", 6.49)), (UNIMATE, "thesis_track", ("In/Out", 6.21)),
    (UNIMATE, "thesis_pi", ("In/Out", 6.21)), (RIG, "hold", ("Ram", 1.49)),
    (RIG, "track", ("Ram", 1.49)), (RIG, "thesis_hold", ("Ram", 1.74)),
    (RIG, "thesis_track", ("Ram", 2.12)),
])
def test_every_set_of_the_machine_files_passes_on_the_nominal_models(
        machine: Machine, name: str, worst: tuple[str, float]) -> None:
    result = gains.check(machine.coefficients[name], machine)
    assert result.ok and all(j.model == "nominal" for j in result.joints)
    top = max(result.joints, key=lambda j: j.margins.ms)
    assert (top.joint, round(top.margins.ms, 2)) == worst
    assert top.margins.ms < MAX_MS_NOMINAL


def test_the_rigs_observer_as_printed_is_refused() -> None:
    """Section 3.6.2, errata #12 and #26: its pole at 94.98 (w taps 95.1, −11.1)."""
    with pytest.raises(GainError, match=r"^coefficient set 'observer' refused, nothing applied: "
                                        r"Ram: unstable on the nominal model: a closed-loop pole "
                                        r"at \|z\| = 94.98, outside the unit circle"):
        gains.check(RIG.coefficients["observer"], RIG)


def test_a_negative_gain_is_refused_naming_the_joint() -> None:
    with pytest.raises(GainError, match=r"Up/Down: unstable on the nominal model: negative gain "
                                        r"\(kp -20, ki 100\): the loop pushes away from its "
                                        r"target\. .*fix their sign"):
        gains.check(with_kp(THESIS_TRACK, -20.0, (2,)), UNIMATE)
    refused = gains.assess(with_kp(THESIS_TRACK, -20.0), UNIMATE)
    assert [p.split(":")[0] for p in refused.problems] == [j.name for j in UNIMATE.joints]


def test_a_gain_far_too_large_is_refused() -> None:
    with pytest.raises(GainError, match=r"In/Out: unstable on the nominal model: a closed-loop "
                                        r"pole at \|z\| = 101\.1"):
        gains.check(with_kp(THESIS_TRACK, 1e9), UNIMATE)


def test_no_feedback_at_all_is_refused() -> None:
    c = replace(with_kp(UNIMATE.hold, 0.0, (BEND,)),
                ki=tuple(0.0 if j == BEND else k for j, k in enumerate(UNIMATE.hold.ki)))
    with pytest.raises(GainError, match=r"Bend: unstable on the nominal model: no feedback "
                                        r"\(kp, ki and kd all 0\)"):
        gains.check(c, UNIMATE)


def test_a_stable_loop_with_too_little_margin_is_refused_with_its_figures() -> None:
    with pytest.raises(GainError, match=r"Bend: too little margin on the nominal model: peak "
                                        r"sensitivity Ms 10\.4 > 8 \(phase margin 10°, crossover "
                                        r"16\.8 Hz\)"):
        gains.check(with_kp(THESIS_TRACK, 105.0, (BEND,)), UNIMATE)


def test_an_identified_model_judges_its_joint_with_its_own_bound() -> None:
    """The same Bend gain on the identified 35 Hz Bend: Ms 2.46, under the identified bound;
    the proposal for it (Ms 2 by design) passes there too."""
    c = with_kp(THESIS_TRACK, 105.0, (BEND,))
    models = [None, None, None, IDENTIFIED_BEND, None, None]
    result = gains.check(c, UNIMATE, models)
    bend = result.joints[BEND]
    assert bend.model == "identified" and bend.bound == MAX_MS_IDENTIFIED
    assert bend.margins.ms == pytest.approx(2.46, abs=0.01)
    assert result.joints[0].model == "nominal"
    proposal = tuning.propose(models, UNIMATE, THESIS_TRACK).coefficients
    assert gains.check(proposal, UNIMATE, models).joints[BEND].margins.ms <= 2.0 + 1e-6
    with pytest.raises(ValueError, match="one model"):
        gains.check(c, UNIMATE, models[:3])


def test_a_number_that_is_not_finite_is_refused_before_any_model() -> None:
    c = replace(UNIMATE.track, ki=(math.nan, *UNIMATE.track.ki[1:]))
    with pytest.raises(CommandError, match="coefficient set 'track': ki must be a finite "
                                           "number, got nan"):
        gains.assess(c, UNIMATE)


def test_the_record_for_a_runs_metadata_is_json_and_says_an_override() -> None:
    refused = gains.assess(with_kp(UNIMATE.track, 1e9), UNIMATE)
    record = json.loads(json.dumps(refused.record("bench test, valves isolated"),
                                   allow_nan=False))
    assert record["passed"] is False and record["overridden"] is True
    assert record["override_reason"] == "bench test, valves isolated"
    assert record["ms"] == [None] * 6 and record["summary"].startswith("In/Out: unstable")
    passed = gains.assess(UNIMATE.hold, UNIMATE).record()
    assert passed["passed"] is True and "overridden" not in passed
    assert passed["summary"] == "stable on the nominal models; worst Swivel Ms 2.14 (≤ 8)"
