"""Denavit–Hartenberg chains, thesis section 4.2.

A link's homogeneous transform ``A_i^{i-1}`` (eq. 4.02) maps coordinates in
frame i to frame i-1; the product along a chain (eq. 4.03) maps the last frame
to the base. Angles are degrees at the API (the operator's unit), lengths mm.
Everything is batch-first: joint arrays ``(..., n)`` give transforms
``(..., 4, 4)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike


@dataclass(frozen=True)
class DHLink:
    """One row of a standard DH table (Table 4.1).

    ``alpha_deg`` is the twist α_i (deg), ``a`` the common-normal length a_i
    (mm), ``d`` the offset d_i (mm), ``theta_deg`` the angle θ_i (deg). The
    joint variable adds to θ for a revolute joint (deg) or to d for a
    prismatic one (mm), so the constant parts are offsets.
    """

    alpha_deg: float
    a: float
    d: float
    theta_deg: float
    prismatic: bool = False

    def transform(self, q: ArrayLike) -> np.ndarray:
        """``A_i^{i-1}`` (eq. 4.02) at joint values ``q: (...)`` (deg or mm) → ``(..., 4, 4)``."""
        q = np.asarray(q, dtype=float)
        if self.prismatic:
            theta = np.full(q.shape, np.radians(self.theta_deg))
            d = self.d + q
        else:
            theta = np.radians(self.theta_deg + q)
            d = np.full(q.shape, self.d)
        ct, st = np.cos(theta), np.sin(theta)
        alpha = np.radians(self.alpha_deg)
        ca, sa = np.cos(alpha), np.sin(alpha)
        out = np.zeros((*q.shape, 4, 4))
        out[..., 0, 0] = ct
        out[..., 0, 1] = -st * ca
        out[..., 0, 2] = st * sa
        out[..., 0, 3] = self.a * ct
        out[..., 1, 0] = st
        out[..., 1, 1] = ct * ca
        out[..., 1, 2] = -ct * sa
        out[..., 1, 3] = self.a * st
        out[..., 2, 1] = sa
        out[..., 2, 2] = ca
        out[..., 2, 3] = d
        out[..., 3, 3] = 1.0
        return out


def forward(links: Sequence[DHLink], q: ArrayLike) -> np.ndarray:
    """Base-to-last-frame transform ``T = A_1^0 A_2^1 … A_n^{n-1}`` (eq. 4.03).

    ``q: (..., n)`` joint values in DH order (deg for revolute links, mm for
    prismatic ones) → ``(..., 4, 4)`` with the position in mm. Raises
    ValueError if ``q`` has the wrong length or a NaN/inf.
    """
    q = _checked(links, q)
    t = links[0].transform(q[..., 0])
    for i, link in enumerate(links[1:], start=1):
        t = t @ link.transform(q[..., i])
    return t


def frames(links: Sequence[DHLink], q: ArrayLike) -> np.ndarray:
    """Every frame of the chain in the base frame: ``T_0^0 = I, T_1^0, …, T_n^0`` (eq. 4.03's
    partial products), for drawing the links.

    ``q: (..., n)`` as ``forward`` → ``(..., n + 1, 4, 4)``; the last frame is ``forward``'s.
    Raises ValueError as ``forward`` does.
    """
    q = _checked(links, q)
    out = np.empty((*q.shape[:-1], len(links) + 1, 4, 4))
    out[..., 0, :, :] = np.eye(4)
    for i, link in enumerate(links):
        out[..., i + 1, :, :] = out[..., i, :, :] @ link.transform(q[..., i])
    return out


def _checked(links: Sequence[DHLink], q: ArrayLike) -> np.ndarray:
    """``q`` as a float array of shape ``(..., len(links))``; ValueError says what is wrong."""
    if not links:
        raise ValueError("a DH chain needs at least one link")
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != len(links):
        raise ValueError(f"expected joint values of shape (..., {len(links)}), got {q.shape}")
    if not np.isfinite(q).all():
        raise ValueError("joint values must be finite numbers; got NaN or inf")
    return q
