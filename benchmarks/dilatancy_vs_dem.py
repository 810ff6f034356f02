"""The continuum with and without the dilatancy option against the DEM (benchmarks/README.md,
"Dilatancy"): one continuum run of a finished DEM's scenario with a given calibration, K_dil set
in its [dilatancy] table, printed as one JSON line: circulation strength against the DEM's, the
ratio and the field difference E (tub47.md; vibroflow.analysis.compare.field_difference).

    .venv/bin/python benchmarks/dilatancy_vs_dem.py --dem-dir runs/study-quick/dem \
        --calibration runs/study-quick/calibration/calibration.toml --k-dil 6.71 --out runs/dil/L1

--compaction adds the cyclic compaction option with the calibration's [compaction] (or
--gamma-c / --dphi-cyc); --diagnose (Lagrangian) also prints, over the samples of the last
cycle, the fractions of disconnected / elastic / flowing points and percentiles of the connected
points' unloaded packing phi = rho exp(-p / K) / rho_s minus phi_c.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dem-dir", required=True, type=Path, help="a finished DEM folder")
    ap.add_argument("--calibration", required=True, type=Path, help="calibration.toml")
    ap.add_argument("--method", default="lagrangian", choices=("lagrangian", "eulerian"))
    ap.add_argument("--k-dil", type=float, default=0.0, help="K_dil (0: the option off)")
    ap.add_argument("--excess", type=float, default=0.0,
                    help="initial_excess_solid_fraction of the bed over phi_c")
    ap.add_argument("--cfl", type=float, default=0.3)
    ap.add_argument("--transfer-cfl", type=float, default=0.0,
                    help="the APIC transfers' Courant number (ContinuumOptions.transfer_cfl); "
                         "default 0: one transfer a step")
    ap.add_argument("--compaction", action="store_true", help="the cyclic compaction option")
    ap.add_argument("--gamma-c", type=float, default=None, help="override [compaction] "
                    "compaction_strain")
    ap.add_argument("--dphi-cyc", type=float, default=None, help="override [compaction] "
                    "excess_solid_fraction")
    ap.add_argument("--diagnose", action="store_true", help="point states and packing over "
                    "the last cycle (Lagrangian)")
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args(argv)

    from vibroflow.measure.bulk import read_csv
    from vibroflow.analysis.compare import field_difference
    from vibroflow.io.calibration_file import Calibration, read_calibration
    from vibroflow.calibration.dem_result import DEMResult
    from vibroflow.continuum.formulation import formulation
    from vibroflow.continuum.tub_run import run_continuum

    with DEMResult.open(args.dem_dir) as res:
        sc = res.scenario
    dem = json.loads((args.dem_dir / "summary.json").read_text())
    tables = read_calibration(args.calibration).to_toml_dict()
    if args.k_dil > 0:
        tables["dilatancy"] = {**tables.get("dilatancy", {}), "K_dil": args.k_dil,
                               "initial_excess_solid_fraction": args.excess}
    if args.compaction:
        comp = dict(tables.get("compaction", {}))
        if args.gamma_c is not None:
            comp["compaction_strain"] = args.gamma_c
        if args.dphi_cyc is not None:
            comp["excess_solid_fraction"] = args.dphi_cyc
        tables["compaction"] = comp
    cal = Calibration.from_dict(tables, where=str(args.calibration))
    opts = dict(dilatancy=args.k_dil > 0, cfl=args.cfl, compaction=args.compaction,
                transfer_cfl=args.transfer_cfl)
    diag = []
    if args.diagnose:
        import numpy as np

        import vibroflow.continuum.mpm.formulation as mpm_formulation

        write_points = mpm_formulation._write_points_vtu

        def spy(vtk, j, t, pose6, state, *rest):
            diag.append((state.phase.copy(), state.density.copy(), state.pressure().copy()))
            return write_points(vtk, j, t, pose6, state, *rest)

        mpm_formulation._write_points_vtu = spy
    t0 = time.perf_counter()
    s = run_continuum(sc, args.out, args.method, calibration=cal,
                      options=formulation(args.method).options(**opts),
                      vtk=args.diagnose and args.method == "lagrangian")
    h = sc.analysis.cell_size
    E = field_difference(read_csv(args.out / "bulk_velocity.csv", cell_size=h),
                         read_csv(args.dem_dir / "bulk_velocity.csv", cell_size=h),
                         sc.analysis.min_solid_fraction)
    c, dc = s["circulation"], dem["circulation"]
    extra = {}
    if diag:
        from vibroflow.continuum.material import material_of
        from vibroflow.continuum.stress_update import unloaded_packing

        mat = material_of(sc, cal, dilatancy=args.k_dil > 0, compaction=args.compaction)
        ph = np.concatenate([d[0] for d in diag])
        rho = np.concatenate([d[1] for d in diag])
        p = np.concatenate([d[2] for d in diag])
        conn = ph != 0
        dphi = unloaded_packing(rho[conn], p[conn], mat.bulk_modulus, mat.solid_density) \
            - mat.critical_solid_fraction
        extra = {"fraction_disconnected": float(np.mean(ph == 0)),
                 "fraction_elastic": float(np.mean(ph == 1)),
                 "fraction_flowing": float(np.mean(ph == 2)),
                 "connected_dphi_p5_p50_p95": [float(v) for v in
                                               np.percentile(dphi, [5, 50, 95])],
                 "pressure_mean_Pa": float(np.mean(p))}
    print(json.dumps({"amplitude_factor": sc.motion.amplitude_factor, "method": args.method,
                      "K_dil": args.k_dil, "excess": args.excess, "cfl": args.cfl,
                      "transfer_cfl": args.transfer_cfl,
                      "compaction": ({"compaction_strain": cal.compaction.compaction_strain,
                                      "excess_solid_fraction":
                                          cal.compaction.excess_solid_fraction}
                                     if args.compaction else None),
                      "strength": c["strength"], "strength_stderr": c["strength_stderr"],
                      "dem_strength": dc["strength"], "dem_strength_stderr": dc["strength_stderr"],
                      "ratio": c["strength"] / dc["strength"], "E": E,
                      "wall_time_s": time.perf_counter() - t0, **extra}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
