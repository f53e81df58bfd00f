"""The Unimate 2000B: forward and closed-form inverse kinematics, thesis sections 4.4–4.5.

Joint vectors are in the thesis's actuator order (ARCHITECTURE.md)::

    q = [In/Out d3 (mm), Rotate θ1, Up/Down θ2, Bend θ4, Yaw θ5, Swivel θ6 (deg)]

A pose is frame 6 (the end-effector) in the base frame 0::

    p = [x, y, z (mm), γ, β, α (deg, X-Y-Z fixed angles, eq. 4.04)]

The inverse follows from the A matrices of section 4.4 (and Appendix A), with
n, o, a the columns of the pose's rotation and P its position:

- the Up/Down axis z1 = (sθ1, −cθ1, 0) is the normal of the arm plane, and the
  Bend axis z3 is parallel to it;
- the wrist point w = P − Ly·a (origin of frame 5) lies in the arm plane, so
  θ1 = atan2(wy, wx) or that + 180° (eq. 4.14, App. A (1)–(3));
- z1·a = cθ5, z1·n = sθ5·cθ6, z1·o = −sθ5·sθ6 give θ5, θ6 in two branches
  (eq. 4.15, 4.16, App. A (1), (4), (5));
- the Bend axis z4 = −(sθ6·n + cθ6·o) lies in the arm plane and the arm point
  o3 = w − Lb·z4 = (cθ1·ρ, sθ1·ρ, d1 + h) with (ρ, h) = Rot(θ2)·(d3, a2)
  (App. A (8), (9)), so d3 = ±√(ρ² + h² − a2²) and θ2 = atan2(h, ρ) − atan2(a2, d3):
  eq. 4.17 solved in closed form (errata #8), without the listing's division by
  cos θ1 (errata #9);
- θ2 + θ4 = atan2(z4·z0, z4·x1) (eq. 4.18).

That is up to 2 (θ1) × 2 (wrist) × 2 (θ2 roots) = 8 branches; each is wrapped
into the joint limits (a ±360° copy of an angle is the same joint position),
filtered by them and ranked by ``distance`` to a reference joint vector
``near``: ``Σ|Δθ| (deg) + |Δd3| / MM_PER_DEGREE``, joint travel with 10 mm of
In/Out weighing as much as 1° of a revolute joint.

Singularities. Where the pose leaves joints undetermined, a joint is held at
its ``near`` value, which is what an operator jogging the arm expects (what is
free stays where it is and the others follow):

- wrist singular (sin θ5 = 0: the Swivel axis z5 is parallel to the Bend and
  Up/Down axes; the all-zero home pose is one). Then only θ2 + θ4 + θ6 and the
  wrist point are fixed, a one-parameter family of In/Out, Up/Down, Bend,
  Swivel. The two wrist branches become two members of it: Swivel held at
  near's (then z4 = −(sθ6·n + cθ6·o) and the arm as usual), and Bend held at
  near's (the wrist point is Rot(θ2)·(d3 + Lb·cθ4, a2 + Lb·sθ4) from the
  shoulder, solved like eq. 4.17, Swivel last). If neither is inside the limits
  the pose is reported unreachable with a hint to pass another ``near``;
- wrist point on the Rotate axis (outside the Unimate's workspace: the In/Out
  lower limit keeps it far away): Rotate = near's Rotate and that + 180°.

Near a wrist singularity the pose is still met to round-off, but the joints are
ill-conditioned: θ6 comes from the O(sin θ5) components z1·n, z1·o, so round-off
in the pose moves the solution by ~1e-14/sin θ5 (deg or mm) along the family
of configurations that nearly reach it. A configuration sitting on a joint
limit with |θ5| below ~0.005° can therefore come back just outside the limit
(beyond LIMIT_TOL) and be reported unreachable.

The numbers. Table 4.1's lengths and the joint limits are machine data and live
in the machine file only; a ``Unimate2000B`` has no defaults, and this package
reads no file: the caller passes them in (``Unimate2000B.from_table``).
``control.motion.robot_model`` builds one from any ``hw.Machine``
(``unimate_model``), and the built-in machine's once (``builtin_unimate``): that
is how the app, ``servodesk fk/ik``, the benchmarks and the tests get theirs.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from kinematics import xyz_fixed
from kinematics.dh import DHLink
from kinematics.dh import forward as dh_forward
from kinematics.dh import frames as dh_frames

JOINTS = ("In/Out", "Rotate", "Up/Down", "Bend", "Yaw", "Swivel")
UNITS = ("mm", "°", "°", "°", "°", "°")
# Distance metric for ranking solutions, a choice of this solver rather than a property of
# the machine: 10 mm of In/Out count as much as 1° of a revolute joint.
MM_PER_DEGREE = 10.0
# Round-off (mm or deg) allowed at a joint limit; a solution this close is clipped onto the limit.
LIMIT_TOL = 1e-9
# |sin θ5| at or below this is a wrist singularity: Swivel and Bend are not unique.
WRIST_TOL = 1e-10
# Wrist point within this distance (mm) of the Rotate axis: Rotate is not unique.
ARM_TOL = 1e-9
# The two Up/Down roots coincide when |d3| = √(ρ² + h² − a2²) is at or below this (mm).
ROOT_TOL = 1e-9
# Two solutions closer than this (mm or deg, every joint) are the same one.
SAME_TOL = 1e-6

DH_ORDER = (1, 2, 0, 3, 4, 5)  # DH joint i is actuator DH_ORDER[i]: θ1, θ2, d3, θ4, θ5, θ6
_WEIGHTS = np.array([1.0 / MM_PER_DEGREE, 1.0, 1.0, 1.0, 1.0, 1.0])
_CHUNK = 8192  # poses solved at once by inverse_batch: bounded, cache-sized temporaries
_RAD, _DEG = math.pi / 180.0, 180.0 / math.pi  # math.radians and math.degrees' factors
_HALF_TURN = np.array([0.0, math.pi])  # the two θ1 branches


class Unreachable(ValueError):
    """No joint solution inside the limits exists for a pose; the message says why."""


@dataclass(frozen=True)
class InverseBatch:
    """Every inverse-kinematics branch of a batch of poses (``inverse_batch``).

    ``solutions: (..., 8, 6)`` joint vectors (mm, deg), NaN where a branch is
    invalid. Slot ``4·i1 + 2·iw + ir``: i1 the Rotate branch (θ1, θ1 + 180°);
    iw the wrist branch (θ5 ≥ 0, then −θ5 with θ6 + 180°; at a wrist
    singularity Swivel held at near's, then Bend held at near's); ir the root
    (+√, then −√). ``valid: (..., 8)`` the branch exists, is inside the limits
    and repeats no other slot. ``best: (..., 6)`` the valid branch nearest
    ``near`` (NaN where none). ``reachable: (...)`` some branch is valid.
    """

    solutions: np.ndarray
    valid: np.ndarray
    best: np.ndarray
    reachable: np.ndarray


@dataclass(frozen=True)
class Unimate2000B:
    """Unimate 2000B geometry (Table 4.1's lengths, mm) and joint limits (actuator order, mm
    and deg), all from a machine file (module docstring): no defaults.

    ``d1`` base height, ``a2`` Up/Down offset, ``lb`` = d5 Bend-to-Yaw length,
    ``ly`` = d6 Yaw-to-tool length. The built-in file's limits are rtshare.h's
    limit_neg/limit_pos.
    """

    d1: float
    a2: float
    lb: float
    ly: float
    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def __post_init__(self) -> None:
        if len(self.lower) != 6 or len(self.upper) != 6:
            raise ValueError(f"need 6 lower and 6 upper limits ({', '.join(JOINTS)})")
        for name, lo, hi in zip(JOINTS, self.lower, self.upper, strict=True):
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"{name} limits {lo:g}…{hi:g} must be finite with lower < upper")

    @classmethod
    def from_table(cls, links: Sequence[DHLink], drives: Sequence[int], lower: Sequence[float],
                   upper: Sequence[float], names: Sequence[str] = JOINTS) -> Unimate2000B:
        """The model of a machine file's DH table: ``links`` in the table's order,
        ``drives[i]`` the actuator whose variable row i carries, ``names`` the machine's
        actuator names (for the error). The rows must drive θ1, θ2, d3, θ4, θ5, θ6
        (``DH_ORDER``) and have ``from_links``'s form; ValueError says what differs.
        """
        if tuple(drives) != DH_ORDER:
            raise ValueError("rows must drive " + ", ".join(JOINTS[j] for j in DH_ORDER)
                             + " in that order, got " + ", ".join(names[j] for j in drives))
        return cls.from_links(links, lower, upper)

    @classmethod
    def from_links(cls, links: Sequence[DHLink], lower: Sequence[float],
                   upper: Sequence[float]) -> Unimate2000B:
        """The model whose DH rows (in DH order θ1, θ2, d3, θ4, θ5, θ6) are ``links``.

        Only the lengths may differ from Table 4.1: d1 (row 1), a2 (row 2), lb and ly
        (d of rows 5 and 6); the closed-form inverse holds for no other form, so any other
        difference raises ValueError naming the row.
        """
        if len(links) != 6:
            raise ValueError(f"the Unimate 2000B has 6 DH rows, got {len(links)}")
        model = cls(d1=links[0].d, a2=links[1].a, lb=links[4].d, ly=links[5].d,
                    lower=tuple(lower), upper=tuple(upper))
        for i, (got, form) in enumerate(zip(links, model.links(), strict=True)):
            if got != form:
                raise ValueError(
                    f"DH row {i + 1} ({JOINTS[DH_ORDER[i]]}) is {_row(got)}, but the Unimate "
                    f"2000B's closed form needs {_row(form)}")
        return model

    @functools.cached_property
    def mid_range(self) -> tuple[float, ...]:
        """The middle of each joint's limits (mm, deg): the default ``near``."""
        return tuple((lo + hi) / 2 for lo, hi in zip(self.lower, self.upper, strict=True))

    @functools.cached_property
    def _unwrapped(self) -> tuple[tuple[float, float], ...]:
        """Per joint, the range lo…hi where ``_wrap`` gives an angle back as it is (+ 0.0):
        all of it for a joint whose limits (with LIMIT_TOL) span less than a turn (one
        copy at most is inside), none of it (an empty range) for the others."""
        return tuple((lo, hi) if hi - lo < 359.0 else (math.inf, -math.inf)
                     for lo, hi in zip(self.lower, self.upper, strict=True))

    def links(self) -> tuple[DHLink, ...]:
        """Table 4.1 as standard DH rows in DH order (θ1, θ2, d3, θ4, θ5, θ6).

        The thesis's two-step A_2^1 (Table 4.2, eq. 4.08) is one standard link
        with α = 90°, a = a2 and θ = θ2 + 90°.
        """
        return (
            DHLink(90.0, 0.0, self.d1, 0.0),
            DHLink(90.0, self.a2, 0.0, 90.0),
            DHLink(-90.0, 0.0, 0.0, 0.0, prismatic=True),
            DHLink(90.0, 0.0, 0.0, 0.0),
            DHLink(-90.0, 0.0, self.lb, 0.0),
            DHLink(0.0, 0.0, self.ly, 0.0),
        )

    def forward(self, q: ArrayLike) -> np.ndarray:
        """``T_6^0`` (eq. 4.11) of joint vectors ``q: (..., 6)`` (mm, deg) → ``(..., 4, 4)`` (mm).

        Defined for any finite q, inside the limits or not.
        """
        q = np.asarray(q, dtype=float)
        if q.ndim == 0 or q.shape[-1] != 6:
            raise ValueError(f"expected joint vectors of shape (..., 6), got {q.shape}")
        return dh_forward(self.links(), q[..., list(DH_ORDER)])

    def frames(self, q: ArrayLike) -> np.ndarray:
        """Every link frame ``T_0^0 … T_6^0`` of joint vectors ``q: (..., 6)`` (mm, deg) →
        ``(..., 7, 4, 4)`` (mm): the base, then frames 1-6 in DH order; the last is
        ``forward``'s. Origins 2 and 3 coincide with 1 and 4 where a link has no length (the
        drawing of the arm takes them as they come)."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 0 or q.shape[-1] != 6:
            raise ValueError(f"expected joint vectors of shape (..., 6), got {q.shape}")
        return dh_frames(self.links(), q[..., list(DH_ORDER)])

    def pose(self, q: ArrayLike) -> np.ndarray:
        """Pose of joint vectors ``q: (..., 6)`` → ``(..., 6)``: x, y, z (mm), γ, β, α (deg)."""
        t = self.forward(q)
        angles = np.degrees(xyz_fixed.angles(t[..., :3, :3]))  # eq. 4.05, errata #15
        return np.concatenate([t[..., :3, 3], angles], axis=-1)

    def jacobian(self, q: ArrayLike) -> np.ndarray:
        """The geometric Jacobian of joint vectors ``q: (..., 6)`` → ``(..., 6, 6)``: the tool
        point's velocity (mm/s, rows 0-2) and the tool's angular velocity (deg/s, rows 3-5),
        both in the base frame, per joint velocity (mm/s or deg/s, actuator order).

        Column of a revolute DH joint i about z_{i-1} through o_{i-1}: (z × (p − o)·π/180, z);
        of the prismatic one along z_{i-1}: (z, 0) (Spong, Hutchinson & Vidyasagar eq. 4.60).
        """
        q = np.asarray(q, dtype=float)
        if q.ndim == 0 or q.shape[-1] != 6:
            raise ValueError(f"expected joint vectors of shape (..., 6), got {q.shape}")
        qdh = q[..., list(DH_ORDER)]
        frame = np.broadcast_to(np.eye(4), (*q.shape[:-1], 4, 4))
        axes, origins = [], []
        for i, link in enumerate(self.links()):
            axes.append(frame[..., :3, 2])
            origins.append(frame[..., :3, 3])
            frame = frame @ link.transform(qdh[..., i])
        tool = frame[..., :3, 3]
        out = np.zeros((*q.shape[:-1], 6, 6))
        for i, link in enumerate(self.links()):
            j = DH_ORDER[i]
            if link.prismatic:
                out[..., :3, j] = axes[i]
            else:
                out[..., :3, j] = np.cross(axes[i], tool - origins[i]) * (math.pi / 180.0)
                out[..., 3:, j] = axes[i]
        return out

    def inverse(self, p: ArrayLike, near: ArrayLike | None = None) -> np.ndarray:
        """Every in-limit joint solution of one pose, nearest ``near`` first.

        ``p: (6,)`` x, y, z (mm), γ, β, α (deg). ``near: (6,)`` joint vector to
        rank by (typically the current reading; default the middle of the
        limits); it also supplies the joint held at a singularity (module
        docstring). Returns ``(k, 6)``, 1 ≤ k ≤ 8, distinct. Raises Unreachable
        naming the reason, ValueError for a NaN/inf, a wrong shape or a position
        so large that the solution overflows (``ρ² + h²`` past float's largest).

        A scalar ``math`` transcription of ``inverse_batch`` (numpy's per-call
        overhead would cost ~10× more for one pose); the tests hold the two to
        each other. A branch is dropped at the first joint found outside its
        limits, before the joints after it are solved; only an unreachable pose
        is solved again in full (``_branches``) for the reason.
        """
        target = _vector(p, "pose")
        ref = self._reference(near)
        fitted, singular = self._solutions(target, ref)
        if not fitted:  # solved again with every branch kept, to say why
            raw, radius, singular = self._branches(target, ref)
            if not all(math.isfinite(v) for v in (radius, *(v for b in raw for v in b))):
                raise ValueError(_overflow(target))
            raise Unreachable(self._why(raw, radius, ref if singular else None))
        if singular:  # the two held joints can pick the same member of the family
            fitted = [q for i, q in enumerate(fitted) if not any(_same(q, u) for u in fitted[:i])]
        if len(fitted) > 1:
            fitted.sort(key=lambda q: _distance(q, ref))
        return np.array(fitted)

    def inverse_batch(self, p: ArrayLike, near: ArrayLike | None = None) -> InverseBatch:
        """All 8 branches of poses ``p: (..., 6)``, vectorised; see InverseBatch.

        ``near: (6,)`` or ``(..., 6)`` as in ``inverse`` (default the middle of
        the limits). Raises ValueError for a NaN/inf or a wrong shape.
        """
        p = np.asarray(p, dtype=float)
        if p.ndim == 0 or p.shape[-1] != 6:
            raise ValueError(f"expected poses of shape (..., 6), got {p.shape}")
        if not np.isfinite(p).all():
            bad = tuple(np.argwhere(~np.isfinite(p).all(axis=-1))[0].tolist())
            where = f" {bad}" if bad else ""
            raise ValueError(f"poses must be finite numbers; pose{where} is {p[bad].tolist()}")
        shape = p.shape[:-1]
        p = p.reshape(-1, 6)
        ref = np.broadcast_to(self._reference_batch(near, shape), (*shape, 6)).reshape(-1, 6)
        solutions, valid = np.empty((len(p), 8, 6)), np.empty((len(p), 8), dtype=bool)
        best = np.empty((len(p), 6))
        for start in range(0, len(p), _CHUNK):
            rows = slice(start, start + _CHUNK)
            self._solve_batch(p[rows], ref[rows], solutions[rows], valid[rows], best[rows])
        reachable = valid.any(axis=-1)
        return InverseBatch(
            solutions=solutions.reshape(*shape, 8, 6),
            valid=valid.reshape(*shape, 8),
            best=best.reshape(*shape, 6),
            reachable=reachable.reshape(shape),
        )

    def _solve_batch(self, p: np.ndarray, near: np.ndarray, out: np.ndarray,
                     valid: np.ndarray, best: np.ndarray) -> None:
        """Fitted branches of poses ``p: (N, 6)`` into ``out: (N, 8, 6)`` (NaN where
        invalid), ``valid: (N, 8)`` and the nearest valid one into ``best: (N, 6)`` (NaN
        where none).

        The equations of ``_branches`` and the limits of ``_fit``, on arrays of one
        joint each: Rotate for both θ1 branches ``(2, N)``, then the rest only for the
        pairs of θ1 branch and pose whose Rotate is inside its limits, one wrist and root
        branch at a time, written into their slots; a root that none of them has inside
        In/Out's limits is not solved further. The second wrist branch (−θ5, θ6 + 180°)
        negates z4, and Swivel's sine and cosine are −z1·o / sθ5 and z1·n / sθ5; the
        slots of a singular wrist's held Bend are solved apart (``_hold_bend_into``).
        """
        x, y, z, g, b, al = p.T
        g, b, al = np.radians(g), np.radians(b), np.radians(al)
        cg, sg, cb, sb, ca, sa = np.cos(g), np.sin(g), np.cos(b), np.sin(b), np.cos(al), np.sin(al)
        n = (ca * cb, sa * cb, -sb)  # eq. 4.04, as xyz_fixed.rotation
        o = (ca * sb * sg - sa * cg, sa * sb * sg + ca * cg, cb * sg)
        a = (ca * sb * cg + sa * sg, sa * sb * cg - ca * sg, cb * cg)
        w = (x - self.ly * a[0], y - self.ly * a[1], z - self.ly * a[2])  # eq. 4.14
        ref = near.T.copy()  # joint, N
        on_axis = np.maximum(np.abs(w[0]), np.abs(w[1])) <= ARM_TOL  # hypot ≥ the larger
        if on_axis.any():
            on_axis &= np.hypot(w[0], w[1]) <= ARM_TOL
        phi = np.where(on_axis, np.radians(ref[1]), np.arctan2(w[1], w[0]))
        t1 = phi + _HALF_TURN[:, None]  # axes (θ1 branch, N)
        rotate, ok_rotate = self._fit_joint(1, np.degrees(t1), ref[1])

        live = np.flatnonzero(ok_rotate)  # (θ1 branch, pose) pairs, one axis from here on
        pose = live % len(p)
        t1, rotate = np.take(t1, live), np.take(rotate, live)
        n, o, a, w = ([v[pose] for v in vector] for vector in (n, o, a, w))
        ref = np.take(ref, pose, axis=1)
        s1, c1 = np.sin(t1), np.cos(t1)
        zn = s1 * n[0] - c1 * n[1]
        zo = s1 * o[0] - c1 * o[1]
        za = s1 * a[0] - c1 * a[1]
        s5 = np.sqrt(zn * zn + zo * zo)
        singular = s5 <= WRIST_TOL
        t5 = np.arctan2(s5, za)  # eq. 4.16
        t6 = np.arctan2(-zo, zn)  # eq. 4.15
        if singular.any():  # Swivel held at near's
            t6 = np.where(singular, np.radians(ref[5]), t6)
            s5 = np.where(singular, 1.0, s5)
            zn = np.where(singular, np.cos(t6), zn)
            zo = np.where(singular, -np.sin(t6), zo)
        s6, c6 = -zo / s5, zn / s5
        z4 = [-(s6 * n[k] + c6 * o[k]) for k in range(3)]
        near_rotate = np.abs(rotate - ref[1])
        first = pose * 8 + (live >= len(p)) * 4  # slot of wrist branch 0, root 0
        order = (live >= len(p)) * (4 * len(p)) + pose  # the same in travel's order
        out.fill(np.nan)
        valid.fill(False)
        travel = np.full((8, len(p)), np.inf)  # slot, pose
        for i, sign in enumerate((1.0, -1.0)):  # wrist branches: θ5, then −θ5, θ6 + 180°
            zx, zy, zz = (z4 if i == 0 else [-v for v in z4])
            rho = c1 * (w[0] - self.lb * zx) + s1 * (w[1] - self.lb * zy)  # App. A (8)
            h = w[2] - self.lb * zz - self.d1  # App. A (9)
            disc = rho * rho + h * h - self.a2 * self.a2
            root = np.sqrt(np.maximum(disc, 0.0))
            yaw, ok_yaw = self._fit_joint(4, np.degrees(sign * t5), ref[4])
            swivel, ok_swivel = self._fit_joint(5, np.degrees(t6 if i == 0 else t6 + np.pi),
                                                ref[5])
            ok_wrist = ok_yaw & ok_swivel & (disc >= 0.0)
            common = near_rotate + np.abs(yaw - ref[4]) + np.abs(swivel - ref[5])
            t24 = shoulder = None
            for k, d3 in enumerate((root, -root)):  # eq. 4.17's two roots
                in_out, ok_root = self._fit_joint(0, d3, ref[0])
                ok_root &= ok_wrist if k == 0 else ok_wrist & (root > ROOT_TOL)
                if not ok_root.any():  # e.g. −√ on an arm whose In/Out is positive
                    continue
                if t24 is None or shoulder is None:
                    t24 = np.arctan2(zz, c1 * zx + s1 * zy)  # eq. 4.18
                    shoulder = np.arctan2(h, rho)
                t2 = shoulder - np.arctan2(self.a2, d3)  # errata #8
                up, ok_up = self._fit_joint(2, np.degrees(t2), ref[2])
                bend, ok_bend = self._fit_joint(3, np.degrees(t24 - t2), ref[3])
                ok = ok_root & ok_up & ok_bend
                slot = first + (2 * i + k)
                valid.ravel()[slot] = ok
                nan = np.where(ok, 0.0, np.nan)  # x + 0.0 is x: NaN where invalid
                for j, value in enumerate((in_out, rotate, up, bend, yaw, swivel)):
                    out.ravel()[slot * 6 + j] = value + nan
                travel.ravel()[order + (2 * i + k) * len(p)] = np.where(
                    ok, np.abs(in_out - ref[0]) * _WEIGHTS[0] + common
                    + np.abs(up - ref[2]) + np.abs(bend - ref[3]), np.inf)
        if singular.any():
            held = np.flatnonzero(singular)
            self._hold_bend_into(out, valid, travel, near, pose[held], live[held] >= len(p),
                                 *(np.stack(v, axis=-1)[held] for v in (w, n, o)), t1[held],
                                 t5[held])
        nearest, shortest = np.zeros(len(p), dtype=np.intp), travel[0]
        for k in range(1, 8):  # argmin over the slots, the first of equals, along the poses
            shorter = travel[k] < shortest
            nearest[shorter], shortest = k, np.where(shorter, travel[k], shortest)
        # NaN where no slot is valid
        best[...] = out.reshape(-1, 6)[np.arange(0, 8 * len(p), 8) + nearest]

    def _hold_bend_into(self, out: np.ndarray, valid: np.ndarray, travel: np.ndarray,
                        near: np.ndarray, rows: np.ndarray, branch: np.ndarray, w: np.ndarray,
                        n: np.ndarray, o: np.ndarray, t1: np.ndarray, t5: np.ndarray) -> None:
        """``_solve_batch``'s slots of wrist branch 1 of the poses ``rows: (K,)`` whose wrist
        is singular on θ1 ``branch``, solved with Bend held at near's (``_hold_bend_batch``
        from their w, n, o ``(K, 3)``, θ1 and θ5), fitted and written over theirs, and the
        repeats of the two held joints made invalid: ``out``, ``valid``, ``travel: (8, N)``
        updated."""
        held, inside = self._hold_bend_batch(w, n, o, t1, t5, near[rows, 3])
        for j in range(6):
            held[..., j], within = self._fit_joint(j, held[..., j], near[rows, j, None])
            inside &= within
        out.reshape(-1, 2, 2, 2, 6)[rows, branch.astype(np.intp), 1] = held
        valid.reshape(-1, 2, 2, 2)[rows, branch.astype(np.intp), 1] = inside
        many = np.unique(rows)
        valid[many] &= ~_repeats(out[many], valid[many])
        solutions = np.where(valid[many, :, None], out[many], np.nan)
        out[many] = solutions
        travel[:, many] = np.where(valid[many], distance(solutions, near[many, None]), np.inf).T

    def _reference(self, near: ArrayLike | None) -> list[float]:
        """``near`` of ``inverse`` as 6 floats, the middle of the limits if None."""
        return list(self.mid_range) if near is None else _vector(near, "near")

    def _reference_batch(self, near: ArrayLike | None, shape: tuple[int, ...]) -> np.ndarray:
        """``near`` of ``inverse_batch``, ``(6,)`` or ``(*shape, 6)``, checked."""
        if near is None:
            return np.array(self.mid_range)
        ref = np.asarray(near, dtype=float)
        if ref.shape != (6,) and ref.shape != (*shape, 6):
            raise ValueError(f"near must have shape (6,) or {(*shape, 6)}, got {ref.shape}")
        if not np.isfinite(ref).all():
            raise ValueError("near must be finite numbers; got NaN or inf")
        return ref

    def _solutions(self, target: list[float], near: list[float]) -> tuple[list[list[float]], bool]:
        """The in-limit branches of one pose in slot order, fitted (``_fit``), and whether
        the wrist is singular: ``_branches`` and ``_fit`` with the same arithmetic, each
        branch given up at its first joint outside the limits."""
        lo, hi, fast = self.lower, self.upper, self._unwrapped
        x, y, z = target[:3]
        g, b, al = target[3] * _RAD, target[4] * _RAD, target[5] * _RAD
        cg, sg, cb, sb, ca, sa = (
            math.cos(g), math.sin(g), math.cos(b), math.sin(b), math.cos(al), math.sin(al),
        )
        n0, n1, n2 = ca * cb, sa * cb, -sb  # eq. 4.04
        o0, o1, o2 = ca * sb * sg - sa * cg, sa * sb * sg + ca * cg, cb * sg
        a0, a1, a2 = ca * sb * cg + sa * sg, sa * sb * cg - ca * sg, cb * cg
        ly, lb = self.ly, self.lb
        w0, w1, w2 = x - ly * a0, y - ly * a1, z - ly * a2  # eq. 4.14
        phi = near[1] * _RAD if math.hypot(w0, w1) <= ARM_TOL else math.atan2(w1, w0)
        in_lo, in_hi = lo[0] - LIMIT_TOL, hi[0] + LIMIT_TOL
        offset = self.a2
        out: list[list[float]] = []
        singular = False
        for t1 in (phi, phi + math.pi):
            s1, c1 = math.sin(t1), math.cos(t1)
            zn, zo = s1 * n0 - c1 * n1, s1 * o0 - c1 * o1
            s5 = math.hypot(zn, zo)
            singular = singular or s5 <= WRIST_TOL
            v = t1 * _DEG
            rotate = v + 0.0 if fast[1][0] <= v <= fast[1][1] else _wrap(v, lo[1], hi[1], near[1])
            if rotate is None:
                continue
            t5 = math.atan2(s5, s1 * a0 - c1 * a1)  # eq. 4.16
            if s5 > WRIST_TOL:
                t6 = math.atan2(-zo, zn)  # eq. 4.15
                wrists: tuple[tuple[float, float], ...] = ((t5, t6), (-t5, t6 + math.pi))
            else:  # Swivel held at near's
                wrists = ((t5, near[5] * _RAD),)
            for t5w, t6w in wrists:
                v = t5w * _DEG
                yaw = v + 0.0 if fast[4][0] <= v <= fast[4][1] else _wrap(v, lo[4], hi[4], near[4])
                if yaw is None:
                    continue
                v = t6w * _DEG
                swivel = (v + 0.0 if fast[5][0] <= v <= fast[5][1]
                          else _wrap(v, lo[5], hi[5], near[5]))
                if swivel is None:
                    continue
                s6, c6 = math.sin(t6w), math.cos(t6w)
                z40, z41, z42 = -s6 * n0 - c6 * o0, -s6 * n1 - c6 * o1, -s6 * n2 - c6 * o2
                rho = c1 * (w0 - lb * z40) + s1 * (w1 - lb * z41)  # App. A (8)
                h = w2 - lb * z42 - self.d1  # App. A (9)
                disc = rho * rho + h * h - offset * offset
                if disc < 0.0:
                    continue
                root = math.sqrt(disc)
                t24 = None
                for d3 in (root, -root) if root > ROOT_TOL else (root,):
                    if not in_lo <= d3 <= in_hi:
                        continue
                    t2 = math.atan2(h, rho) - math.atan2(offset, d3)  # eq. 4.17, errata #8
                    v = t2 * _DEG
                    up = (v + 0.0 if fast[2][0] <= v <= fast[2][1]
                          else _wrap(v, lo[2], hi[2], near[2]))
                    if up is None:
                        continue
                    if t24 is None:
                        t24 = math.atan2(z42, c1 * z40 + s1 * z41)  # eq. 4.18
                    v = (t24 - t2) * _DEG
                    bend = (v + 0.0 if fast[3][0] <= v <= fast[3][1]
                            else _wrap(v, lo[3], hi[3], near[3]))
                    if bend is not None:
                        out.append([min(max(d3, lo[0]), hi[0]), rotate, up, bend, yaw, swivel])
            if s5 <= WRIST_TOL:
                for q in self._hold_bend((w0, w1, w2), (n0, n1, n2), (o0, o1, o2), t1, t5,
                                         near[3]):
                    fitted = self._fit(q, near)
                    if fitted is not None:
                        out.append(fitted)
        return out, singular

    def _branches(
        self, target: list[float], near: list[float]
    ) -> tuple[list[list[float]], float, bool]:
        """Raw branches of one pose in slot order (deg, unwrapped); the largest distance
        from the Up/Down axis (mm) of an arm point without a real θ2 root (0 if none);
        whether the wrist is singular."""
        x, y, z = target[:3]
        g, b, al = (math.radians(v) for v in target[3:])
        cg, sg, cb, sb, ca, sa = (
            math.cos(g), math.sin(g), math.cos(b), math.sin(b), math.cos(al), math.sin(al),
        )
        n = (ca * cb, sa * cb, -sb)  # eq. 4.04
        o = (ca * sb * sg - sa * cg, sa * sb * sg + ca * cg, cb * sg)
        a = (ca * sb * cg + sa * sg, sa * sb * cg - ca * sg, cb * cg)
        w = (x - self.ly * a[0], y - self.ly * a[1], z - self.ly * a[2])  # eq. 4.14
        on_axis = math.hypot(w[0], w[1]) <= ARM_TOL
        phi = math.radians(near[1]) if on_axis else math.atan2(w[1], w[0])
        out: list[list[float]] = []
        radius = 0.0
        singular = False
        for t1 in (phi, phi + math.pi):
            s1, c1 = math.sin(t1), math.cos(t1)
            zn, zo, za = s1 * n[0] - c1 * n[1], s1 * o[0] - c1 * o[1], s1 * a[0] - c1 * a[1]
            s5 = math.hypot(zn, zo)
            t5 = math.atan2(s5, za)  # eq. 4.16
            if s5 > WRIST_TOL:
                t6 = math.atan2(-zo, zn)  # eq. 4.15
                wrists = ((t5, t6), (-t5, t6 + math.pi))
            else:
                singular = True
                wrists = ((t5, math.radians(near[5])),)
            for t5w, t6w in wrists:
                s6, c6 = math.sin(t6w), math.cos(t6w)
                z4 = (-s6 * n[0] - c6 * o[0], -s6 * n[1] - c6 * o[1], -s6 * n[2] - c6 * o[2])
                rho = c1 * (w[0] - self.lb * z4[0]) + s1 * (w[1] - self.lb * z4[1])  # App. A (8)
                h = w[2] - self.lb * z4[2] - self.d1  # App. A (9)
                disc = rho * rho + h * h - self.a2 * self.a2
                if disc < 0.0:
                    radius = max(radius, math.hypot(rho, h))
                    continue
                root = math.sqrt(disc)
                t24 = math.atan2(z4[2], c1 * z4[0] + s1 * z4[1])  # eq. 4.18
                for d3 in (root, -root) if root > ROOT_TOL else (root,):
                    t2 = math.atan2(h, rho) - math.atan2(self.a2, d3)  # eq. 4.17, errata #8
                    out.append([
                        d3, math.degrees(t1), math.degrees(t2), math.degrees(t24 - t2),
                        math.degrees(t5w), math.degrees(t6w),
                    ])
            if s5 <= WRIST_TOL:
                out.extend(self._hold_bend(w, n, o, t1, t5, near[3]))
        return out, radius, singular

    def _hold_bend(self, w: tuple[float, ...], n: tuple[float, ...], o: tuple[float, ...],
                   t1: float, t5: float, bend: float) -> list[list[float]]:
        """Wrist-singular branches with Bend held at ``bend`` (deg), up to 2.

        With z4 = Rot(θ2 + θ4)·x1 in the arm plane, App. A (8), (9) become
        (ρw, hw) = Rot(θ2)·(d3 + Lb·cθ4, a2 + Lb·sθ4): eq. 4.17's form with a
        longer offset. Swivel then follows from z4 = −(sθ6·n + cθ6·o).
        """
        s1, c1 = math.sin(t1), math.cos(t1)
        s4, c4 = math.sin(math.radians(bend)), math.cos(math.radians(bend))
        rho, h = c1 * w[0] + s1 * w[1], w[2] - self.d1
        offset = self.a2 + self.lb * s4
        disc = rho * rho + h * h - offset * offset
        if disc < 0.0:
            return []
        root = math.sqrt(disc)
        out = []
        for reach in (root, -root) if root > ROOT_TOL else (root,):
            t2 = math.atan2(h, rho) - math.atan2(offset, reach)
            psi = t2 + math.radians(bend)
            z4 = (c1 * math.cos(psi), s1 * math.cos(psi), math.sin(psi))
            t6 = math.atan2(-(z4[0] * n[0] + z4[1] * n[1] + z4[2] * n[2]),
                            -(z4[0] * o[0] + z4[1] * o[1] + z4[2] * o[2]))
            out.append([reach - self.lb * c4, math.degrees(t1), math.degrees(t2), bend,
                        math.degrees(t5), math.degrees(t6)])
        return out

    def _hold_bend_batch(self, w: np.ndarray, n: np.ndarray, o: np.ndarray, t1: np.ndarray,
                         t5: np.ndarray, bend: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``_hold_bend`` of K singular wrists → ``(K, 2, 6)`` (deg), exists ``(K, 2)``."""
        s1, c1 = np.sin(t1)[:, None], np.cos(t1)[:, None]
        t4 = np.radians(bend)[:, None]
        s4, c4 = np.sin(t4), np.cos(t4)
        rho, h = c1 * w[:, 0, None] + s1 * w[:, 1, None], w[:, 2, None] - self.d1
        offset = self.a2 + self.lb * s4
        disc = rho * rho + h * h - offset * offset
        root = np.sqrt(np.maximum(disc, 0.0))
        reach = root * np.array([1.0, -1.0])
        t2 = np.arctan2(h, rho) - np.arctan2(offset, reach)
        psi = t2 + t4
        z4 = np.stack([c1 * np.cos(psi), s1 * np.cos(psi), np.sin(psi)], axis=-1)
        t6 = np.arctan2(-(z4 * n[:, None]).sum(-1), -(z4 * o[:, None]).sum(-1))
        d3 = reach - self.lb * c4
        angles = np.degrees(np.broadcast_arrays(t1[:, None], t2, t4, t5[:, None], t6))
        exists = np.concatenate([disc >= 0.0, root > ROOT_TOL], axis=-1)
        return np.stack([d3, *angles], axis=-1), exists

    def _fit(self, q: list[float], near: list[float]) -> list[float] | None:
        """``q`` with each angle moved to its in-limit ±360° copy nearest ``near``
        and clipped onto a limit it touches within LIMIT_TOL, or None if outside."""
        lo, hi = self.lower, self.upper
        if not lo[0] - LIMIT_TOL <= q[0] <= hi[0] + LIMIT_TOL:
            return None
        out = [min(max(q[0], lo[0]), hi[0])]
        for j in range(1, 6):
            v = _wrap(q[j], lo[j], hi[j], near[j])
            if v is None:
                return None
            out.append(v)
        return out

    def _fit_joint(self, j: int, value: np.ndarray, near: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
        """``_fit`` of joint ``j``'s values (mm, deg; any shape, ``near`` broadcast with
        them) → fitted, inside: ``_wrap``'s arithmetic, elementwise."""
        lo, hi = self.lower[j], self.upper[j]
        base, top = lo - LIMIT_TOL, hi + LIMIT_TOL
        if j == 0:
            return np.clip(value, lo, hi) + 0.0, (value >= base) & (value <= top)
        low_copy = value - 360.0 * np.floor((value - base) / 360.0)
        inside = low_copy <= top
        if top - base < 359.0:  # one copy at most is inside: no turns to add
            return np.clip(low_copy, lo, hi) + 0.0, inside  # + 0.0 turns -0.0 into 0.0
        turns = np.clip(np.round((near - low_copy) / 360.0),
                        0.0, np.floor((top - low_copy) / 360.0))
        return np.clip(low_copy + 360.0 * turns, lo, hi) + 0.0, inside

    def _why(self, raw: list[list[float]], radius: float, held: list[float] | None) -> str:
        """The reason no branch of a pose is usable, for Unreachable; ``held`` is
        ``near`` when the wrist was singular and joints were held at it."""
        hint = ("" if held is None else
                f" (wrist singular: Swivel held at {held[5]:g}° or Bend at {held[3]:g}° "
                f"from near; another near may reach it)")
        if not raw:
            return (f"out of reach: the arm point is {radius:.1f} mm from the Up/Down axis, "
                    f"inside the a2 = {self.a2:g} mm offset (eq. 4.17 has no real root){hint}")
        closest = min((self._violations(q) for q in raw), key=lambda v: sum(c for *_, c in v))
        parts = []
        for j, value, _ in closest:
            lo, hi = self.lower[j], self.upper[j]
            if j == 0:
                gap = (f"{value - hi:.1f} mm beyond" if value > hi
                       else f"{lo - value:.1f} mm short of")
                parts.append(f"In/Out would be {value:.1f} mm, {gap} {lo:g}…{hi:g} mm")
            else:
                parts.append(f"{JOINTS[j]} would be {value:.1f}°, outside {lo:g}…{hi:g}°")
        head = "out of reach" if closest[0][0] == 0 else "outside the joint limits"
        return f"{head}: {'; '.join(parts)}{hint}"

    def _violations(self, q: list[float]) -> list[tuple[int, float, float]]:
        """(joint, value, weighted excess) for each joint of ``q`` outside its limits;
        an angle is taken at its ±360° copy nearest the middle of its range."""
        out = []
        for j, (v, lo, hi) in enumerate(zip(q, self.lower, self.upper, strict=True)):
            if j:
                mid = (lo + hi) / 2
                v = mid + (v - mid + 180.0) % 360.0 - 180.0
            excess = max(lo - v, v - hi)
            if excess > LIMIT_TOL:
                out.append((j, v, excess * _WEIGHTS[j]))
        return out


def _repeats(q: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Slots of ``q: (N, 8, 6)`` that repeat a valid earlier slot → ``(N, 8)``.

    Only a singular wrist's two held joints can meet (every other pair differs
    by 180° in θ1 or θ6, or in the sign of a root), so wrist branch 1 is
    compared with wrist branch 0 of the same θ1 branch.
    """
    q, valid = q.reshape(-1, 2, 2, 2, 6), valid.reshape(-1, 2, 2, 2)
    gap = np.abs(q[:, :, 1, :, None] - q[:, :, 0, None, :]).max(axis=-1)
    repeats = np.zeros_like(valid)
    repeats[:, :, 1] = ((gap <= SAME_TOL) & valid[:, :, 0, None, :]).any(axis=-1)
    return repeats.reshape(-1, 8)


def _wrap(v: float, lo: float, hi: float, near: float) -> float | None:
    """The ±360° copy of angle ``v`` inside lo…hi nearest ``near``, clipped onto a
    limit it touches within LIMIT_TOL; None if no copy is inside (deg)."""
    base, top = lo - LIMIT_TOL, hi + LIMIT_TOL
    v -= 360.0 * math.floor((v - base) / 360.0)
    if v > top:
        return None
    turns = round((near - v) / 360.0)
    if turns > 0:
        v += 360.0 * min(turns, math.floor((top - v) / 360.0))
    return min(max(v, lo), hi) + 0.0  # + 0.0 turns -0.0 into 0.0


def distance(q: ArrayLike, near: ArrayLike) -> np.ndarray:
    """Ranking metric of joint vectors ``(..., 6)``, broadcast together:
    Σ|Δθ| (deg) + |Δd3| / MM_PER_DEGREE."""
    return (np.abs(np.asarray(q, dtype=float) - near) * _WEIGHTS).sum(axis=-1)


def _overflow(p: Sequence[float]) -> str:
    """Why a pose has no finite solution: its position, the largest coordinate named."""
    k = max(range(3), key=lambda i: abs(p[i]))
    return (f"{'xyz'[k]} {p[k]:g} mm is too large: the inverse kinematics squares the "
            "distances of the wrist point (eq. 4.17) and overflows; give a position within "
            "the arm's reach")


def _same(q: Sequence[float], u: Sequence[float]) -> bool:
    """Whether two joint vectors are one solution (every joint within SAME_TOL)."""
    return all(abs(a - b) <= SAME_TOL for a, b in zip(q, u, strict=True))


def _distance(q: Sequence[float], near: Sequence[float]) -> float:
    """``distance`` of one pair of joint vectors, in plain floats for ``inverse``."""
    return abs(q[0] - near[0]) / MM_PER_DEGREE + sum(
        abs(v - r) for v, r in zip(q[1:], near[1:], strict=True)
    )


def _row(link: DHLink) -> str:
    kind = "prismatic" if link.prismatic else "revolute"
    return (f"α {link.alpha_deg:g}°, a {link.a:g} mm, d {link.d:g} mm, θ {link.theta_deg:g}° "
            f"({kind})")


def _vector(v: ArrayLike, what: str) -> list[float]:
    """One finite 6-vector as floats; ValueError naming ``what`` otherwise."""
    if type(v) is np.ndarray and v.dtype == np.float64 and v.shape == (6,):
        values = v.tolist()  # what a caller usually passes, without asarray's cost
    else:
        arr = np.asarray(v, dtype=float)
        if arr.shape != (6,):
            raise ValueError(f"{what} must have 6 values, got shape {arr.shape}")
        values = arr.tolist()
    if not all(map(math.isfinite, values)):
        raise ValueError(f"{what} must be finite numbers, got {values}")
    return values

