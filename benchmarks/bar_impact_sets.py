"""The bar's impacts in the DEM and in LIGGGHTS, impact by impact, from runs already on disk
(benchmarks/bar_maps.py's folders): why the two codes' counts and speeds differ
(docs/validation.md section 27).

    python benchmarks/bar_impact_sets.py [--out runs/bar_maps_fromdem] [--seeds 1 2]
                                         [--tag liggghts-fromdem]

For each seed: the DEM's /part_impacts (dem-seed<N>/dem.h5) and LIGGGHTS' per-step part dump
(<tag>-seed<N>/post/part_contacts.dump) read by the import's rule
(vibroflow.liggghts.part_contacts.part_impacts) on two meshes, the deck's own part_<name>.stl and
the export's default 0.05 mm chords.  Per set: impacts in the window, their mean normal speed,
the energy delivered (W over average_last), the impacts below 0.1 m/s, the repeats of a ball
within 1 ms and the impacts above the contact-law threshold (g + A_z omega^2) sqrt(m/k) (the
speed whose peak force v sqrt(k m) equals the ball's weight in the tub's peak acceleration).
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import h5py
import numpy as np

from vibroflow.liggghts.dumps import read_dump
from vibroflow.liggghts.parameters import ball_mass, pair_tables
from vibroflow.liggghts.part_contacts import PartGeometry, deck_meshes, part_impacts
from vibroflow.scenario.io import load_scenario
from vibroflow.tub.motion import TubMotion
from vibroflow.tub.parts import parts_of


def threshold(scenario) -> float:
    """(g + A_z omega^2) sqrt(m / k_n) (m/s) of the balls' pair with the first part."""
    k = pair_tables(scenario).kn[0, 3]
    m = ball_mass(scenario)
    mo = scenario.motion
    a = mo.amplitude_z * mo.amplitude_factor * (2.0 * math.pi * mo.frequency) ** 2
    return (float(np.linalg.norm(scenario.gravity)) + a) * math.sqrt(m / k)


def describe(name: str, time, ball, vn, mass: float, window: float, v_th: float) -> None:
    o = np.lexsort((time, ball))
    same = ball[o][1:] == ball[o][:-1]
    repeats = int(np.sum(np.diff(time[o])[same] < 1e-3))
    print(f"  {name:34s} {vn.size:5d} impacts, mean v_n {vn.mean():.3f} m/s, "
          f"{0.5 * mass * np.sum(vn ** 2) / window:.3f} W, below 0.1 m/s {int(np.sum(vn < 0.1))}, "
          f"repeats within 1 ms {repeats}, above {v_th:.4f} m/s {int(np.sum(vn > v_th))}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("runs/bar_maps_fromdem"))
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--tag", default="liggghts-fromdem")
    args = ap.parse_args()
    for seed in args.seeds:
        deck = args.out / f"{args.tag}-seed{seed}"
        s = load_scenario(deck / "scenario.toml")
        run, m = s.run, ball_mass(s)
        v_th = threshold(s)
        print(f"seed {seed}:")
        with h5py.File(args.out / f"dem-seed{seed}" / "dem.h5", "r") as f:
            g = f["part_impacts"]
            describe("DEM", g["time"][()], g["ball"][()], g["normal_speed"][()].astype(float),
                     m, run.average_last, v_th)
        post = deck / "post"
        n0 = int((post / "vibration_start_step.txt").read_text().split()[0])
        ids = np.sort(next(iter(read_dump(post / "balls.dump"))).data[:, 0].astype(np.int64))
        parts = parts_of(s)
        rho = s.materials[s.fill.material].density
        for name, meshes in (("LIGGGHTS, the deck's mesh", deck_meshes(deck, parts)),
                             ("LIGGGHTS, the default 0.05 mm mesh", None)):
            geom = PartGeometry(parts, s.tub.length, s.tub.periodic, meshes)
            imp = part_impacts(post / "part_contacts.dump", geom, TubMotion.of_scenario(s), n0,
                               run.dt, int(round((run.duration - run.average_last) / run.dt)),
                               ids, rho)
            describe(name, imp["time"], imp["ball"], imp["normal_speed"].astype(float), m,
                     run.average_last, v_th)


if __name__ == "__main__":
    main()
