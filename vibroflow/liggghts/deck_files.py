"""What a LIGGGHTS deck folder holds (vibroflow.liggghts.deck): the names of its files, the
deck's and the meshes' and those LIGGGHTS writes into post/ for the importer, and its README.txt
(`readme`, checked template lines like the deck's)."""
from __future__ import annotations

from vibroflow.liggghts.dem_fill import DATA_NAME
from vibroflow.liggghts.template import _SLOT, _Deck, _fmt, _whole, safe_name

DECK_NAME = "in.tub"
POST_DIR = "post"
BALL_DUMP = "balls.dump"
WALL_DUMP = "wall.dump"
PAIR_DUMP = "pairs.dump"
SERIES_FILE = "series.txt"
START_FILE = "vibration_start_step.txt"
FILL_FILE = "fill_done.txt"
SETTLE_FILE = "settle_done.txt"
#: the meshes' files, as vibroflow.liggghts.stl.write_tub_meshes names them
U_MESH_FILE = "tub_u.stl"
PARTITION_MESH_FILE = "partitions.stl"


_README = """LIGGGHTS deck for the vibroflow scenario '{}' (SI units)
=====================================================================

Files: in.tub (the deck), tub_u.stl (the U-shaped tub wall), partitions.stl (the glass
partitions at y = 0 and y = L_y), scenario.toml (the scenario it was written from), post/ (where
LIGGGHTS writes its output; post/dump_steps.txt lists the snapshot steps).

Run it in this folder with LIGGGHTS 3.8 on 2 MPI ranks:

    mpirun -np 2 liggghts -in in.tub

(as root Open MPI also wants --allow-run-as-root, and --oversubscribe on a machine with fewer
cores than ranks; the Debian package's executable is `liggghts`, a source build's `lmp_auto`).

What it does: inserts {} balls at random in the tub, lets them settle with the
tub at rest, then vibrates the tub for {} s ({} steps of
{} s) and writes WRITTEN (all at the same
steps), and the kinetic energy every {} steps to post/SERIES.

Then convert the results into vibroflow's format (dem.h5, summary.json, bulk_velocity.csv):

    vibroflow import liggghts post --out results

(the scenario is read from scenario.toml next to post/).  The tub's pose is not written by
LIGGGHTS: it is a known function of time, recomputed from the scenario by the importer.
"""


def readme(scenario, vib_steps: int, n_snap: int, wall_contacts: bool,
            pair_contacts: bool = True, from_dem: bool = False) -> _Deck:
    """README.txt of a deck folder as checked template lines (`_Deck`); from_dem: fill.data's."""
    outputs = [f"{_SLOT} snapshots of the balls to post/{BALL_DUMP}"]
    if wall_contacts:
        outputs.append(f"the ball-wall contacts to post/{WALL_DUMP}")
    if pair_contacts:
        outputs.append(f"the ball-ball contacts (ids, force) to post/{PAIR_DUMP}")
    written = ", ".join(outputs[:-1]) + (" and " if len(outputs) > 1 else "") + outputs[-1]
    template = _README.replace("WRITTEN", written).replace("SERIES", SERIES_FILE)
    if from_dem:
        template = template.replace("inserts {} balls at random in the tub,", "reads the {} balls "
                                    f"of a vibroflow DEM run's settled bed from {DATA_NAME},")
    if template.endswith("\n"):
        template = template[:-1]
    run = scenario.run
    text = _Deck()
    text.add_block(template, safe_name("case", scenario.case),
                   _whole("fill.count", scenario.fill.count, 1), _fmt(run.duration), vib_steps,
                   _fmt(run.dt), n_snap, _whole("run.series_every", run.series_every, 1))
    return text

