"""The continuum's material: its parameters, shared by every continuum formulation.

`ContinuumMaterial` holds the parameters of the elasto-visco-plastic law of the media (SI) and
packs them for the compiled kernels (`as_array`, the P_* layout below); the law itself, the
model of Dunatunga & Kamrin (2015, J. Fluid Mech. 779, 483-513) with mu(I) or Drucker-Prager
flow and the dilatancy, compaction and bed-viscosity options, is compiled in stress_update.py,
whose docstring states it; mu(I) and phi(I) in numpy form are rheology.py's.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from vibroflow.errors import InputError
from vibroflow.io.calibration_file import Calibration, read_calibration

#: rheology models (params[0])
MU_I = 0
DRUCKER_PRAGER = 1
MODELS = {"mu_i": MU_I, "drucker_prager": DRUCKER_PRAGER}

# packed parameter layout of `ContinuumMaterial.as_array()`
(P_MODEL, P_K, P_G, P_MU_S, P_MU_2, P_I0, P_D, P_RHO_S, P_RHO_C, P_MU_DP, P_ETA, P_KDIL,
 P_PHI_SLOPE, P_GAMMA_C, P_DPHI_CYC, P_ETA_BED, P_KLAW_REF, P_KLAW_P_REF, P_KLAW_N, P_KLAW_P_MIN,
 P_KLAW_P_MAX) = range(21)
N_PARAMS = 21

# tub47 defaults (documented in ContinuumMaterial)
_MU_S = math.tan(math.radians(20.9))
_MU_2 = math.tan(math.radians(32.8))


def check_bed_viscosity(value) -> None:
    """The bed viscosity (Pa s; ContinuumMaterial.bed_viscosity, ContinuumOptions'): a finite
    number >= 0, else a one-line InputError naming it."""
    if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value)
                                       and value >= 0):
        raise InputError(f"bed_viscosity = {value!r}: must be a finite number >= 0 Pa s "
                         "(0 = off)")


def bulk_law_tangent(p: float, bulk_law) -> float:
    """K_t = K_ref (p / p_ref)^n (Pa) at pressure p (Pa) clamped to [p_min, p_max]; bulk_law =
    (K_ref, p_ref, n, p_min, p_max) (ContinuumMaterial.bulk_law; stress_update.bulk_tangent
    compiled)."""
    k_ref, p_ref, n, lo, hi = (float(x) for x in bulk_law)
    return k_ref * (min(max(p, lo), hi) / p_ref) ** n


def check_bulk_law(bulk_law) -> None:
    """(K_ref, p_ref, n, p_min, p_max): K_ref, p_ref > 0 Pa, n finite, 0 < p_min < p_max Pa;
    else a one-line InputError naming it."""
    try:
        k_ref, p_ref, n, lo, hi = (float(x) for x in bulk_law)
    except (TypeError, ValueError):
        raise InputError(f"bulk_law = {bulk_law!r}: must be (K_ref, p_ref, n, p_min, p_max)") \
            from None
    if not (all(math.isfinite(x) for x in (k_ref, p_ref, n, lo, hi)) and k_ref > 0
            and p_ref > 0 and 0 < lo < hi):
        raise InputError(f"bulk_law = {bulk_law!r}: must be (K_ref, p_ref, n, p_min, p_max) "
                         "with K_ref, p_ref > 0 Pa, n finite and 0 < p_min < p_max Pa")


def drucker_prager_mu(mu_s: float) -> float:
    """Plane-strain matched Drucker-Prager slope mu_dp = tan(beta)/sqrt(3) (-) of a material of
    friction angle atan(mu_s) (models.md: tan beta = 3 sqrt(3) tan phi / sqrt(9 + 12 tan^2 phi))."""
    t = mu_s
    tan_beta = 3.0 * math.sqrt(3.0) * t / math.sqrt(9.0 + 12.0 * t * t)
    return tan_beta / math.sqrt(3.0)


@dataclass(frozen=True)
class ContinuumMaterial:
    """Parameters of the continuum (SI).

    Defaults are tub47's (shared/reference/tub47.md, models.md) when no calibration is given:

    * mu_s = tan 20.9 deg = 0.382, mu_2 = tan 32.8 deg = 0.644, I_0 = 0.279: the glass-bead mu(I)
      of Jop, Forterre & Pouliquen (2006) quoted in models.md;
    * phi_max = 0.60, phi_min = 0.30 (phi(I) = phi_max - (phi_max - phi_min) I, the slope 0.3 of
      da Cruz et al. 2005); critical solid fraction phi_c = phi_max;
    * bulk_modulus = 4.5e6 Pa: the affine estimate K = phi Z k_n / (3 pi d)
      (vibroflow.calibration.elastic.affine_moduli_linear) at phi = 0.60, Z = 4.5 contacts per ball,
      k_n = 1e5 N/m, d = 6.35 mm; shear_modulus = 1.3e6 Pa: the affine G (3.9e6 Pa) divided by 3
      for non-affine relaxation (affine G is an upper bound, several times the measured one);
    * diameter 6.35 mm, solid density 7800 kg/m^3 (steel balls);
    * viscosity (Drucker-Prager option only) = (mu_2 - mu_s) d sqrt(rho_s p_ref) / I_0 at
      p_ref = 5 kPa (mid-depth of tub47's bed): the slope d tau / d gamma_dot of mu(I) at I -> 0;
    * dilatancy = K_dil (-) of the peak-friction option (stress_update.py), 0 = off (default);
      measured on DEM by vibroflow.calibration.dilatancy (calibration.toml [dilatancy]);
    * compaction_strain = gamma_c (-) and compaction_excess = dphi_cyc (-) of the cyclic
      compaction option (stress_update.py), gamma_c = 0 = off (default); measured on DEM by
      vibroflow.calibration.compaction (calibration.toml [compaction]);
    * initial_solid_fraction: the unloaded packing phi_0 of the settled bed the continuum runs
      start from (None: the critical one, phi_c); a bed denser than phi_c matters only with
      the dilatancy option (its peak friction K_dil (phi_0 - phi_c)).
    * bed_viscosity = eta_b (Pa s): the bed's Kelvin-Voigt damping
      (stress_update.damped_stress), 0 = off (default); measured on DEM by
      benchmarks/strip_damping.py.
    * bulk_law = (K_ref, p_ref, n, p_min, p_max) (Pa, Pa, -, Pa, Pa): the bulk part's tangent
      K_t = K_ref (p / p_ref)^n with p clamped to [p_min, p_max] (stress_update.py, "Option:
      the unloading law"; models.md 4.3), None = off (default: K = bulk_modulus); measured on
      DEM by vibroflow.calibration.unloading (calibration.toml [elastic] unloading_law_*).
      bulk_modulus is then the law's largest tangent, K_t(p_max), which sets the time step.
    """

    model: str = "mu_i"
    bulk_modulus: float = 4.5e6
    shear_modulus: float = 1.3e6
    mu_s: float = _MU_S
    mu_2: float = _MU_2
    I_0: float = 0.279
    phi_max: float = 0.60
    phi_min: float = 0.30
    critical_solid_fraction: float = 0.60
    diameter: float = 0.00635
    solid_density: float = 7800.0
    viscosity: float | None = None
    dilatancy: float = 0.0
    compaction_strain: float = 0.0
    compaction_excess: float = 0.0
    initial_solid_fraction: float | None = None
    bed_viscosity: float = 0.0
    bulk_law: tuple | None = None

    def __post_init__(self):
        if self.model not in MODELS:
            raise InputError(f"model = {self.model!r}: must be one of {', '.join(MODELS)}")
        for name in ("bulk_modulus", "shear_modulus", "I_0", "diameter", "solid_density"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"{name} = {v!r}: must be a finite number > 0")
        if not 0 <= self.mu_s:
            raise InputError(f"mu_s = {self.mu_s!r}: must be a friction coefficient >= 0")
        if not self.mu_s <= self.mu_2:
            raise InputError(f"mu_2 = {self.mu_2!r}: must be at least mu_s = {self.mu_s!r}")
        if not 0 < self.critical_solid_fraction < 1:
            raise InputError(f"critical_solid_fraction = {self.critical_solid_fraction!r}: "
                             "must be in (0, 1)")
        if self.viscosity is not None and not self.viscosity >= 0:
            raise InputError(f"viscosity = {self.viscosity!r}: must be >= 0 Pa s")
        if not (isinstance(self.dilatancy, (int, float)) and math.isfinite(self.dilatancy)
                and self.dilatancy >= 0):
            raise InputError(f"dilatancy = {self.dilatancy!r}: must be a finite number >= 0 "
                             "(K_dil; 0 = off)")
        if self.dilatancy > 0 and self.model != "mu_i":
            raise InputError(f"dilatancy = {self.dilatancy!r} with model = {self.model!r}: the "
                             "dilatancy option is part of the mu_i model only (0 = off)")
        for name in ("compaction_strain", "compaction_excess"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise InputError(f"{name} = {v!r}: must be a finite number >= 0 (0 = off)")
        if not self.critical_solid_fraction + self.compaction_excess < 1.0:
            raise InputError(f"compaction_excess = {self.compaction_excess!r}: phi_c + it must "
                             "stay below 1")
        if self.initial_solid_fraction is not None and not (
                self.critical_solid_fraction <= self.initial_solid_fraction < 1.0):
            raise InputError(f"initial_solid_fraction = {self.initial_solid_fraction!r}: must "
                             f"be in [critical_solid_fraction = {self.critical_solid_fraction!r}"
                             ", 1)")
        for name in ("phi_max", "phi_min"):
            v = getattr(self, name)
            if not 0 < v < 1:
                raise InputError(f"{name} = {v!r}: must be a solid fraction in (0, 1)")
        if not self.phi_max > self.phi_min:
            raise InputError(f"phi_min = {self.phi_min!r}: must be below phi_max = "
                             f"{self.phi_max!r}")
        check_bed_viscosity(self.bed_viscosity)
        if self.bulk_law is not None:
            check_bulk_law(self.bulk_law)

    @property
    def critical_density(self) -> float:
        """rho_c = rho_s phi_c (kg/m^3): below it the media is disconnected (stress-free)."""
        return self.solid_density * self.critical_solid_fraction

    @property
    def initial_density(self) -> float:
        """rho_0 = rho_s phi_0 (kg/m^3) of the unloaded settled bed (rho_c by default)."""
        phi0 = self.initial_solid_fraction
        return self.critical_density if phi0 is None else self.solid_density * phi0

    @property
    def mu_dp(self) -> float:
        """Drucker-Prager slope tau/p (-), plane-strain matched to mu_s."""
        return drucker_prager_mu(self.mu_s)

    @property
    def eta(self) -> float:
        """Drucker-Prager viscosity (Pa s): `viscosity`, or the default of the class docstring."""
        if self.viscosity is not None:
            return float(self.viscosity)
        p_ref = 5.0e3
        return (self.mu_2 - self.mu_s) * self.diameter * math.sqrt(self.solid_density * p_ref) \
            / self.I_0

    def p_wave_speed(self, density: float | None = None) -> float:
        """Elastic P-wave speed sqrt((K + 4G/3) / rho) (m/s), at rho_c by default."""
        rho = self.critical_density if density is None else density
        return math.sqrt((self.bulk_modulus + 4.0 * self.shear_modulus / 3.0) / rho)

    def as_array(self) -> np.ndarray:
        """Packed parameters for the kernels (layout P_MODEL .. P_ETA of this module)."""
        a = np.zeros(N_PARAMS)
        a[P_MODEL] = MODELS[self.model]
        a[P_K] = self.bulk_modulus
        a[P_G] = self.shear_modulus
        a[P_MU_S] = self.mu_s
        a[P_MU_2] = self.mu_2
        a[P_I0] = self.I_0
        a[P_D] = self.diameter
        a[P_RHO_S] = self.solid_density
        a[P_RHO_C] = self.critical_density
        a[P_MU_DP] = self.mu_dp
        a[P_ETA] = self.eta
        a[P_KDIL] = self.dilatancy
        a[P_PHI_SLOPE] = self.phi_max - self.phi_min
        a[P_GAMMA_C] = self.compaction_strain
        a[P_DPHI_CYC] = self.compaction_excess
        a[P_ETA_BED] = self.bed_viscosity
        if self.bulk_law is not None:
            (a[P_KLAW_REF], a[P_KLAW_P_REF], a[P_KLAW_N], a[P_KLAW_P_MIN],
             a[P_KLAW_P_MAX]) = self.bulk_law
        return a

    def to_dict(self) -> dict:
        d = asdict(self)
        d["critical_density"] = self.critical_density
        d["mu_dp"] = self.mu_dp
        d["eta"] = self.eta
        if self.bulk_law is None:
            del d["bulk_law"]
        else:
            d["bulk_law"] = dict(zip(("K_ref_Pa", "p_ref_Pa", "n", "p_min_Pa", "p_max_Pa"),
                                     (float(x) for x in self.bulk_law)))
        return d

    @classmethod
    def from_calibration(cls, cal: Calibration, model: str = "mu_i") -> "ContinuumMaterial":
        """From a calibration record (`read_calibration`): [rheology] mu_s, mu_2, I_0, phi_max,
        phi_min, critical_solid_fraction (phi_max when absent); [elastic] bulk_modulus_Pa,
        shear_modulus_Pa; [media] diameter_m, solid_density_kg_m3; [drucker_prager]
        viscosity_Pa_s (the Drucker-Prager option's viscosity, when finite).  The dilatancy
        option stays off (K_dil = 0) here: the caller switches it on with
        `dataclasses.replace(mat, dilatancy=...)` (run options, calibration.toml [dilatancy]
        K_dil)."""
        r, e, m = cal.rheology, cal.elastic, cal.media
        eta = cal.drucker_prager.viscosity_Pa_s if cal.drucker_prager is not None else None
        if not (eta is not None and math.isfinite(eta) and eta >= 0):
            eta = None
        phi_c = r.critical_solid_fraction
        return cls(model=model,
                   bulk_modulus=float(e.bulk_modulus_Pa), shear_modulus=float(e.shear_modulus_Pa),
                   mu_s=float(r.mu_s), mu_2=float(r.mu_2), I_0=float(r.I_0),
                   phi_max=float(r.phi_max), phi_min=float(r.phi_min),
                   critical_solid_fraction=float(r.phi_max if phi_c is None else phi_c),
                   diameter=float(m.diameter_m), solid_density=float(m.solid_density_kg_m3),
                   viscosity=None if eta is None else float(eta))

    @classmethod
    def from_file(cls, path, model: str = "mu_i") -> "ContinuumMaterial":
        """From calibration.toml (a file, or a run folder holding one)."""
        return cls.from_calibration(read_calibration(path), model=model)
