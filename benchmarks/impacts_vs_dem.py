"""Impact speeds inferred from the continuum's shear rate against the DEM's measured impacts
(the mission's comparison 4: "impact velocity inferred from the continuum shear rate against DEM
impacts"; docs/decisions/impact-speed.md).

    python benchmarks/impacts_vs_dem.py --dem-dir runs/study-tub47/dem
        [--calibration FILE] [--methods lagrangian,eulerian] [--settle-time 0.05]
        [--set key=value ...]

For the DEM run in DIR (its dem.h5 and, by default, its calibration.toml) this prints:

* the DEM's shear rate measured as a continuum measures it (the phase-resolved velocity field
  of its snapshots on the analysis cells, vibroflow.measure.phase_shear): the bed's
  solid-weighted mean and the near-wall one, with batch-means standard errors;
* the impact relation v = c0 + c1 d gamma_dot fitted on that measure
  (calibration.impacts.impact_relations_on_cells) beside the calibration's relation fitted on
  the 5 mm coarse-grained field;
* for each continuum method, run on the same scenario with its default options: its shear
  rate on both definitions (the phase-resolved field's, which the runs report, and the mean
  of its points' instantaneous rates), and the mean ball-ball and
  ball-wall impact speeds inferred from each, against the DEM's measured means (the phase
  field's ratio +- its error: the run's, the relation's and the DEM's, less the relation's
  covariance with the DEM's mean, as the report's);
* the shear rate of the time-averaged field (the slow roll alone), DEM and continua: the rest
  of the phase field's is the bed's deformation within each cycle;
* the DEM's own inference (the cell relation applied to its own cell shear rate): the part of
  any difference that is the relation's (its scatter and weighting), not the flow's; beside
  the measured means (every impact alike), the DEM's node means weighted by solid fraction as
  a continuum's bed mean is.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path)
    ap.add_argument("--calibration", type=Path, default=None)
    ap.add_argument("--methods", default="lagrangian,eulerian")
    ap.add_argument("--settle-time", type=float, default=None)
    ap.add_argument("--set", action="append", default=[], dest="sets")
    args = ap.parse_args(argv)

    from vibroflow.io.calibration_file import Calibration, read_calibration
    from vibroflow.calibration.dem_result import DEMResult
    from vibroflow.analysis.impact_stats import relative_difference_stderr
    from vibroflow.calibration.impacts import impact_relations_on_cells
    from vibroflow.measure.contacts import mean_speed_stderr
    from vibroflow.report.impact_figures import measured_covariance
    from vibroflow.scenario.io import apply_overrides

    cal_path = args.calibration or args.dem_dir / "calibration.toml"
    tables = read_calibration(cal_path).to_toml_dict()
    with DEMResult.open(args.dem_dir) as res:
        scenario = res.scenario
        d = res.diameter
        cells = impact_relations_on_cells(res)
    if args.sets:
        scenario = apply_overrides(scenario, args.sets)
    dem = json.loads((args.dem_dir / "summary.json").read_text())["impacts"]
    measured = {"ball_ball": dem["ball_ball_mean_normal_speed"],
                "ball_wall": dem["ball_wall_mean_normal_speed"]}
    measured_se = {k: dem.get(f"{k}_mean_normal_speed_stderr") for k in measured}
    # the relation the continuum uses: fitted on the continuum's measure, with its errors
    for name in ("ball_ball", "ball_wall"):
        g = cells[name]
        tables["impacts"][name].update(
            c0_cells_m_s=g["c0"], c1_cells=g["c1"], c0_cells_stderr_m_s=g["c0_stderr"],
            c1_cells_stderr=g["c1_stderr"], c0_c1_cells_covariance_m_s=g["c0_c1_covariance"],
            c0_cells_measured_covariance_m2_s2=g["c0_measured_covariance"],
            c1_cells_measured_covariance_m_s=g["c1_measured_covariance"])
    cal = Calibration.from_dict(tables, where=str(cal_path))

    print(f"DEM {args.dem_dir} ({scenario.case}): shear rate on the analysis cells "
          f"(phase-resolved field, h = {cells['cell_size_m'] * 1e3:.0f} mm): bed "
          f"{cells['bed_mean_shear_rate_1_s']:.3f} +- "
          f"{cells['bed_mean_shear_rate_1_s_stderr']:.3f} 1/s, near the wall "
          f"{cells['near_wall_shear_rate_1_s']:.3f} +- "
          f"{cells['near_wall_shear_rate_1_s_stderr']:.3f} 1/s; the roll's alone (the "
          f"time-averaged field's) {cells['bed_roll_shear_rate_1_s']:.3f} 1/s")
    own = {}
    for name, rate in (("ball_ball", cells["bed_mean_shear_rate_1_s"]),
                       ("ball_wall", cells["near_wall_shear_rate_1_s"])):
        fine = getattr(cal.impacts, name)
        c = cells[name]
        own[name] = c["c0"] + c["c1"] * d * rate
        sw = c["mean_normal_speed_solid_weighted"]
        print(f"  {name}: measured mean {measured[name]:.4f} m/s (the nodes' means weighted by "
              f"solid fraction, as a continuum's mean is: {sw:.4f}); relation on cells c0 "
              f"{c['c0']:.4f} m/s, c1 {c['c1']:.3f} (R^2 {c['r2']:.2f}, {c['points']} points); "
              f"on the 5 mm field c0 {fine.c0_m_s:.4f}, c1 {fine.c1:.3f}; the DEM's own "
              f"inference {own[name]:.4f} ({own[name] / measured[name]:.2f} of measured, "
              f"{own[name] / sw:.2f} of the solid-weighted)")

    rows = []
    for method in [m.strip() for m in args.methods.split(",") if m.strip()]:
        out = Path(tempfile.mkdtemp(prefix=f"impacts-{method}-"))
        if method in ("lagrangian", "eulerian"):
            from vibroflow.continuum.formulation import formulation
            from vibroflow.continuum.tub_run import run_continuum
            form = formulation(method)
            opt = (form.options(settle_time=args.settle_time) if args.settle_time
                   else form.options())
            s = run_continuum(scenario, out, method, calibration=cal, options=opt)
        else:
            print(f"--methods: {method!r} is not lagrangian or eulerian", file=sys.stderr)
            return 2
        sr = s["continuum"]["shear_rate"]
        row = {"method": method, "bed": sr["mean_1_s"], "bed_se": sr["mean_1_s_stderr"],
               "wall": sr["near_wall_1_s"], "wall_se": sr["near_wall_1_s_stderr"],
               "bed_inst": sr["instantaneous_mean_1_s"], "roll": sr["roll_mean_1_s"],
               "wall_inst": sr["instantaneous_near_wall_1_s"]}
        bb, bw = cal.impacts.ball_ball, cal.impacts.ball_wall
        row["bb_old"] = bb.c0_m_s + bb.c1 * d * row["bed_inst"]
        row["bw_old"] = bw.c0_m_s + bw.c1 * d * row["wall_inst"]
        for key, name in (("bb", "ball_ball"), ("bw", "ball_wall")):
            im = s["impacts"]
            v = im[f"{name}_mean_normal_speed"]
            row[key] = v
            # the ratio's error: the run's and the relation's errors, and the DEM's, less the
            # relation's covariance with the DEM's mean where both are this run's
            row[key + "_se"] = relative_difference_stderr(
                v, mean_speed_stderr(im, name), measured[name], measured_se[name],
                measured_covariance(im, name, measured[name]))
        rows.append(row)

    sw_bb = cells["ball_ball"]["mean_normal_speed_solid_weighted"]
    sw_bw = cells["ball_wall"]["mean_normal_speed_solid_weighted"]
    print()
    print("(ratios to the DEM's measured means; in brackets, to its solid-weighted node means)")
    print("| method | bed shear rate, phase field (DEM) | the roll's (DEM) | instantaneous | "
          "near-wall, phase field "
          "(DEM) | instantaneous | ball-ball inferred / DEM measured: phase field, "
          "instantaneous | ball-wall phase field, instantaneous |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['method']} | {r['bed']:.2f} +- {r['bed_se']:.2f} "
              f"({cells['bed_mean_shear_rate_1_s']:.2f}) | {r['roll']:.2f} "
              f"({cells['bed_roll_shear_rate_1_s']:.2f}) | {r['bed_inst']:.2f} | "
              f"{r['wall']:.2f} +- {r['wall_se']:.2f} ({cells['near_wall_shear_rate_1_s']:.2f}) "
              f"| {r['wall_inst']:.2f} | {r['bb']:.4f} / {measured['ball_ball']:.4f} = "
              f"{r['bb'] / measured['ball_ball']:.2f} +- {r['bb_se']:.2f} "
              f"({r['bb'] / sw_bb:.2f}), {r['bb_old'] / measured['ball_ball']:.2f} "
              f"| {r['bw'] / measured['ball_wall']:.2f} +- {r['bw_se']:.2f} "
              f"({r['bw'] / sw_bw:.2f}), "
              f"{r['bw_old'] / measured['ball_wall']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
