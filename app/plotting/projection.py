"""Orthographic views of the base frame (x, y, z mm; z up) onto a braille raster's pixels.

A view looks at the scene from ``azimuth`` (about z) and ``elevation`` (above the floor):
its screen axes are ``u`` (right), ``v`` (up) and the line of sight ``d`` (into the screen)::

    u = (cos az, sin az, 0)        f = (−sin az, cos az, 0)
    d = cos el · f − sin el · z     v = u × d

so the front view (0°, 0°) shows x to the right and z up, looking along +y; the side view
(90°, 0°) y to the right, from +x; the top view (0°, 90°) x right and y up. A braille pixel
is half a cell wide and a quarter of it high, which a terminal's 1:2 cell makes square, so
one scale (pixels per mm) serves both axes and a sphere stays round.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

ZOOM_RANGE = (0.25, 8.0)
ISOMETRIC_ELEVATION = math.degrees(math.atan(1 / math.sqrt(2)))  # 35.26°: the cube's diagonal


@dataclass(frozen=True)
class View:
    """Where the scene is seen from (deg) and how close (``zoom`` 1: the workspace fills it)."""

    name: str
    azimuth_deg: float
    elevation_deg: float
    zoom: float = 1.0

    def orbited(self, d_azimuth: float, d_elevation: float) -> View:
        """Turned about z by ``d_azimuth`` and tilted by ``d_elevation`` (kept within ±90°)."""
        elevation = min(90.0, max(-90.0, self.elevation_deg + d_elevation))
        azimuth = (self.azimuth_deg + d_azimuth + 180.0) % 360.0 - 180.0
        return replace(self, name="orbit", azimuth_deg=azimuth, elevation_deg=elevation)

    def zoomed(self, factor: float) -> View:
        return replace(self, zoom=min(ZOOM_RANGE[1], max(ZOOM_RANGE[0], self.zoom * factor)))

    def axes(self) -> np.ndarray:
        """``(3, 3)``: the rows u (right), v (up), d (into the screen), unit vectors."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        u = np.array([math.cos(az), math.sin(az), 0.0])
        f = np.array([-math.sin(az), math.cos(az), 0.0])
        d = math.cos(el) * f - math.sin(el) * np.array([0.0, 0.0, 1.0])
        return np.stack([u, np.cross(u, d), d])


VIEWS = {
    "front": View("front", 0.0, 0.0),
    "side": View("side", 90.0, 0.0),
    "top": View("top", 0.0, 90.0),
    "isometric": View("isometric", -45.0, ISOMETRIC_ELEVATION),
}


@dataclass(frozen=True)
class Projection:
    """Base-frame points (mm) → raster pixels: column ``x`` from the left, row ``y`` from the
    top, ``(width_px, height_px)`` pixels. ``centre`` (3,) lands on the raster's middle."""

    axes: np.ndarray
    centre: np.ndarray
    scale: float  # pixels per mm
    width_px: int
    height_px: int

    def pixels(self, points: ArrayLike) -> np.ndarray:
        """``(..., 3)`` mm → ``(..., 2)`` pixel (column, row), fractional, maybe off the raster."""
        screen = (np.asarray(points, dtype=float) - self.centre) @ self.axes[:2].T
        col = self.width_px / 2 + self.scale * screen[..., 0]
        row = self.height_px / 2 - self.scale * screen[..., 1]
        return np.stack([col, row], axis=-1)


def fit(view: View, extent: ArrayLike, width_px: int, height_px: int,
        margin: float = 0.04) -> Projection:
    """The projection of ``view`` that shows the points ``extent (K, 3)`` (the workspace's
    corners) whole at zoom 1, centred, with ``margin`` of the raster spare on each side."""
    axes = view.axes()
    corners = np.asarray(extent, dtype=float)
    screen = corners @ axes[:2].T
    low, high = screen.min(axis=0), screen.max(axis=0)
    span = np.maximum(high - low, 1e-9)
    room = (1.0 - 2 * margin) * np.array([width_px, height_px], dtype=float)
    scale = view.zoom * float(min(room / span))
    middle = (low + high) / 2
    centre = middle[0] * axes[0] + middle[1] * axes[1]
    return Projection(axes, centre, scale, width_px, height_px)
