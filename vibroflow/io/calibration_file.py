"""calibration.toml: the continuum's parameters measured on a DEM run, as a typed record
(`Calibration`), written and read here only (`vibroflow calibrate` writes it; the continuum, the
study and the report read it).

Each TOML table is a frozen pydantic model: the parameters the continuum needs are required
finite numbers (the [rheology] mu(I)/phi(I) constants, the [elastic] moduli, the [wall]
friction, the [media] diameter and density), so a file that lacks one is a one-line error when
it is read, not a solver that runs on a default; every other table and key is optional. Every
value carries its standard error (`*_stderr`, NaN where none could be estimated); keys a table
does not declare are kept as they are (extra="allow"), and the record keeps the file's key order,
so `Calibration.to_toml_dict` gives back exactly the tables the file holds and a record written
and read again is the same file, byte for byte (the types and `Table`:
calibration_table.py).  Units are SI, named in the keys (`_Pa`, `_m`,
`_m_s`, `_1_s`, `_kg_m3`).
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import tomli_w
from pydantic import ValidationError

from vibroflow.errors import InputError
from vibroflow.io.atomic import write_text_atomic
from vibroflow.io.calibration_table import Count, Finite, Number, Table, Text

CALIBRATION_FILE = "calibration.toml"


class CoarseGraining(Table):
    kernel: Text | None = None
    width_m: Number | None = None
    cell_size_m: Number | None = None
    contact_stress: Text | None = None


class Source(Table):
    """[source]: the DEM run the calibration was measured on."""
    run: Text | None = None
    case: Text | None = None
    dem_code: Text | None = None
    snapshots: Count | None = None
    window_s: list[Number] | None = None
    shear_cell: bool | None = None
    created: Text | None = None
    vibroflow_version: Text | None = None
    coarse_graining: CoarseGraining | None = None


class Media(Table):
    """[media]: the balls and the bed they form."""
    diameter_m: Finite
    solid_density_kg_m3: Finite
    bed_solid_fraction: Number | None = None
    bed_pressure_Pa: Number | None = None
    coordination_number: Number | None = None
    coordination_number_all_balls: Number | None = None


class Rheology(Table):
    """[rheology]: mu(I) = mu_s + (mu_2 - mu_s) / (1 + I_0 / I), phi(I) = phi_max - (phi_max -
    phi_min) I, and the critical solid fraction below which the material is stress-free."""
    model: Text | None = None
    source: Text | None = None
    points: Count | None = None
    status: Text | None = None
    mu_s: Finite
    mu_s_stderr: Number | None = None
    mu_2: Finite
    mu_2_stderr: Number | None = None
    I_0: Finite
    I_0_stderr: Number | None = None
    phi_max: Finite
    phi_max_stderr: Number | None = None
    phi_min: Finite
    phi_min_stderr: Number | None = None
    mu_fit_chi2_per_dof: Number | None = None
    critical_solid_fraction: Finite | None = None


class Elastic(Table):
    """[elastic]: the packed bed's moduli (Pa) the continuum gets."""
    bulk_modulus_Pa: Finite
    bulk_modulus_stderr_Pa: Number | None = None
    shear_modulus_Pa: Finite
    shear_modulus_stderr_Pa: Number | None = None
    shear_modulus_small_strain_Pa: Number | None = None
    shear_modulus_small_strain_stderr_Pa: Number | None = None
    youngs_modulus_Pa: Number | None = None
    poisson_ratio: Number | None = None
    pressure_Pa: Number | None = None
    solid_fraction: Number | None = None
    coordination_number: Number | None = None
    source: Text | None = None
    #: the bed's bulk modulus on the unloading branch after each landing, measured in the DEM
    #: tub run (vibroflow.calibration.unloading); the continuum's --moduli unloading
    unloading_bulk_modulus_Pa: Number | None = None
    unloading_bulk_modulus_stderr_Pa: Number | None = None
    #: the tangent law of the same branch, K_t = K_ref (p / p_ref)^n on [p_min, p_max]
    #: (vibroflow.calibration.unloading.unloading_law); the continuum's --moduli unloading-law
    unloading_law_modulus_Pa: Number | None = None
    unloading_law_modulus_stderr_Pa: Number | None = None
    unloading_law_reference_pressure_Pa: Number | None = None
    unloading_law_exponent: Number | None = None
    unloading_law_exponent_stderr: Number | None = None
    unloading_law_min_pressure_Pa: Number | None = None
    unloading_law_max_pressure_Pa: Number | None = None


class DruckerPrager(Table):
    """[drucker_prager]: the equivalent Drucker-Prager cone with viscosity."""
    model: Text | None = None
    friction_angle_deg: Number | None = None
    tan_beta: Number | None = None
    beta_deg: Number | None = None
    dilation_angle_deg: Number | None = None
    viscosity_Pa_s: Number | None = None
    inertial_number: Number | None = None


class Wall(Table):
    """[wall]: the media's effective Coulomb friction on the tub's lining."""
    friction: Finite
    friction_stderr: Number | None = None
    choice: Text | None = None
    contact_friction: Number | None = None
    mean_ft_over_fn: Number | None = None
    mean_ft_over_fn_stderr: Number | None = None
    ratio_of_sums: Number | None = None
    sliding_fraction: Number | None = None
    sliding_fraction_stderr: Number | None = None
    coherent_slip_friction: Number | None = None
    coherent_slip_friction_stderr: Number | None = None
    contacts: Count | None = None


class Partitions(Table):
    """[partitions]: the effective friction on the partitions, the body force it gives."""
    friction: Finite
    friction_stderr: Number | None = None
    contact_friction: Number | None = None
    mean_ft_over_fn: Number | None = None
    sliding_fraction: Number | None = None
    contacts: Count | None = None
    body_force: Text | None = None
    spacing_m: Number | None = None
    #: the friction along the mean flow, sum(-F_t . u / |u|) / sum F_n (calibration.wall_friction)
    friction_along_flow: Number | None = None
    friction_along_flow_stderr: Number | None = None


class ImpactRelation(Table):
    """[impacts.ball_ball], [impacts.ball_wall]: v = c0 + c1 d gamma_dot (m/s) fitted on the
    DEM's coarse-grained field (c0_m_s, c1) and on the continuum's measure of the shear rate
    (c0_cells_m_s, c1_cells), v = a sqrt(T), v = b0 + b1 sqrt(T) on the coarse-grained points
    (b0_temperature_m_s, b1_temperature) and on the analysis cells' centres
    (b0_temperature_cells_m_s, b1_temperature_cells), and which of the shear rate and the
    temperature the DEM supports better on the cells (preferred_relation); further keys (the
    p95 relations, the shares within 0.8 - 1.25) are kept as they are written.  The *_stderr
    keys and the *_covariance_m_s keys (of each pair's intercept and slope, what a prediction's
    error needs: measure.stats.affine_prediction_stderr) are the delete-one-batch jackknife's
    (calibration.impacts.jackknife_of_refits): one batch's cycles move many points together,
    so the points' own least-squares errors would understate them.  The same cycles move the
    DEM's measured mean_normal_speed_m_s: the *_measured_covariance_* keys (m^2/s^2 for an
    intercept, m/s for a slope) are each coefficient's jackknife covariance with it, what a
    comparison of an inferred speed with that mean needs (analysis.impact_stats.
    relative_difference_stderr); the shear-rate relations' *_left_out keys are their
    coefficients with each batch left out, in batch order, for the covariance with any other
    statistic of those batches (a probe cell's measured speed: report.figures)."""
    count: Count | None = None
    mean_normal_speed_m_s: Number | None = None
    c0_m_s: Number | None = None
    c0_stderr_m_s: Number | None = None
    c1: Number | None = None
    c1_stderr: Number | None = None
    c0_c1_covariance_m_s: Number | None = None
    c0_measured_covariance_m2_s2: Number | None = None
    c1_measured_covariance_m_s: Number | None = None
    c0_left_out_m_s: list[Number] | None = None
    c1_left_out: list[Number] | None = None
    r2: Number | None = None
    a_temperature: Number | None = None
    a_temperature_stderr: Number | None = None
    c0_cells_m_s: Number | None = None
    c0_cells_stderr_m_s: Number | None = None
    c1_cells: Number | None = None
    c1_cells_stderr: Number | None = None
    c0_c1_cells_covariance_m_s: Number | None = None
    c0_cells_measured_covariance_m2_s2: Number | None = None
    c1_cells_measured_covariance_m_s: Number | None = None
    c0_cells_left_out_m_s: list[Number] | None = None
    c1_cells_left_out: list[Number] | None = None
    b0_temperature_m_s: Number | None = None
    b0_temperature_stderr_m_s: Number | None = None
    b1_temperature: Number | None = None
    b1_temperature_stderr: Number | None = None
    b0_b1_temperature_covariance_m_s: Number | None = None
    b0_temperature_measured_covariance_m2_s2: Number | None = None
    b1_temperature_measured_covariance_m_s: Number | None = None
    r2_temperature_affine: Number | None = None
    b0_temperature_cells_m_s: Number | None = None
    b0_temperature_cells_stderr_m_s: Number | None = None
    b1_temperature_cells: Number | None = None
    b1_temperature_cells_stderr: Number | None = None
    b0_b1_temperature_cells_covariance_m_s: Number | None = None
    b0_temperature_cells_measured_covariance_m2_s2: Number | None = None
    b1_temperature_cells_measured_covariance_m_s: Number | None = None
    r2_temperature_affine_cells: Number | None = None
    preferred_relation: Text | None = None


class Impacts(Table):
    """[impacts]: impact speeds against the shear rate and the granular temperature."""
    shear_rate_model: Text | None = None
    temperature_model: Text | None = None
    bagnold_sqrtT_over_d_gamma_dot: Number | None = None
    bagnold_r2: Number | None = None
    reference_shear_rate_1_s: Number | None = None
    ball_ball: ImpactRelation | None = None
    ball_wall: ImpactRelation | None = None


class CyclicShear(Table):
    """[cyclic_shear]: the cyclic shear cell at the tub's frequency, per strain amplitude."""
    frequency_Hz: Number | None = None
    pressure_Pa: Number | None = None
    tub_shear_rate_cycle_mean_1_s: Number | None = None
    tub_strain_amplitude: Number | None = None
    secant_shear_modulus_at_tub_amplitude_Pa: Number | None = None
    strain_amplitude: list[Number] | None = None
    secant_shear_modulus: list[Number] | None = None
    secant_shear_modulus_stderr: list[Number] | None = None


class Dilatancy(Table):
    """[dilatancy]: K_dil of mu = mu(I) + K_dil (phi - phi_eq(I)) (Pailha & Pouliquen 2009)."""
    K_dil: Number | None = None
    K_dil_stderr: Number | None = None
    initial_excess_solid_fraction: Number | None = None


class Compaction(Table):
    """[compaction]: the cyclic compaction of the packing at the tub's amplitude."""
    compaction_strain: Number | None = None
    excess_solid_fraction: Number | None = None


class WallFlux(Table):
    """[kinetic.wall_flux]: the fluctuation-energy flux of the walls into the balls (W/m^2),
    per arc bin of the U (arc_edges_m) and phase bin (phase_rad), with batch-means errors."""
    arc_edges_m: list[Number] | None = None
    phase_rad: list[Number] | None = None
    length_m: Number | None = None
    partition_area_m2: Number | None = None
    u_fluctuation_flux_W_m2: Number | None = None
    u_fluctuation_flux_stderr_W_m2: Number | None = None
    u_power_flux_W_m2: Number | None = None
    u_power_flux_stderr_W_m2: Number | None = None
    u_drive_flux_W_m2: Number | None = None
    u_drive_flux_stderr_W_m2: Number | None = None
    u_fluctuation_flux_by_arc_W_m2: list[Number] | None = None
    u_fluctuation_flux_by_arc_stderr_W_m2: list[Number] | None = None
    u_fluctuation_flux_by_phase_W_m2: list[Number] | None = None
    u_fluctuation_flux_by_phase_stderr_W_m2: list[Number] | None = None
    u_fluctuation_flux_by_phase_arc_W_m2: list[list[Number]] | None = None
    u_fluctuation_flux_by_phase_arc_stderr_W_m2: list[list[Number]] | None = None
    partitions_fluctuation_flux_W_m2: Number | None = None
    partitions_fluctuation_flux_stderr_W_m2: Number | None = None
    partitions_power_flux_W_m2: Number | None = None
    partitions_power_flux_stderr_W_m2: Number | None = None
    partitions_drive_flux_W_m2: Number | None = None
    partitions_drive_flux_stderr_W_m2: Number | None = None
    partitions_fluctuation_flux_by_phase_W_m2: list[Number] | None = None
    partitions_fluctuation_flux_by_phase_stderr_W_m2: list[Number] | None = None


class Conductivity(Table):
    """[kinetic.conductivity]: the DEM's fluctuation-energy flux q = -C kappa grad T against
    Gidaspow's conductivity kappa (calibration.conductivity): the multiplier C with its
    batch-means error, R^2, the cells' scatter and C by solid-fraction bin; and (gd_*) the
    two-term law q = -A kappa_GD grad T - B mu_GD grad phi of Garzo & Dufty
    (calibration.heat_flux_law): A, B, R^2 and the share of cells it points the right way, as
    it is and fitted, by solid-fraction bin and on the cycle means."""
    model: Text | None = None
    multiplier: Number | None = None
    multiplier_stderr: Number | None = None
    r2: Number | None = None
    cells: Count | None = None
    status: Text | None = None
    cell_ratio_median: Number | None = None
    cell_ratio_p16: Number | None = None
    cell_ratio_p84: Number | None = None
    down_gradient_fraction: Number | None = None
    flux_magnitude_ratio_median: Number | None = None
    kinetic_share: Number | None = None
    solid_fraction_range: list[Number] | None = None
    solid_fraction_edges: list[Number] | None = None
    multiplier_by_solid_fraction: list[Number] | None = None
    multiplier_by_solid_fraction_stderr: list[Number] | None = None
    cells_by_solid_fraction: list[Count] | None = None
    r2_by_solid_fraction: list[Number] | None = None
    # Garzo & Dufty's q = -A kappa grad T - B mu grad phi (calibration.heat_flux_law)
    gd_model: Text | None = None
    gd_status: Text | None = None
    gd_conductivity_multiplier: Number | None = None
    gd_conductivity_multiplier_stderr: Number | None = None
    gd_density_multiplier: Number | None = None
    gd_density_multiplier_stderr: Number | None = None
    gd_r2: Number | None = None
    gd_direction_fraction: Number | None = None
    gd_r2_as_is: Number | None = None
    gd_direction_fraction_as_is: Number | None = None
    gd_density_share: Number | None = None
    gd_conductivity_multiplier_by_solid_fraction: list[Number] | None = None
    gd_conductivity_multiplier_stderr_by_solid_fraction: list[Number] | None = None
    gd_density_multiplier_by_solid_fraction: list[Number] | None = None
    gd_density_multiplier_stderr_by_solid_fraction: list[Number] | None = None
    gd_r2_by_solid_fraction: list[Number] | None = None
    gd_direction_fraction_by_solid_fraction: list[Number] | None = None
    gd_unweighted_cells: Count | None = None
    gd_unweighted_conductivity_multiplier: Number | None = None
    gd_unweighted_conductivity_multiplier_stderr: Number | None = None
    gd_unweighted_density_multiplier: Number | None = None
    gd_unweighted_density_multiplier_stderr: Number | None = None
    gd_unweighted_r2: Number | None = None
    gd_unweighted_direction_fraction: Number | None = None
    gd_cycle_mean_cells: Count | None = None
    gd_cycle_mean_conductivity_multiplier: Number | None = None
    gd_cycle_mean_conductivity_multiplier_stderr: Number | None = None
    gd_cycle_mean_density_multiplier: Number | None = None
    gd_cycle_mean_density_multiplier_stderr: Number | None = None
    gd_cycle_mean_r2: Number | None = None
    gd_cycle_mean_direction_fraction: Number | None = None
    gd_cycle_mean_unweighted_cells: Count | None = None
    gd_cycle_mean_unweighted_conductivity_multiplier: Number | None = None
    gd_cycle_mean_unweighted_conductivity_multiplier_stderr: Number | None = None
    gd_cycle_mean_unweighted_density_multiplier: Number | None = None
    gd_cycle_mean_unweighted_density_multiplier_stderr: Number | None = None
    gd_cycle_mean_unweighted_r2: Number | None = None
    gd_cycle_mean_unweighted_direction_fraction: Number | None = None


class Kinetic(Table):
    """[kinetic]: kinetic theory's constants measured on the DEM: the ball-ball restitution e,
    the close packing phi_rcp of g0 fitted with Johnson & Jackson's frictional pressure (Fr,
    phi_min, exponents n, p) to p = rho_s phi T (1 + 2 (1 + e) phi g0) + p_f in the
    coarse-grained cells, the scatter of Lun's pressure alone beside it, the walls' energy
    flux, and the dense sliding loss's k_f (sliding_coefficient, from the shear cell), which the
    temperature's balance takes only where dense_dissipation = true."""
    model: Text | None = None
    g0_form: Text | None = None
    restitution: Number | None = None
    restitution_source: Text | None = None
    phi_rcp: Number | None = None
    phi_rcp_stderr: Number | None = None
    status: Text | None = None
    points: Count | None = None
    solid_fraction_range: list[Number] | None = None
    rms_log_residual: Number | None = None
    chi2_per_dof: Number | None = None
    frictional_Pa: Number | None = None
    frictional_Pa_stderr: Number | None = None
    frictional_phi_min: Number | None = None
    frictional_phi_min_stderr: Number | None = None
    frictional_n: Number | None = None
    frictional_p: Number | None = None
    lun_rms_log_residual: Number | None = None
    sliding_coefficient: Number | None = None
    sliding_coefficient_stderr: Number | None = None
    sliding_coefficient_source: Text | None = None
    dense_dissipation: bool | None = None
    wall_flux: WallFlux | None = None
    conductivity: Conductivity | None = None


class ScenarioMedia(Table):
    """[scenario.media]: the balls of the DEM run and the contact laws that shape the bed's
    rheology (normal restitution, Coulomb friction) against each other, the lining and the
    partitions."""
    diameter_m: Number | None = None
    density_kg_m3: Number | None = None
    ball_ball_restitution: Number | None = None
    ball_ball_friction: Number | None = None
    ball_wall_restitution: Number | None = None
    ball_wall_friction: Number | None = None
    ball_partition_restitution: Number | None = None
    ball_partition_friction: Number | None = None


class ScenarioTub(Table):
    """[scenario.tub]: the DEM run's tub."""
    radius_m: Number | None = None
    rim_height_m: Number | None = None
    length_m: Number | None = None
    periodic: bool | None = None


class ScenarioSource(Table):
    """[scenario]: the scenario the calibration was measured on (its case, media and tub), which
    a solver given the calibration checks its own scenario against."""
    case: Text | None = None
    media: ScenarioMedia | None = None
    tub: ScenarioTub | None = None


class Calibration(Table):
    """The whole of calibration.toml: [rheology], [elastic], [wall] and [media] required, the
    other tables when measured, [scenario] (the scenario it came from) last."""
    rheology: Rheology
    elastic: Elastic
    wall: Wall
    media: Media
    source: Source | None = None
    drucker_prager: DruckerPrager | None = None
    impacts: Impacts | None = None
    partitions: Partitions | None = None
    cyclic_shear: CyclicShear | None = None
    dilatancy: Dilatancy | None = None
    compaction: Compaction | None = None
    kinetic: Kinetic | None = None
    scenario: ScenarioSource | None = None

    @classmethod
    def from_dict(cls, tables: dict, where: str = "calibration") -> "Calibration":
        """The record of these tables; InputError naming `where`, the field (table.key), its
        value and what is allowed when one does not fit."""
        try:
            return cls.model_validate(tables)
        except ValidationError as e:
            raise InputError(f"{where}: {_first_error(e, tables)}") from None


def _first_error(e: ValidationError, tables: dict) -> str:
    """The first error as "table.key = value: what is allowed", with the table's status (why a
    fit left a value out) when it has one other than "measured"."""
    err = e.errors(include_url=False)[0]
    loc = [str(p) for p in err["loc"]]
    field = ".".join(loc)
    table = tables.get(loc[0]) if len(loc) == 2 else None
    status = table.get("status", "") if isinstance(table, dict) else ""
    why = f" ({status})" if status and status != "measured" else ""
    if err["type"] == "missing":
        what = "a table" if len(loc) == 1 else "a finite number"
        return f"{field} is missing: must be {what}{why}"
    msg = "must be a table" if err["type"] == "model_type" else \
        err["msg"].removeprefix("Value error, ")
    return f"{field} = {err.get('input')!r}: {msg}{why}"


def write_calibration(path, cal: Calibration) -> Path:
    """calibration.toml, atomically, with a header saying what it is."""
    path = Path(path)
    head = ("# vibroflow calibration: continuum parameters measured on a DEM run (SI units).\n"
            "# Read with vibroflow.calibration.read_calibration; every value has its standard\n"
            "# error (*_stderr, NaN where none could be estimated) and [source] says where it\n"
            "# came from.\n\n")
    return write_text_atomic(path, head + tomli_w.dumps(cal.to_toml_dict()))


def read_calibration(path) -> Calibration:
    """Read calibration.toml (a file, or a run directory holding one); InputError when it is
    missing, malformed or lacks a parameter the continuum needs."""
    p = Path(path)
    if p.is_dir():
        p = p / CALIBRATION_FILE
        if not p.is_file():
            raise InputError(f"calibration = {str(path)!r}: a folder with no {CALIBRATION_FILE} "
                             "(give the file, or run `vibroflow calibrate` on a DEM run)")
    if not p.is_file():
        raise InputError(f"calibration = {str(path)!r}: no such file (run `vibroflow calibrate`)")
    try:
        tables = tomllib.loads(p.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{p}: malformed TOML ({e})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{p}: cannot be read ({type(e).__name__}: {e})") from None
    return Calibration.from_dict(tables, where=str(p))
