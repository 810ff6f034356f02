"""The bar's impact map in vibroflow's DEM and in LIGGGHTS 3.8 (the exported deck with the bar as
an STL mesh) on a short or the full tub47-bar, each code with several fill seeds.

    python benchmarks/bar_maps.py [--case short|full|preset] [--seeds 1 2] [--codes dem liggghts]
                                  [--out DIR] [--from-dem-fill] [--forget-histories [--relax S]]
                                  [--judge]

The short case (SHORT_SETS; tests/test_dem_vs_liggghts_bar.py runs the same): tub47-bar 19.05 mm
long (three ball diameters) with 1500 balls, the bar lowered to z = 0.045 m so that it lies
under about 4 cm of media, 0.5 s of settling (at most 0.6 s: LIGGGHTS' balls, inserted at
random up to the rim, need it to land and come to rest), 0.25 s of
vibration averaged over its last 0.2 s (9 cycles).  --case full (FULL_SETS): the tub47-bar
preset itself, 14 000 balls in the 63.5 mm slice, the bar at (0.05, 0.10) m under some 10 cm of
media, settled as the preset settles (0.5 s, at most 2 s), with the short case's vibration,
0.25 s averaged over its last 0.2 s (9 whole cycles, 4 batches): the preset's 3 s do not fit a
seed in minutes, LIGGGHTS from the DEM's bed taking 17 ms a step on 2 cores (its 1 um meshes
move every step: 300 000 steps, some 90 minutes) and the DEM 2 - 3 ms (10 - 14 minutes); with
0.25 s a seed takes the DEM 1 min (plus 1.5 - 3.5 min of settling, which the fill cache keeps)
and LIGGGHTS 8 min (docs/validation.md section 27, "The full tub47-bar").  --case preset
(PRESET_SETS): the tub47-bar preset as it stands, 3 s of vibration averaged over the last 2 s
(94 cycles, 4 batches); with LIGGGHTS inserting its own bed (2.5 ms a step on 2 cores, 13 - 40
min a seed) and the DEM (13 - 17 min a seed), without --from-dem-fill (its 1 um meshes: 90 min
a seed) (section 27, "The preset's own window").  Writes DIR/<code>-seed<N>/ (the runs),
DIR/<code>-seed<N>.csv (the bar's map, vibroflow.analysis.impact_maps.write_map_csv) and prints
the map differences E_rate and E_speed between the seeds of each code and between the codes.
Default DIR: runs/bar_maps (git-ignored).  --from-dem-fill: LIGGGHTS starts from the DEM run's
settled bed of the same seed (vibroflow.liggghts.dem_fill; its maps liggghts-fromdem-seed<N>).
--forget-histories: the DEM vibrates its settled bed with every tangential spring and rolling
history set to zero, as LIGGGHTS from that bed starts (run_dem(forget_histories=True); its runs
and maps dem-forget-seed<N>); with --relax S the bed then rests S seconds with the tub at rest
first, as LIGGGHTS' --fill-from settling does (0.1 s here; dem-relax-seed<N>).
--judge: runs nothing; judges the finished runs already in DIR (dem[-forget|-relax]-seed<N>,
liggghts[-fromdem]-seed<N>-result; a LIGGGHTS deck whose import is missing is imported first),
and prints per run the impacts per second on the bar, their mean normal speed and the energy
delivered (summary.json's part line, over the window's whole cycles), the cycle-mean force on
the bar with its batch-means error (parts.nc, vibroflow.analysis.impact_maps.cycle_mean), and
the map differences E(b, a) of each pair, a the reference (the DEM first, then the lower seed).
"""
from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

from vibroflow import liggghts as LG
import numpy as np

from vibroflow.analysis.impact_maps import (cycle_mean, part_map, rate_difference,
                                            speed_difference, write_map_csv)
from vibroflow.io.parts_file import read_parts
from vibroflow.dem.run import run_dem
from vibroflow.scenario.io import load_scenario

#: the short tub47-bar of the comparison
SHORT_SETS = ["tub.length=0.01905", "fill.count=1500", "parts.0.center=[0.05, 0.0, 0.045]",
              "fill.settle_time=0.5", "fill.max_settle_time=0.6", "run.duration=0.25",
              "run.average_last=0.2"]


#: the full tub47-bar (14 000 balls, 63.5 mm long, the bar at z = 0.10 m) with the short case's
#: vibration, 0.25 s averaged over its last 0.2 s (9 whole cycles, 4 batches): the preset's 3 s
#: take LIGGGHTS from the DEM's bed (its 1 um meshes move every step) some hours on 2 cores
FULL_SETS = ["run.duration=0.25", "run.average_last=0.2"]

#: the tub47-bar preset as it stands: 3 s of vibration averaged over the last 2 s (94 cycles)
PRESET_SETS: list[str] = []

CASES = {"short": SHORT_SETS, "full": FULL_SETS, "preset": PRESET_SETS}


def make_case(seed: int, case: str = "short"):
    """The scenario of the named case (CASES) with fill seed `seed`."""
    return load_scenario("tub47-bar", [*CASES[case], f"run.seed={seed}"])


def short_case(seed: int):
    return make_case(seed, "short")


def run_code(code: str, seed: int, root: Path, from_dem_fill: bool = False,
             forget_histories: bool = False, relax_s: float = 0.0,
             case: str = "short") -> Path:
    """Run one code on the case (CASES); returns the folder holding its parts.nc.  from_dem_fill:
    LIGGGHTS starts from the settled bed of the DEM run root/dem-seed<N> (made first if
    missing) instead of inserting its own.  forget_histories: the DEM starts the vibration
    with its contact histories at zero, in root/dem-forget-seed<N> (relax_s > 0: after
    relax_s at rest, in root/dem-relax-seed<N>)."""
    s = make_case(seed, case)
    if code == "dem":
        out = root / f"{dem_tag(forget_histories, relax_s)}-seed{seed}"
        run_dem(s, out, progress=case != "short", forget_histories=forget_histories, relax_s=relax_s)
        return out
    tag = "liggghts-fromdem" if from_dem_fill else "liggghts"
    deck = root / f"{tag}-seed{seed}"
    bed = None
    if from_dem_fill:
        if not (root / f"dem-seed{seed}" / "summary.json").is_file():
            run_code("dem", seed, root, case=case)
        bed = LG.dem_fill(root / f"dem-seed{seed}", s)
    LG.export_deck(s, deck, fill_from=bed)
    LG.run_deck(deck, nprocs=2, timeout=7200)
    out = root / f"{tag}-seed{seed}-result"
    LG.import_run(deck / "post", s, out)
    return out


def dem_tag(forget_histories: bool, relax_s: float) -> str:
    """The DEM run's name: dem, dem-forget or dem-relax."""
    if not forget_histories:
        return "dem"
    return "dem-relax" if relax_s > 0 else "dem-forget"


def mean_force(run_dir: Path, part: str = "bar") -> tuple[np.ndarray, np.ndarray]:
    """The cycle-mean force on the part (N, part axes) and its batch-means error (parts.nc)."""
    sel = read_parts(run_dir / "parts.nc").sel(part=part)
    return cycle_mean(sel["force"].values, sel["force_stderr"].values)


def judge(root: Path, seeds: list[int], case: str = "short") -> dict:
    """Print what the module docstring says of the finished runs in root; returns the maps."""
    maps = {}
    for name in ("dem", "dem-forget", "dem-relax", "liggghts", "liggghts-fromdem"):
        for seed in seeds:
            folder = root / (f"{name}-seed{seed}" if name.startswith("dem")
                             else f"{name}-seed{seed}-result")
            deck = root / f"{name}-seed{seed}"
            if name.startswith("liggghts") and not (folder / "summary.json").is_file() and (
                    deck / "post" / LG.BALL_DUMP).is_file():
                LG.import_run(deck / "post", make_case(seed, case), folder)
            if not (folder / "parts.nc").is_file():
                continue
            maps[name, seed] = part_map(folder / "parts.nc", "bar")
            write_map_csv(root / f"{name}-seed{seed}.csv", maps[name, seed])
            tot = json.loads((folder / "summary.json").read_text())["parts"][0]
            f, e = mean_force(folder)
            print(f"{name} seed {seed}: {tot['impacts_per_s']:.0f} impacts/s, mean normal speed "
                  f"{tot['normal_speed_mean_m_s']:.3f} m/s, {tot['energy_per_s_W']:.3f} W; "
                  "mean force on the bar "
                  f"x {f[0]:+.2f} +- {e[0]:.2f} N, z {f[2]:+.2f} +- {e[2]:.2f} N")
    return maps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--codes", nargs="+", default=["dem", "liggghts"])
    ap.add_argument("--out", type=Path, default=Path("runs/bar_maps"))
    ap.add_argument("--from-dem-fill", action="store_true",
                    help="LIGGGHTS starts from the DEM run's settled bed of the same seed")
    ap.add_argument("--forget-histories", action="store_true",
                    help="the DEM starts the vibration with its contact histories at zero")
    ap.add_argument("--relax", type=float, default=0.0, metavar="S",
                    help="with --forget-histories: S seconds at rest first (s)")
    ap.add_argument("--case", choices=sorted(CASES), default="short",
                    help="short: SHORT_SETS (default); full: the tub47-bar preset")
    ap.add_argument("--judge", action="store_true",
                    help="run nothing: judge the finished runs already in --out")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    maps = judge(args.out, args.seeds, args.case) if args.judge else {}
    for code in [] if args.judge else args.codes:
        for seed in args.seeds:
            t0 = time.perf_counter()
            folder = run_code(code, seed, args.out, args.from_dem_fill, args.forget_histories,
                              args.relax, args.case)
            name = ("liggghts-fromdem" if code == "liggghts" and args.from_dem_fill else
                    dem_tag(args.forget_histories, args.relax) if code == "dem" else code)
            maps[name, seed] = part_map(folder / "parts.nc", "bar")
            write_map_csv(args.out / f"{name}-seed{seed}.csv", maps[name, seed])
            print(f"{code} seed {seed}: {time.perf_counter() - t0:.0f} s", flush=True)
    for (ka, a), (kb, b) in itertools.combinations(maps.items(), 2):
        print(f"E({kb[0]} {kb[1]} against {ka[0]} {ka[1]}): rate {rate_difference(b, a):.3f}, "
              f"speed {speed_difference(b, a):.3f}")


if __name__ == "__main__":
    main()
