"""The vibrated layer: the DEM strip against both continua with the granular temperature
(issue 29's check; vibroflow.calibration.vibrated_layer, vibrated_layer_continuum).

    python benchmarks/vibrated_layer.py [--case tub47] [--dem-out FILE | --dem FILE]
        [--calibration FILE] [--methods lagrangian,eulerian] [--seeds 1,2,3,4,5] [--out FILE]

--dem-out FILE runs the DEM strip over the seeds and writes its profiles (JSON, atomically);
the stored reference tests/data/vibrated-layer-dem/layer.json is

    python benchmarks/vibrated_layer.py --dem-out tests/data/vibrated-layer-dem/layer.json \
        --methods none

--dem FILE reads a stored one instead.  Each continuum runs the same strip and phases; printed:
the take-off phase (the floor's psi / 2 pi), the floor force's cycle mean / weight, and by
band of height at the phase of the floor's top (psi = pi / 2, phase 4/16) T and phi, with the
DEM's seed mean and seed scatter beside each.  --out FILE: the continua's profiles (JSON).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

import bench
from vibroflow.calibration.vibrated_layer import LayerSetup, vibrated_layer
from vibroflow.calibration.vibrated_layer_continuum import continuum_layer
from vibroflow.io.atomic import json_safe, write_json_atomic
from vibroflow.io.calibration_file import read_calibration


def rounded(obj, digits=4):
    """The JSON tree with floats to `digits` significant digits."""
    if isinstance(obj, float):
        return obj if not math.isfinite(obj) or obj == 0 else float(f"{obj:.{digits}g}")
    if isinstance(obj, dict):
        return {k: rounded(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [rounded(v, digits) for v in obj]
    return obj


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", default="tub47")
    ap.add_argument("--calibration", default="tests/data/tub47-dem/calibration.toml")
    ap.add_argument("--dem", default="tests/data/vibrated-layer-dem/layer.json")
    ap.add_argument("--dem-out", default=None)
    ap.add_argument("--methods", default="lagrangian,eulerian")
    ap.add_argument("--seeds", default="1,2,3,4,5")
    ap.add_argument("--out", default=None, help="the continua's profiles (JSON)")
    a = ap.parse_args(argv)
    scenario = bench.scenario(a.case)
    if a.dem_out:
        setup = LayerSetup(seeds=tuple(int(s) for s in a.seeds.split(",")))
        t0 = time.time()
        dem = rounded(json_safe(vibrated_layer(scenario, setup)))
        dem["command"] = ("python benchmarks/vibrated_layer.py --dem-out "
                          f"{a.dem_out} --methods none --case {a.case} --seeds {a.seeds}")
        write_json_atomic(a.dem_out, dem, indent=None)
        print(f"DEM: {len(setup.seeds)} seeds, {time.time() - t0:.0f} s -> {a.dem_out}")
    else:
        with open(a.dem) as fh:
            dem = json.load(fh)
    s = dem["summary"]
    setup = LayerSetup(**{k: (tuple(v) if k == "seeds" else v) for k, v in dem["setup"].items()})
    weight = dem["seeds"][0]["mass_kg"] * 9.81 / (dem["strip"]["length_m"]
                                                   * dem["strip"]["width_m"])
    print(f"{dem['case']}: Gamma {dem['stroke']['gamma']:.3g}; DEM take-off "
          f"{s['take_off_phase']:.3f} +- {s['take_off_phase_seed_scatter']:.3f} (seed scatter), "
          "cycle-mean floor force / weight "
          + ", ".join(f"{r['floor_force_cycle_mean_over_weight']:.3f}" for r in dem["seeds"]))
    cal = read_calibration(a.calibration)
    runs = {}
    for method in [m for m in a.methods.split(",") if m and m != "none"]:
        t0 = time.time()
        c = continuum_layer(method, scenario, cal, setup, weight / 9.81)
        runs[method] = c
        if a.out:
            write_json_atomic(a.out, rounded(json_safe(runs)), indent=None)
        print(f"\n{method} ({time.time() - t0:.0f} s; {c['kinetic_source']}): take-off "
              f"{c['take_off_phase']:.3f}, cycle-mean force / weight "
              f"{c['floor_force_cycle_mean_over_weight']:.3f}")
        print("| height (mm) | T DEM (m2/s2) | scatter | T continuum | phi DEM | scatter | "
              "phi continuum |")
        print("|---|---|---|---|---|---|---|")
        ph = 4
        for j, z in enumerate(dem["seeds"][0]["height_m"]):
            if j >= len(c["height_m"]) or (s["solid_fraction"][ph][j] or 0) < 0.05:
                continue
            print(f"| {1e3 * z:.0f} | {s['temperature_m2_s2'][ph][j]:.4f} | "
                  f"{s['temperature_m2_s2_seed_scatter'][ph][j]:.4f} | "
                  f"{np.nan_to_num(c['temperature_m2_s2'][ph][j]):.4f} | "
                  f"{s['solid_fraction'][ph][j]:.3f} | "
                  f"{s['solid_fraction_seed_scatter'][ph][j]:.3f} | "
                  f"{c['solid_fraction'][ph][j]:.3f} |")
        print("force / weight by phase: " + " ".join(
            f"{v:.2f}" for v in c["floor_force_over_weight"]))
    print("DEM force / weight by phase: " + " ".join(
        f"{v:.2f}" for v in s["floor_force_over_weight"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
