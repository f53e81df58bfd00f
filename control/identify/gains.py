"""Gain checks: a coefficient set is applied only if every joint's loop is stable with margin
(issue 11; ``docs/identification.md``, "Gain checks").

**Rule.** For each joint, the eq. 5.1 law's linear part (``tuning.controller``)
is closed around the joint's model (``tuning.loop_plant``: the model's larger
velocity slope through min-PWM compensation, its oil column and dead time, one
more sample of loop delay). The set passes when every closed loop is stable
(every pole inside the unit circle) and its peak sensitivity
``Ms = max|1/(1 + C·P)|`` is at most

- ``MAX_MS_NOMINAL`` = 8 on the machine file's nominal model
  (``sysid.nominal``), used for every joint the caller has no identified
  model of;
- ``MAX_MS_IDENTIFIED`` = 6 on an identified model (``sysid.DeadbandModel``
  from a ``tracking_actuate`` run).

**Why these bounds.** The nominal model is crude: its deadband is the machine
file's minimum PWM, its gain makes 100 % duty give ``max_speed``, and its oil
column is a guessed 20 Hz with ζ = 0.5 and no dead time (identification on the
simulator finds 15–43 Hz, ζ 0.33–0.55). Its Ms is an indication, wrong either
way: the thesis's In/Out gains give 6.21 on it and 2.40 on the identified
model, while the proposals designed for Ms = 2 on identified models give 2.1 to
8.8 on it, and Swivel's is unstable. So on the nominal model the check is a
sanity bound: it refuses what is unstable or nearly so on any plausible
model (a wrong sign, a gain a thousand times too large, the rig's observer of
section 3.6.2 as printed, errata #12), and passes the machine files' own sets,
the worst of which reach 6.49 (Unimate hold, Swivel) and 6.21 (track and
thesis_pi, In/Out). Ms ≤ 8 still keeps the Nyquist curve 1/8 from −1: a gain
margin of at least 8/7 and a phase margin of at least 7.2°. On an identified
model the same sets reach 5.23 (hold, Swivel), 2.40 (track and thesis_pi,
In/Out) and the proposals 2.00 (``tuning.DEFAULT_MS``), so 6 keeps the thesis's
own gains while holding an identified loop to a gain margin of 1.2 and a phase
margin of 9.6°. The textbook's 2 (the proposals' design target) would refuse
the thesis's own track set once In/Out is identified, and its hold set once
the wrist is.

The finite-number check (``control.rt.commands.check_coefficients``) runs first
and cannot be overridden; it is also the control process's own check, which
never imports this module (it needs scipy).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from control.identify import tuning
from control.identify.sysid import DeadbandModel, nominal
from control.rt.commands import check_coefficients
from hw.machine import Coefficients, Machine

MAX_MS_NOMINAL = 8.0
MAX_MS_IDENTIFIED = 6.0
MS_ROUNDING = 1e-6  # a design at exactly the bound passes


class GainError(ValueError):
    """A coefficient set the gain check refuses; the message names each joint and why (and
    the API's ways out); ``problems``, each joint's ``"Joint: what is wrong"``, let a caller
    such as the TUI word its own advice."""

    def __init__(self, message: str, problems: Sequence[str] = ()) -> None:
        super().__init__(message)
        self.problems = tuple(problems)


@dataclass(frozen=True)
class JointCheck:
    """One joint's loop: the model it was checked on, its margins, and what is wrong (``""``
    when nothing is)."""

    joint: str
    model: str  # "nominal" or "identified"
    bound: float
    margins: tuning.Margins
    largest_pole: float  # |z| of the closed loop's largest pole
    problem: str

    @property
    def ok(self) -> bool:
        return not self.problem


@dataclass(frozen=True)
class GainCheck:
    """A coefficient set checked joint by joint."""

    name: str
    joints: tuple[JointCheck, ...]

    @property
    def ok(self) -> bool:
        return all(j.ok for j in self.joints)

    @property
    def problems(self) -> list[str]:
        """``"Joint: what is wrong"`` for each joint that fails."""
        return [f"{j.joint}: {j.problem}" for j in self.joints if not j.ok]

    def summary(self) -> str:
        """One line: what passed, or what failed."""
        if not self.ok:
            return "; ".join(self.problems)
        worst = max(self.joints, key=lambda j: j.margins.ms / j.bound)
        models = sorted({j.model for j in self.joints})
        return (f"stable on the {' and '.join(models)} models; worst {worst.joint} Ms "
                f"{worst.margins.ms:.2f} (≤ {worst.bound:g})")

    def record(self, override: str | None = None) -> dict[str, object]:
        """JSON-compatible, for a run's metadata: the verdict, each joint's model and Ms
        (None when unstable), and the override's reason if one let a refused set through."""
        out: dict[str, object] = {
            "passed": self.ok,
            "summary": self.summary(),
            "models": [j.model for j in self.joints],
            "ms": [j.margins.ms if math.isfinite(j.margins.ms) else None for j in self.joints],
            "bounds": [j.bound for j in self.joints],
        }
        if override is not None:
            out["overridden"] = not self.ok
            out["override_reason"] = override
        return out


def assess(coefficients: Coefficients, machine: Machine,
           models: Sequence[DeadbandModel | None] | None = None,
           dt: float | None = None) -> GainCheck:
    """Check ``coefficients`` joint by joint on ``models`` (one per joint; None, or a None
    entry, means the machine file's nominal model) at sample time ``dt`` (default the
    machine's). Raises CommandError (a ValueError) if a number is not finite or the set does
    not fit the machine; otherwise returns the verdict, refused or not."""
    check_coefficients(coefficients, machine.n_joints)
    step = machine.sample_time_s if dt is None else dt
    if models is None:
        models = [None] * machine.n_joints
    if len(models) != machine.n_joints:
        raise ValueError(f"need one model (or None) per joint, {machine.n_joints}, got "
                         f"{len(models)}")
    return GainCheck(coefficients.name, tuple(
        _joint(coefficients, machine, j, model, step) for j, model in enumerate(models)))


def check(coefficients: Coefficients, machine: Machine,
          models: Sequence[DeadbandModel | None] | None = None,
          dt: float | None = None) -> GainCheck:
    """``assess``, raising GainError naming every joint that fails and how to fix it."""
    result = assess(coefficients, machine, models, dt)
    if not result.ok:
        raise GainError(
            f"coefficient set {coefficients.name!r} refused, nothing applied: "
            f"{'; '.join(result.problems)}. Lower the gains (or fix their sign), check the "
            "set on the joint's identified model (Identify tab; set_coefficients(..., "
            "models=...)), or override with a reason (set_coefficients(..., override=...))",
            result.problems)
    return result


def _joint(c: Coefficients, machine: Machine, j: int, model: DeadbandModel | None,
           dt: float) -> JointCheck:
    joint = machine.joints[j]
    kind, bound = ("nominal", MAX_MS_NOMINAL) if model is None else ("identified",
                                                                      MAX_MS_IDENTIFIED)
    plant = tuning.loop_plant(nominal(joint) if model is None else model, joint, dt)
    ctrl = tuning.controller(c, j, dt)
    margins = tuning.margins(plant, ctrl, dt)
    pole = _largest_pole(plant, ctrl)
    return JointCheck(joint.name, kind, bound, margins, pole,
                      _problem(c, j, kind, bound, margins, pole, dt))


def _problem(c: Coefficients, j: int, kind: str, bound: float, margins: tuning.Margins,
             pole: float, dt: float) -> str:
    on = f"on the {kind} model"
    if margins.stable:
        if margins.ms <= bound * (1 + MS_ROUNDING):
            return ""
        return (f"too little margin {on}: peak sensitivity Ms {margins.ms:.3g} > {bound:g} "
                f"(phase margin {margins.phase_margin_deg:.0f}°, crossover "
                f"{margins.crossover_hz:.3g} Hz)")
    taps = tuning.error_taps(c, j, dt)
    gain = sum(taps) + c.ki[j] * dt  # the law's response to a constant error, first tick
    if not any(taps) and c.ki[j] == 0.0:
        why = "no feedback (kp, ki and kd all 0): nothing holds the joint"
    elif gain < 0:
        why = (f"negative gain (kp {_taps(c.kp[j])}, ki {c.ki[j]:g}): the loop pushes away from "
               "its target")
    else:
        why = f"a closed-loop pole at |z| = {pole:.4g}, outside the unit circle"
    return f"unstable {on}: {why}"


def _largest_pole(plant: tuple[np.ndarray, np.ndarray],
                  ctrl: tuple[np.ndarray, np.ndarray]) -> float:
    char = np.polyadd(np.polymul(ctrl[1], plant[1]), np.polymul(ctrl[0], plant[0]))
    return float(np.max(np.abs(np.roots(char))))


def _taps(taps: tuple[float, ...]) -> str:
    return ", ".join(f"{t:g}" for t in taps) if len(taps) != 1 else f"{taps[0]:g}"
