"""The continua's granular temperature against the DEM's thermal temperature (the balls'
velocities about each snapshot's own coarse-grained velocity) and its phase-resolved one
(docs/validation.md section 28; calibration/thermal_temperature.py, measure/thermal.py).

    python benchmarks/thermal_temperature.py tub FIELDS_NC LAGRANGIAN_DIR EULERIAN_DIR
    python benchmarks/thermal_temperature.py layer DEM_JSON CONTINUA_JSON

tub: FIELDS_NC a calibration's fields.nc holding thermal_temperature_cycle_mean (`vibroflow
calibrate`; or a DEM run directory, coarse-grained here with the thermal temperature), the
continua's run folders with temperature.csv (`vibroflow continuum tub47-quick --method M
--calibration CAL --temperature`).  Printed: E of each continuum's T against the DEM's thermal
and phase-resolved T on the analysis cells (report.temperature_maps), the DEM's batch-means
error as an E, and by height the phi-weighted mean T of the cells with solid fraction >= 0.3.

layer: DEM_JSON the strip's profiles with the thermal temperature (tests/data/vibrated-layer-dem/
thermal.json), CONTINUA_JSON the continua's profiles (`python benchmarks/vibrated_layer.py
--dem DEM_JSON --out CONTINUA_JSON`).  Printed by band of height (cycle means, mass-weighted
over the phases, bands with cycle-mean solid fraction > 0.1): the DEM's T about each band's
mean and its thermal T with their seed scatter, each continuum's T and its ratio to the thermal
T; E against both and the largest miss over section 23's allowance (2 seed standard deviations).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from vibroflow.calibration.run_fields import coarse_grain_run, read_fields
from vibroflow.report.temperature_maps import PHI_KEY, SE_KEY, T_KEY, temperature_maps
from vibroflow.scenario import load_scenario
from vibroflow.tub.geometry import geometry_of


def tub(fields: str, lagrangian: str, eulerian: str, case: str) -> None:
    src = Path(fields)
    avg = read_fields(src) if src.is_file() else coarse_grain_run(src, thermal=True)[0]
    sc = load_scenario(case)
    runs = {"lagrangian": Path(lagrangian).resolve(), "eulerian": Path(eulerian).resolve()}
    data = SimpleNamespace(
        geometry=geometry_of(sc), scenario=sc, dem_fields=avg, continuum_methods=list(runs),
        out=Path("."), summary={"methods": {m: {"bulk_velocity_csv": str(p / "x.csv")}
                                            for m, p in runs.items()}})
    maps = temperature_maps(data)
    th, ph = maps.dem_thermal, maps.dem
    print(f"DEM thermal T's batch-means error as an E: {maps.E_dem_error:.3f}")
    for name, c in maps.continua.items():
        print(f"{name}: E against the thermal T {c['E_thermal']:.3f}, against the "
              f"phase-resolved T {c['E_phase_resolved']:.3f}")
    print("| z (mm) | DEM phase-resolved T | DEM thermal T | "
          + " | ".join(f"{m} (/ thermal)" for m in maps.continua) + " |")
    print("|---" * (3 + len(maps.continua)) + "|")
    for k in range(len(maps.z)):
        on = th[PHI_KEY][k] >= 0.3
        if not on.any():
            continue
        w = th[PHI_KEY][k][on]

        def mean(a, k=k, on=on, w=w):
            return float(np.sum(w * a[k][on]) / np.sum(w))
        se = float(np.sqrt(np.sum((w * th[SE_KEY][k][on]) ** 2)) / np.sum(w))
        print(f"| {1e3 * maps.z[k]:.0f} | {mean(ph[T_KEY]):.3g} | {mean(th[T_KEY]):.3g} +- "
              f"{se:.1g} | " + " | ".join(
                  f"{mean(c[T_KEY]):.3g} ({mean(c[T_KEY]) / mean(th[T_KEY]):.2f})"
                  for c in maps.continua.values()) + " |")


def _cycle_mean(T, phi):
    T, phi = np.nan_to_num(np.array(T, float)), np.nan_to_num(np.array(phi, float))
    w = phi.sum(0)
    return (T * phi).sum(0) / np.where(w > 0, w, np.nan)


def layer(dem_json: str, continua_json: str) -> None:
    with open(dem_json) as fh:
        dem = json.load(fh)
    with open(continua_json) as fh:
        cont = json.load(fh)
    s, seeds = dem["summary"], dem["seeds"]
    h = np.array(seeds[0]["height_m"])
    phi = np.nanmean(np.array(s["solid_fraction"], float), axis=0)
    on = phi > 0.1
    ref = {}
    for key, label in (("temperature_m2_s2", "about each band's mean"),
                       ("thermal_temperature_m2_s2", "thermal")):
        per = np.array([_cycle_mean(r[key], r["solid_fraction"]) for r in seeds])
        ref[label] = (_cycle_mean(s[key], s["solid_fraction"]), np.std(per, axis=0, ddof=1))
    Tc = {m: np.pad(_cycle_mean(c["temperature_m2_s2"], c["solid_fraction"]),
                    (0, h.size))[:h.size] for m, c in cont.items()}
    print("| height (mm) | phi | DEM T about the band's mean (seed sd) | DEM thermal T (seed sd) | "
          + " | ".join(f"{m} (/ thermal)" for m in Tc) + " |")
    print("|---" * (4 + len(Tc)) + "|")
    (Tb, sb), (Th, sh) = ref.values()
    for j in np.nonzero(on)[0]:
        print(f"| {1e3 * h[j]:.0f} | {phi[j]:.2f} | {Tb[j]:.3g} ({sb[j]:.1g}) | {Th[j]:.3g} "
              f"({sh[j]:.1g}) | " + " | ".join(f"{v[j]:.3g} ({v[j] / Th[j]:.2f})"
                                                for v in Tc.values()) + " |")
    w = phi[on]
    for label, (T, sd) in ref.items():
        mean = np.sum(w * T[on]) / w.sum()
        print(f"DEM seed scatter as an E, {label}: "
              f"{np.sqrt(np.sum(w * sd[on] ** 2) / w.sum()) / mean:.3f}")
        for m, v in Tc.items():
            E = np.sqrt(np.sum(w * (v[on] - T[on]) ** 2) / w.sum()) / mean
            miss = np.max(np.abs(v[on] - T[on]) / (2 * sd[on]))
            print(f"  {m} against the DEM's T {label}: E {E:.3f}, largest miss / allowance "
                  f"{miss:.1f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    t = sub.add_parser("tub")
    t.add_argument("fields")
    t.add_argument("lagrangian")
    t.add_argument("eulerian")
    t.add_argument("--case", default="tub47-quick")
    lay = sub.add_parser("layer")
    lay.add_argument("dem")
    lay.add_argument("continua")
    a = ap.parse_args(argv)
    if a.what == "tub":
        tub(a.fields, a.lagrangian, a.eulerian, a.case)
    else:
        layer(a.dem, a.continua)
    return 0


if __name__ == "__main__":
    sys.exit(main())
