"""The closed-form inverse gives the answers it gave before its speed-up (issue 29 item 4).

``inverse_reference.npz`` holds 2,600 poses and nears and what ``Unimate2000B.inverse``
(every in-limit branch, nearest first, or the Unreachable message) and ``inverse_batch``
(the 8 slots, valid, best) returned for them at commit 0a885e0, before the two were
rewritten for speed. The cases: random in-limit configurations with random nears, near
= the configuration itself and the default near; configurations with joints on their
limits; Yaw at and near the wrist singularity (0 to 0.5°); and poses out of reach or
outside the limits. Every answer must be the stored one to 1e-9 (mm, deg) and reach its
pose by forward kinematics. Made by
``PYTHONPATH=. python tests/kinematics/test_inverse_reference.py``; run that again only if
the answers are meant to change.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from control.motion.robot_model import builtin_unimate
from kinematics import Unreachable, unimate, xyz_fixed
from kinematics.unimate import Unimate2000B

REFERENCE = Path(__file__).with_name("inverse_reference.npz")
MODEL = builtin_unimate()
# Every angle free over a full turn and In/Out either way: all 8 slots occur (on the
# Unimate's limits only slots 0 and 2 can).
WIDE = replace(MODEL, lower=(-3000.0, -180.0, -180.0, -180.0, -180.0, -180.0),
               upper=(3000.0, 180.0, 180.0, 180.0, 180.0, 180.0))
MODELS = {"builtin": MODEL, "wide": WIDE}
SCALE = {"builtin": 0.5, "wide": 0.15}  # of cases(), 4,000 poses at 1
TOL = 1e-9
# Yaw values (deg) at and around the wrist singularity sin θ5 = 0.
YAWS = (0.0, 1e-13, 1e-12, 1e-10, 1e-9, 1e-8, 1e-6, 1e-4, 1e-2, 0.5)


def cases(model: Unimate2000B, scale: float, seed: int = 2029) -> dict[str, np.ndarray]:
    """The reference's inputs: ``pose (N, 6)``, ``near (N, 6)`` and ``default (N,)``, the
    rows solved with near omitted (their near is then the middle of the limits); ``scale``
    times 4,000 of them."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array(model.lower), np.array(model.upper)

    def size(count: int) -> int:
        return round(count * scale)

    def inside(count: int) -> np.ndarray:
        return rng.uniform(lo, hi, (count, 6))

    def either(q: np.ndarray, other: np.ndarray) -> np.ndarray:
        """Each row from ``q`` or ``other``, at random."""
        return np.where(rng.random((len(q), 1)) < 0.5, q, other)

    def on_limits(q: np.ndarray) -> np.ndarray:
        pick = rng.integers(0, 3, q.shape)  # 0 keep, 1 lower, 2 upper limit
        return np.where(pick == 1, lo, np.where(pick == 2, hi, q))

    def near_wrist(q: np.ndarray) -> np.ndarray:
        q = q.copy()
        q[:, 4] = rng.choice(YAWS, len(q)) * rng.choice([-1.0, 1.0], len(q))
        return q

    groups: list[tuple[np.ndarray, np.ndarray, bool]] = []
    q = inside(size(1500))
    groups.append((q, inside(len(q)), False))
    q = inside(size(300))
    groups.append((q, q, False))
    q = inside(size(300))
    groups.append((q, np.tile(model.mid_range, (len(q), 1)), True))
    q = on_limits(inside(size(500)))
    groups.append((q, either(q, inside(len(q))), False))
    q = near_wrist(inside(size(600)))
    groups.append((q, either(q, either(q + rng.normal(0.0, 1.0, q.shape), inside(len(q)))),
                   False))
    q = near_wrist(on_limits(inside(size(300))))
    groups.append((q, either(q, inside(len(q))), False))
    q = near_wrist(inside(size(100)))
    groups.append((q, np.tile(model.mid_range, (len(q), 1)), True))
    q = inside(size(200))
    past = rng.random(q.shape) < 0.3
    q += past * rng.choice([-1.0, 1.0], q.shape) * rng.uniform(0.001, 0.2, q.shape) * (hi - lo)
    groups.append((q, inside(len(q)), False))
    poses = [model.pose(q) for q, _, _ in groups]
    far = model.pose(inside(size(200)))
    far[:, :3] *= rng.uniform(0.3, 1.6, (len(far), 1))
    poses.append(far)
    groups.append((far, inside(len(far)), False))
    return {
        "pose": np.concatenate(poses),
        "near": np.concatenate([near for _, near, _ in groups]),
        "default": np.concatenate([np.full(len(q), d) for q, _, d in groups]),
    }


def solve(model: Unimate2000B, pose: np.ndarray, near: np.ndarray,
          default: np.ndarray) -> dict[str, np.ndarray]:
    """What ``inverse`` and ``inverse_batch`` give for the cases, in the reference's form:
    ``count`` single solutions per row (0: Unreachable, whose ``message`` is kept),
    ``single`` their rows in order; ``valid`` the batch's 8 slots, ``batch`` the valid
    slots' rows in order, ``best`` the batch's best slot (-1 if none)."""
    singles, counts, messages = [], [], []
    for p, n, d in zip(pose, near, default, strict=True):
        try:
            sols = model.inverse(p) if d else model.inverse(p, near=n)
        except Unreachable as e:
            counts.append(0)
            messages.append(str(e))
            continue
        singles.append(sols)
        counts.append(len(sols))
        messages.append("")
    valid, batch, best = [], [], []
    for use_default in (False, True):
        rows = np.flatnonzero(default == use_default)
        result = (model.inverse_batch(pose[rows]) if use_default
                  else model.inverse_batch(pose[rows], near=near[rows]))
        valid.append((rows, result.valid))
        batch.append((rows, result.solutions))
        best.append((rows, result.best))
    valid_all = np.zeros((len(pose), 8), dtype=bool)
    solutions = np.full((len(pose), 8, 6), np.nan)
    best_all = np.full((len(pose), 6), np.nan)
    for (rows, v), (_, s), (_, b) in zip(valid, batch, best, strict=True):
        valid_all[rows], solutions[rows], best_all[rows] = v, s, b
    best_slot = np.full(len(pose), -1)
    for i in np.flatnonzero(valid_all.any(axis=1)):
        slots = np.flatnonzero(valid_all[i])
        best_slot[i] = slots[np.abs(solutions[i, slots] - best_all[i]).max(axis=1).argmin()]
    return {
        "count": np.array(counts), "single": np.concatenate(singles),
        "message": np.array(messages), "valid": valid_all, "batch": solutions[valid_all],
        "nan_elsewhere": np.isnan(solutions[~valid_all]).all(), "best": best_slot,
    }


def limits(model: Unimate2000B) -> np.ndarray:
    """The model's numbers as the reference stores them."""
    return np.array([model.d1, model.a2, model.lb, model.ly, *model.lower, *model.upper])


@pytest.fixture(scope="module", params=list(MODELS))
def reference(request: pytest.FixtureRequest) -> tuple[Unimate2000B, dict[str, np.ndarray]]:
    """A model and its stored cases and answers (``solve``'s keys)."""
    name, model = request.param, MODELS[request.param]
    with np.load(REFERENCE) as data:
        stored = {k.split("/", 1)[1]: v for k, v in data.items() if k.startswith(name + "/")}
    assert (stored["model"] == limits(model)).all(), (
        f"the {name} Unimate differs from the one the reference was made with: make the "
        "reference again (module docstring) if that change is meant")
    return model, stored


@pytest.fixture(scope="module")
def now(reference: tuple[Unimate2000B, dict]) -> dict[str, np.ndarray]:
    model, stored = reference
    return solve(model, stored["pose"], stored["near"], stored["default"])


def test_single_inverse_gives_the_stored_solutions(reference: tuple, now: dict) -> None:
    _, reference = reference
    np.testing.assert_array_equal(now["count"], reference["count"])
    np.testing.assert_allclose(now["single"], reference["single"], rtol=0, atol=TOL)
    np.testing.assert_array_equal(now["message"], reference["message"])


def test_batch_inverse_gives_the_stored_branches(reference: tuple, now: dict) -> None:
    _, reference = reference
    np.testing.assert_array_equal(now["valid"], reference["valid"])
    np.testing.assert_allclose(now["batch"], reference["batch"], rtol=0, atol=TOL)
    assert now["nan_elsewhere"]
    np.testing.assert_array_equal(now["best"], reference["best"])


def test_a_batch_of_several_chunks_gives_the_stored_branches(reference: tuple) -> None:
    """The cases over and over, two chunks of ``inverse_batch``'s and more: each pose gets
    its own answers wherever a chunk begins."""
    model, reference = reference
    rows = np.flatnonzero(~reference["default"])
    copies = -(-2 * unimate._CHUNK // len(rows))
    result = model.inverse_batch(np.tile(reference["pose"][rows], (copies, 1)),
                                 near=np.tile(reference["near"][rows], (copies, 1)))
    want = np.tile(reference["valid"][rows], (copies, 1))
    np.testing.assert_array_equal(result.valid, want)
    stored = np.full((len(reference["pose"]), 8, 6), np.nan)
    stored[reference["valid"]] = reference["batch"]
    np.testing.assert_allclose(result.solutions, np.tile(stored[rows], (copies, 1, 1)),
                               rtol=0, atol=TOL)


def test_the_cases_cover_every_kind_of_branch() -> None:
    """Together the two models' cases hold every slot, both singular holds, unreachable
    poses of each kind and poses with several solutions, so the tests above compare
    all of them."""
    with np.load(REFERENCE) as data:
        stored = dict(data)
    valid = np.concatenate([stored[f"{m}/valid"] for m in MODELS])
    batch = np.concatenate([stored[f"{m}/batch"] for m in MODELS])
    count = np.concatenate([stored[f"{m}/count"] for m in MODELS])
    messages = np.concatenate([stored[f"{m}/message"] for m in MODELS])[count == 0]
    assert (valid.sum(axis=0) > 100).all()
    held = np.nonzero(valid)[1][np.abs(batch[:, 4]) <= 1e-9] % 4
    assert (held < 2).sum() > 100 and (held >= 2).sum() > 100  # Swivel held, Bend held
    assert (count == 0).sum() > 100 and (count > 2).sum() > 100
    for reason in ("out of reach: In/Out", "outside the joint limits", "wrist singular"):
        assert sum(reason in m for m in messages) > 10, reason


def test_every_solution_reaches_its_pose(reference: tuple, now: dict) -> None:
    model, reference = reference
    pose = reference["pose"]
    rows = np.repeat(np.arange(len(pose)), now["count"])
    assert_reaches(model, now["single"], pose[rows])
    rows = np.nonzero(now["valid"])[0]
    assert_reaches(model, now["batch"], pose[rows])
    for q in (now["single"], now["batch"]):
        assert (q >= model.lower).all() and (q <= model.upper).all()


def assert_reaches(model: Unimate2000B, q: np.ndarray, p: np.ndarray) -> None:
    """FK of joint vectors ``q`` is pose ``p``: position to 1e-6 mm, rotation to 1e-9."""
    got = model.forward(q)
    want = xyz_fixed.rotation(*np.radians(p[:, 3:]).T)
    np.testing.assert_allclose(got[:, :3, 3], p[:, :3], rtol=0, atol=1e-6)
    np.testing.assert_allclose(got[:, :3, :3], want, rtol=0, atol=1e-9)


def write() -> None:
    """Solve the cases with the current code and store them as the reference."""
    arrays = {}
    for name, model in MODELS.items():
        inputs = cases(model, SCALE[name])
        answers = solve(model, inputs["pose"], inputs["near"], inputs["default"])
        del answers["nan_elsewhere"]
        arrays |= {f"{name}/{k}": v for k, v in {"model": limits(model), **inputs,
                                                  **answers}.items()}
        print(f"{name}: {len(inputs['pose']):,} poses, {len(answers['single']):,} single and "
              f"{len(answers['batch']):,} batch solutions, {(answers['count'] == 0).sum():,} "
              "unreachable")
    np.savez_compressed(REFERENCE, **arrays)
    print(f"{REFERENCE}: {REFERENCE.stat().st_size / 1e3:.0f} kB")


if __name__ == "__main__":
    sys.exit(write())
