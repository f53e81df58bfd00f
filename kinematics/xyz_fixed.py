"""X-Y-Z fixed angles, thesis section 4.3.

A frame is rotated by γ about the fixed x axis, then β about the fixed y axis,
then α about the fixed z axis, so ``R = Rz(α) · Ry(β) · Rx(γ)`` (eq. 4.04).
Angles are radians; everything is batch-first: angle arrays ``(...)`` give
rotations ``(..., 3, 3)`` and back.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

# cos β = hypot(r11, r21) at or below this counts as β = ±90° (errata #15): α and γ
# are then not separable and α is reported as 0. Setting α = 0 moves the
# rotation by at most 2·GIMBAL_TOL, so this is round-off sized.
GIMBAL_TOL = 1e-12


def rotation(gamma: ArrayLike, beta: ArrayLike, alpha: ArrayLike) -> np.ndarray:
    """Rotation matrix of X-Y-Z fixed angles γ, β, α (rad, broadcast together) → ``(..., 3, 3)``.

    eq. 4.04; the thesis prints r22 as ``sα sβ sγ − cα cγ``, the listing's
    Inverse_calc (and the product Rz Ry Rx) has ``+ cα cγ``, used here.
    """
    g, b, a = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (gamma, beta, alpha)))
    cg, sg = np.cos(g), np.sin(g)
    cb, sb = np.cos(b), np.sin(b)
    ca, sa = np.cos(a), np.sin(a)
    r = np.empty((*g.shape, 3, 3))
    r[..., 0, 0] = ca * cb
    r[..., 0, 1] = ca * sb * sg - sa * cg
    r[..., 0, 2] = ca * sb * cg + sa * sg
    r[..., 1, 0] = sa * cb
    r[..., 1, 1] = sa * sb * sg + ca * cg
    r[..., 1, 2] = sa * sb * cg - ca * sg
    r[..., 2, 0] = -sb
    r[..., 2, 1] = cb * sg
    r[..., 2, 2] = cb * cg
    return r


def angles(r: ArrayLike) -> np.ndarray:
    """X-Y-Z fixed angles of rotation matrices ``r: (..., 3, 3)`` → ``(..., 3)`` as γ, β, α (rad).

    β ∈ [-π/2, π/2] and α from eq. 4.05. γ comes from the residual rotation
    ``Rx(γ) = Ry(β)ᵀ Rz(α)ᵀ R``: for an exact rotation that is eq. 4.05's
    ``atan2(r32, r33)``, and it stays exact as β → ±90°, where eq. 4.05's α and
    γ are both undefined. There (cos β < GIMBAL_TOL) α = 0 and γ reduces to
    ``atan2(sβ·r12, r22)`` (errata #15), so ``rotation(*angles(R))`` gives R back.
    """
    r = np.asarray(r, dtype=float)
    if r.shape[-2:] != (3, 3):
        raise ValueError(f"expected rotation matrices of shape (..., 3, 3), got {r.shape}")
    cos_beta = np.hypot(r[..., 0, 0], r[..., 1, 0])
    beta = np.arctan2(-r[..., 2, 0], cos_beta)  # eq. 4.05
    alpha = np.where(cos_beta > GIMBAL_TOL, np.arctan2(r[..., 1, 0], r[..., 0, 0]), 0.0)
    ca, sa = np.cos(alpha), np.sin(alpha)
    gamma = np.arctan2(
        np.sin(beta) * (ca * r[..., 0, 1] + sa * r[..., 1, 1]) + np.cos(beta) * r[..., 2, 1],
        ca * r[..., 1, 1] - sa * r[..., 0, 1],
    )
    return np.stack([gamma, beta, alpha], axis=-1)
