"""Granular column collapse: the deposit measured from points, and the published scaling laws.

A column of width L0 and height H0 (aspect ratio a = H0 / L0) standing against a wall at
x = x_wall (or the half of a column of width 2 L0 about its symmetry plane, the positions then
folded onto one side) is released and spreads along +x; at rest it leaves a deposit of run-out
L_inf (the front's distance from the wall) and height H_inf (at the wall).  This
module measures both from any set of points, so that every method (the Lagrangian and Eulerian
continua, the DEM) is judged by the same ruler:

* each point carries the area it stands for in the x-z plane, in m^2 per metre of thickness (a
  material point: its volume; a ball in a slab of thickness W: its volume / (W phi_0), phi_0
  the column's initial solid fraction, so that the balls' areas add up to L0 H0 at the start);
* the thickness profile h(x) (m) is the points' area per unit length of floor, binned along x
  (`thickness_profile`); it conserves the column's area, sum h dx = L0 H0, and needs no surface
  detection;
* the run-out L_inf is where the profile last falls through a threshold thickness (default one
  grain diameter), linearly interpolated between bin centres (`front_by_thickness`): a few
  grains flung ahead of the front are thinner than one grain and are ignored, which the farthest
  point would not do; `front_by_mass_fraction` gives the position behind which a stated fraction
  of the mass lies, for a second, threshold-free reading;
* the height H_inf is the profile's mean over a window next to the wall (default two grain
  diameters, at least one bin);
* `measure_continuum_deposit` picks these settings for material points or grid cells of a
  given side (bins of whole point sides, a front no thinner than a point), `slab_areas` the
  areas of the balls of a quasi-2D slab.

The published scaling laws, all of the form (L_inf - L0)/L0 = lambda a (a <= a_lin) or
lambda' a^alpha (a >= a_pow), and H_inf/L0 = a (a <= a_h) or kappa a^beta (a >= a_h), with
L0 the column's width behind the gate (half-width, or radius, for the symmetric set-ups):

planar (a channel, the flow along one direction, i.e. a 2D collapse):
  * `LUBE_2005`: Lube, Huppert, Sparks & Freundt 2005, "Collapses of two-dimensional granular
    columns", Phys. Rev. E 72, 041301 (sand, rice, sugar, couscous in a channel; their
    eq. 4 onward): lambda = 1.2 for a < 1.8, lambda' = 1.9, alpha = 2/3 for a > 2.8;
    H_inf/L0 = a for a < 1.15 and a^(2/5) above, "whatever the grain type and the floor's
    roughness";
  * `LAJEUNESSE_2005`: Lajeunesse, Monnier & Homsy 2005, "Granular slumping on a horizontal
    surface", Phys. Fluids 17, 103302 (glass beads in a channel): lambda = 1.8 for a < 3,
    lambda' = 2.3, alpha = 2/3 above, as consolidated in Lagree, Staron & Popinet 2011
    (J. Fluid Mech. 686, 378, their eq. 3.1) with a_0 = 3 for both branches;
axisymmetric (a cylinder spreading on a plane), the experiments the issues name:
  * `LUBE_2004`: Lube, Huppert, Sparks & Hallworth 2004, "Axisymmetric collapses of granular
    columns", J. Fluid Mech. 508, 175: (r_inf - r_i)/r_i = 1.24 a for a < 1.7 and
    1.6 a^(1/2) above;
  * `LAJEUNESSE_2004`: Lajeunesse, Mangeney-Castelnau & Vilotte 2004, "Spreading of a granular
    mass on a horizontal plane", Phys. Fluids 16, 2371 (an axisymmetric, not a channel,
    experiment): H_inf / R_i = a for a < 0.74, saturating at 0.74 above.

Which law to compare with: a plane-strain continuum and a quasi-2D slab of balls collapse in a
plane, so the planar laws; the axisymmetric ones spread less (the area grows as r^2) and are
the reference of the continua's axisymmetric sections (MPMSystem.axisymmetric,
EulerianSystem.axisymmetric; tests/test_axisymmetric.py), a cylinder being what Lube et al.
2004 and Lajeunesse et al. 2004 collapsed.  Of the planar two, Lube
et al. (2005) is the one stated "whatever the grain type and the floor's roughness" over a range
of materials, so it is the reference of the tests; Lajeunesse et al. (2005), for glass beads
(closest to smooth steel balls and to the glass-bead mu(I) of the default continuum), is
printed beside it.  The laws' prefactors do depend on the grains (a factor 1.5 between the two
at the same a), which bounds how closely any one material can be expected to follow any one fit.

Where the numbers come from: the Lube 2005 power law 1.9 a^(2/3) for a > 2.8 and the Lajeunesse
2004 saturation 0.74 were read in public secondary sources quoting the papers (a code's test
citing Lube et al.'s eq. 4; the deposit radius sqrt(3a/0.74) of a cone of height 0.74 R_i); the
linear prefactors, the transition ratios and the planar height laws from the consolidation in
Lagree, Staron & Popinet (2011, section 3.1) as quoted by a public validation report; the
small-a height H_inf = H0 (the top of a low column never moves) is common to every experiment.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vibroflow.errors import InputError


# ----------------------------------------------------------------------------------------------
# the published laws

@dataclass(frozen=True)
class ScalingLaw:
    """A published fit of the final deposit against the aspect ratio a = H0 / L0 (module
    docstring).  runout(a) = (L_inf - L0)/L0 and height(a) = H_inf/L0, dimensionless; each
    raises InputError outside the ranges the authors fitted (the gap between the linear and the
    power-law branches, where neither was fitted, included)."""

    name: str
    reference: str
    geometry: str            # "planar" or "axisymmetric"
    lam: float               # linear run-out prefactor
    a_lin: float             # linear branch for a <= a_lin
    lam_pow: float           # power-law run-out prefactor
    alpha: float             # power-law exponent
    a_pow: float             # power-law branch for a >= a_pow
    a_h: float | None = None   # H_inf/L0 = a for a <= a_h
    kappa: float | None = None  # H_inf/L0 = kappa a^beta for a >= a_h
    beta: float | None = None

    def runout(self, a: float) -> float:
        """(L_inf - L0) / L0 at aspect ratio a."""
        a = _aspect(a)
        if a <= self.a_lin:
            return self.lam * a
        if a >= self.a_pow:
            return self.lam_pow * a ** self.alpha
        raise InputError(f"aspect ratio a = {a!r}: {self.name} fits a <= {self.a_lin} and "
                         f"a >= {self.a_pow}, not the transition between")

    def height(self, a: float) -> float:
        """H_inf / L0 at aspect ratio a."""
        a = _aspect(a)
        if self.a_h is None:
            raise InputError(f"{self.name}: gives no final-height law")
        if a <= self.a_h:
            return a
        return self.kappa * a ** self.beta

    def runout_length(self, L0: float, H0: float) -> float:
        """L_inf (m) of a column of width L0 and height H0 (m), from the wall."""
        return L0 * (1.0 + self.runout(H0 / L0))


def _aspect(a) -> float:
    if not (isinstance(a, (int, float)) and math.isfinite(a) and a > 0):
        raise InputError(f"aspect ratio a = {a!r}: must be a finite number > 0")
    return float(a)


LUBE_2005 = ScalingLaw(
    "Lube et al. 2005", "Lube, Huppert, Sparks & Freundt 2005, Phys. Rev. E 72, 041301",
    "planar", lam=1.2, a_lin=1.8, lam_pow=1.9, alpha=2.0 / 3.0, a_pow=2.8,
    a_h=1.15, kappa=1.0, beta=0.4)
LAJEUNESSE_2005 = ScalingLaw(
    "Lajeunesse et al. 2005", "Lajeunesse, Monnier & Homsy 2005, Phys. Fluids 17, 103302",
    "planar", lam=1.8, a_lin=3.0, lam_pow=2.3, alpha=2.0 / 3.0, a_pow=3.0)
LUBE_2004 = ScalingLaw(
    "Lube et al. 2004", "Lube, Huppert, Sparks & Hallworth 2004, J. Fluid Mech. 508, 175",
    "axisymmetric", lam=1.24, a_lin=1.7, lam_pow=1.6, alpha=0.5, a_pow=1.7)
LAJEUNESSE_2004 = ScalingLaw(
    "Lajeunesse et al. 2004",
    "Lajeunesse, Mangeney-Castelnau & Vilotte 2004, Phys. Fluids 16, 2371",
    "axisymmetric", lam=math.nan, a_lin=0.0, lam_pow=math.nan, alpha=math.nan,
    a_pow=math.inf, a_h=0.74, kappa=0.74, beta=0.0)


def quasistatic_runout(a: float, deposit_slope: float) -> float:
    """(L_inf - L0)/L0 of a low column (top untouched) whose collapse leaves a plane slope of
    gradient `deposit_slope` (tan of the deposit angle): the trapezoid of height H0 holding the
    column's area L0 H0 reaches L0 + H0 / (2 tan theta), so the run-out is a / (2 tan theta).
    The linear laws' lambda is 1/(2 tan theta) of the experiments' deposits: 1.2 is a 22.6 deg
    slope, 1.8 a 15.5 deg one; a column that slid no faster than quasi-statically would stop at
    its friction angle, tan theta = mu_s."""
    a = _aspect(a)
    if not deposit_slope > 0:
        raise InputError(f"deposit_slope = {deposit_slope!r}: must be > 0")
    return a / (2.0 * deposit_slope)


def quasistatic_runout_axisymmetric(a: float, deposit_slope: float) -> tuple[float, float]:
    """((r_inf - R0)/R0, H_inf/R0) of a cylinder of radius R0 and height H0 = a R0 whose
    collapse leaves a plane slope of gradient s = `deposit_slope` (tan of the deposit angle):
    the solid of revolution of that slope holding the cylinder's volume pi R0^2 H0.

    While c = a / s <= sqrt(3) it is a truncated cone of height H0 (the top untouched), top
    radius r_t and base r_t + c (in units of R0), whose volume (pi H0 / 3)(r_t^2 + r_t r_b +
    r_b^2) = pi R0^2 H0 gives 3 r_t^2 + 3 c r_t + c^2 = 3, so r_t = (sqrt(36 - 3 c^2) - 3c)/6.
    Taller columns leave a full cone, (pi/3) r_b^2 (s r_b) = pi a: r_b = (3a/s)^(1/3), its
    height s r_b < H0.  Lube et al. 2004's linear branch 1.24 a is this with a shallower slope
    than the grains' friction: a deposit at the friction angle is what a column that slid no
    faster than quasi-statically would leave (tan theta = mu_s)."""
    a = _aspect(a)
    if not deposit_slope > 0:
        raise InputError(f"deposit_slope = {deposit_slope!r}: must be > 0")
    c = a / deposit_slope
    if c * c <= 3.0:
        r_top = (math.sqrt(36.0 - 3.0 * c * c) - 3.0 * c) / 6.0
        return r_top + c - 1.0, a
    r_base = (3.0 * c) ** (1.0 / 3.0)
    return r_base - 1.0, deposit_slope * r_base


# ----------------------------------------------------------------------------------------------
# the measurement

@dataclass(frozen=True)
class Deposit:
    """A measured deposit: run-out L_inf (m, front distance from the wall, by the thickness
    threshold), height H_inf (m, at the wall), the front by mass fraction (m), the profile
    (bin centres x (m, from the wall) and thickness h (m)) and the settings used."""

    runout: float
    height: float
    runout_mass: float
    mass_fraction: float
    threshold: float
    x: np.ndarray
    h: np.ndarray

    def normalised(self, L0: float) -> tuple[float, float]:
        """((L_inf - L0)/L0, H_inf/L0), the laws' variables."""
        return (self.runout - L0) / L0, self.height / L0


def thickness_profile(x, area, bin_width: float, x_wall: float = 0.0,
                      reach: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Thickness h (m) of the deposit on bins of `bin_width` (m) from the wall: the points'
    area (m^2 per metre of thickness) in each bin over the bin's width.  x (N,) point positions
    (m); bins from x_wall to `reach` (m from the wall; default past the farthest point).
    Returns (bin centres from the wall (m), h (m))."""
    x = np.asarray(x, dtype=float).ravel()
    area = np.broadcast_to(np.asarray(area, dtype=float), x.shape)
    if not bin_width > 0:
        raise InputError(f"bin_width = {bin_width!r}: must be > 0 m")
    if x.size == 0:
        raise InputError("points: none given")
    if np.any(~np.isfinite(x)) or np.any(~np.isfinite(area)) or np.any(area < 0):
        raise InputError("points: positions must be finite and areas finite and >= 0")
    s = x - x_wall
    far = float(s.max()) if reach is None else float(reach)
    nbin = max(int(math.floor(far / bin_width)) + 2, 1)
    idx = np.floor(s / bin_width).astype(np.int64)
    keep = (idx >= 0) & (idx < nbin)
    h = np.bincount(idx[keep], weights=area[keep], minlength=nbin) / bin_width
    centres = (np.arange(nbin) + 0.5) * bin_width
    return centres, h


def front_by_thickness(centres, h, threshold: float) -> float:
    """Distance from the wall (m) where the thickness profile last falls through `threshold`
    (m), linearly interpolated between the last bin at or above it and the next one; 0 if no bin
    reaches it."""
    centres = np.asarray(centres, dtype=float)
    h = np.asarray(h, dtype=float)
    above = np.nonzero(h >= threshold)[0]
    if above.size == 0:
        return 0.0
    k = int(above[-1])
    if k + 1 >= h.size:
        return float(centres[k] + 0.5 * (centres[1] - centres[0] if h.size > 1 else 0.0))
    h0, h1 = h[k], h[k + 1]
    f = (h0 - threshold) / (h0 - h1) if h0 > h1 else 0.0
    return float(centres[k] + f * (centres[k + 1] - centres[k]))


def front_by_mass_fraction(x, mass, fraction: float, x_wall: float = 0.0) -> float:
    """Distance from the wall (m) behind which `fraction` of the mass lies."""
    if not 0 < fraction <= 1:
        raise InputError(f"mass fraction = {fraction!r}: must be in (0, 1]")
    x = np.asarray(x, dtype=float).ravel() - x_wall
    mass = np.broadcast_to(np.asarray(mass, dtype=float), x.shape)
    order = np.argsort(x, kind="stable")
    cum = np.cumsum(mass[order])
    k = int(np.searchsorted(cum, fraction * cum[-1]))
    return float(x[order][min(k, x.size - 1)])


def measure_deposit(x, area, grain_diameter: float, bin_width: float | None = None,
                    x_wall: float = 0.0, threshold: float | None = None,
                    wall_window: float | None = None, mass=None,
                    mass_fraction: float = 0.99) -> Deposit:
    """Run-out and height of a deposit (module docstring) from points at x (N,) m, each
    standing for `area` (N,) m^2 per metre of thickness (mass (N,) for the mass-fraction front,
    default proportional to the area).

    grain_diameter (m) sets the defaults: bins of one grain diameter (`bin_width`), the front
    where the deposit gets thinner than one grain (`threshold`), the height averaged over the
    bins within two grain diameters of the wall, at least one bin (`wall_window`): grains held
    by the wall's friction make a thin ridge against it that a single narrow bin would read as
    the deposit's height.  Points on a lattice (material points) need bins of a
    whole number of lattice spacings, at least one, or the profile aliases; and a continuum
    cannot be thinner than one point, so its threshold should be at least the point's side.
    The front is never put past the farthest point."""
    if not (isinstance(grain_diameter, (int, float)) and grain_diameter > 0):
        raise InputError(f"grain_diameter = {grain_diameter!r}: must be > 0 m")
    bw = grain_diameter if bin_width is None else float(bin_width)
    thr = grain_diameter if threshold is None else float(threshold)
    win = max(bw, 2.0 * grain_diameter) if wall_window is None else float(wall_window)
    if not thr > 0:
        raise InputError(f"threshold = {thr!r}: must be > 0 m")
    if not win > 0:
        raise InputError(f"wall_window = {win!r}: must be > 0 m")
    centres, h = thickness_profile(x, area, bw, x_wall)
    near = centres - 0.5 * bw < win   # the bins that start within the window
    height = float(h[near].mean())
    # the interpolation between bin centres must not put the front past the farthest point
    farthest = float(np.max(np.asarray(x, dtype=float))) - x_wall
    runout = min(front_by_thickness(centres, h, thr), farthest)
    m = np.asarray(area, dtype=float) if mass is None else np.asarray(mass, dtype=float)
    runout_mass = front_by_mass_fraction(x, m, mass_fraction, x_wall)
    return Deposit(runout=runout, height=height, runout_mass=runout_mass,
                   mass_fraction=mass_fraction, threshold=thr, x=centres, h=h)


def measure_continuum_deposit(x, area, point_side: float, grain_diameter: float,
                              x_wall: float = 0.0, mass=None,
                              wall_window: float | None = None) -> Deposit:
    """`measure_deposit` with the settings a continuum needs: x (N,) m the positions of
    material points (or cell centres) each standing for `area` (N,) m^2 per metre of thickness
    (its mass over the column's initial density, so the areas add up to L0 H0), on a lattice
    (or grid) of side `point_side` (m).  Bins are a whole number of point sides, at least two
    and at least one grain diameter (no aliasing); the front is where the deposit gets thinner
    than one grain or one point side, whichever is thicker (a continuum holds no thinner
    layer); the height is read within two grain diameters of the wall, at least one bin, or
    within `wall_window` (m) when given (a cylinder's axis: the few points next to it make the
    thickness of one bin there swing by 5 - 15 %, tests/test_axisymmetric.py)."""
    if not (isinstance(point_side, (int, float)) and point_side > 0):
        raise InputError(f"point_side = {point_side!r}: must be > 0 m")
    if not (isinstance(grain_diameter, (int, float)) and grain_diameter > 0):
        raise InputError(f"grain_diameter = {grain_diameter!r}: must be > 0 m")
    bins = max(2, math.ceil(grain_diameter / point_side - 1e-9))
    return measure_deposit(x, area, grain_diameter, bin_width=bins * point_side, x_wall=x_wall,
                           threshold=max(grain_diameter, point_side), mass=mass,
                           wall_window=wall_window)


def slab_areas(radius, slab_thickness: float, solid_fraction: float) -> np.ndarray:
    """Area (m^2 per metre of thickness) each ball of a quasi-2D slab stands for: its volume
    over the slab thickness W (m) and the column's solid fraction phi_0, so that a deposit of
    balls and a continuum of the same column are measured alike (module docstring)."""
    r = np.asarray(radius, dtype=float)
    if not slab_thickness > 0:
        raise InputError(f"slab_thickness = {slab_thickness!r}: must be > 0 m")
    if not 0 < solid_fraction < 1:
        raise InputError(f"solid_fraction = {solid_fraction!r}: must be in (0, 1)")
    return 4.0 / 3.0 * math.pi * r**3 / (slab_thickness * solid_fraction)
