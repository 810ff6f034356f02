"""The tub's inner surface as exact analytic surfaces in the tub frame (tub47.md, "Tub").

Cross-section (x-z): a U made of a half circle of radius R centred at (0, R) (so the lowest point
of the inner surface is the origin) and two vertical walls x = -R and x = +R from z = R up to the
rim.  The two pieces meet with a common tangent at z = R, so the nearest point of the surface to
any interior point is unique: on the circle when z <= R, on the nearer vertical wall above.
Length direction: flat partitions at y = 0 and y = length (or a periodic length instead).

The DEM (ball-wall contacts), the continuum solvers (grid boundary), the analysis (masks, wall
positions) and the LIGGGHTS exporter (STL) all use this module.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np


@dataclass(frozen=True)
class TubGeometry:
    """U-shaped tub (SI, m)."""

    radius: float = 0.15
    rim_height: float = 0.40
    length: float = 0.0635
    periodic: bool = False

    @property
    def half_width(self) -> float:
        return self.radius

    def as_array(self) -> np.ndarray:
        """Packed parameters for the numba kernels: [radius, rim_height, length, periodic]."""
        return np.array([self.radius, self.rim_height, self.length, float(self.periodic)])

    def cross_section_area(self, z_top: float | None = None) -> float:
        """Area (m^2) of the U cross-section below z_top (default: the rim)."""
        return cross_section_area(self.radius, self.rim_height if z_top is None else z_top)

    def wall_arc_length(self) -> float:
        """Length (m) of the U profile from rim to rim."""
        return np.pi * self.radius + 2.0 * (self.rim_height - self.radius)

    def profile(self, n: int = 200) -> np.ndarray:
        """Points (n, 2) of the U profile (x, z) from the left rim through the bottom to the right
        rim, for drawing and for meshing."""
        s = np.linspace(-0.5 * self.wall_arc_length(), 0.5 * self.wall_arc_length(), n)
        return np.stack(arc_to_point(s, self.radius), axis=-1)

    def inside(self, x, z, margin: float = 0.0):
        """True where the tub-frame point (x, z) lies inside the U (below the rim) by at least
        `margin` (m) from the wall."""
        d = np.asarray(distance_to_wall_np(x, z, self.radius))
        return (d >= margin) & (np.asarray(z) <= self.rim_height)


def cross_section_area(radius: float, z_top: float) -> float:
    """Area of the U below height z_top (m^2)."""
    R = radius
    h = min(max(z_top, 0.0), R)
    # circular segment of height h
    seg = R * R * np.arccos((R - h) / R) - (R - h) * np.sqrt(max(2 * R * h - h * h, 0.0))
    return seg + 2 * R * max(z_top - R, 0.0)


def arc_to_point(s, radius):
    """Point (x, z) of the U profile at arc length s from the bottom (positive towards +x)."""
    s = np.asarray(s, dtype=float)
    R = radius
    quarter = 0.5 * np.pi * R
    a = np.clip(s / R, -0.5 * np.pi, 0.5 * np.pi)
    x = np.where(np.abs(s) <= quarter, R * np.sin(a), np.sign(s) * R)
    z = np.where(np.abs(s) <= quarter, R - R * np.cos(a), R + np.abs(s) - quarter)
    return x, z


def point_to_arc(x, z, radius):
    """Arc length s (m) along the U profile, from the bottom and positive towards +x, of the
    profile's point nearest to the tub-frame point (x, z): R atan2(x, R - z) on the half circle
    (z <= R), +-(pi R / 2 + z - R) on the vertical walls; the inverse of arc_to_point for a point
    on the profile (u_wall_nearest's s, for arrays)."""
    x = np.asarray(x, dtype=float)
    z = np.asarray(z, dtype=float)
    R = radius
    side = np.where(x >= 0.0, 1.0, -1.0) * (0.5 * np.pi * R + (z - R))
    return np.where(z <= R, R * np.arctan2(x, R - z), side)


def distance_to_wall_np(x, z, radius):
    """Signed distance (m) from tub-frame points to the U's inner surface, positive inside."""
    x = np.asarray(x, dtype=float)
    z = np.asarray(z, dtype=float)
    R = radius
    circle = R - np.hypot(x, z - R)
    side = R - np.abs(x)
    return np.where(z <= R, circle, side)


@nb.njit(cache=True, inline="always")
def u_wall_nearest(px, pz, radius):
    """Nearest point of the U's inner surface (ignoring the rim) to tub-frame point (px, pz).

    Returns (gap, nx, nz, cx, cz, s): gap is the signed distance from the point to the surface
    (positive inside the tub), (nx, nz) the unit inward normal at the nearest point (pointing
    from the wall into the tub), (cx, cz) that point and s its arc-length coordinate measured
    from the bottom, positive towards +x.
    """
    R = radius
    quarter = 0.5 * np.pi * R
    if pz <= R:
        dx = px
        dz = pz - R
        rho = np.sqrt(dx * dx + dz * dz)
        if rho < 1e-300:
            # the circle's centre: every wall point is equally near; pick the bottom
            return R, 0.0, 1.0, 0.0, 0.0, 0.0
        ux = dx / rho
        uz = dz / rho
        cx = R * ux
        cz = R + R * uz
        s = R * np.arctan2(ux, -uz)
        return R - rho, -ux, -uz, cx, cz, s
    if px >= 0.0:
        return R - px, -1.0, 0.0, R, pz, quarter + (pz - R)
    return R + px, 1.0, 0.0, -R, pz, -(quarter + (pz - R))


def geometry_of(scenario) -> TubGeometry:
    """The scenario's tub as a TubGeometry (ValueError in explicit mode: no tub)."""
    tub = scenario.tub
    if tub is None:
        raise ValueError("scenario.tub = None: a tub is needed by a tub-mode scenario")
    return TubGeometry(radius=tub.radius, rim_height=tub.rim_height, length=tub.length,
                       periodic=tub.periodic)
