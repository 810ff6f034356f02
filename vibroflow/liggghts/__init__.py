"""The LIGGGHTS round trip: a tub scenario exported as a LIGGGHTS 3.8 deck, run elsewhere, and its
dumps imported back as vibroflow results, so the two codes are compared with the same analysis.

    export_deck(scenario, DIR)      DIR/in.tub, tub_u.stl, partitions.stl, scenario.toml,
                                    README.txt, post/ (where LIGGGHTS writes)
    mpirun -np 2 liggghts -in in.tub    (in DIR; see README.txt and docs/liggghts.md)
    import_run(DIR/post, scenario, OUT) OUT/dem.h5 (vibroflow's DEM layout, source "liggghts"),
                                    OUT/summary.json, OUT/bulk_velocity.csv

Modules: stl (the tub's triangle meshes), dem_fill (a DEM run's settled bed as the deck's
start), fill_deck (the fill's lines of the deck), part_meshes (the parts' meshes), parameters (the
contact law, seeds and snapshot steps a scenario gives the deck), template (what user input may
put into a deck), deck (the export), deck_files (a deck folder's file names and README),
motion_deck (the tub's motion in the deck), part_deck (the parts' lines of the deck), launch
(running LIGGGHTS; its log's loop times), dumps (reading LIGGGHTS text dumps), contacts (the dumped
contacts as dem.h5 rows), part_contacts (the parts' impacts and loads), importer (a run's dumps
as dem.h5, summary.json, bulk_velocity.csv and, with parts, parts.nc).
"""
from vibroflow.liggghts.deck import DeckInfo, export_deck
from vibroflow.liggghts.deck_files import (BALL_DUMP, DECK_NAME, PAIR_DUMP, POST_DIR,
                                           SERIES_FILE, START_FILE, WALL_DUMP)
from vibroflow.liggghts.dem_fill import DemFill, dem_fill
from vibroflow.liggghts.dumps import DumpSnapshot, iter_dump, read_dump
from vibroflow.liggghts.importer import import_run
from vibroflow.liggghts.launch import find_liggghts, loop_times, mpirun_command, run_deck
from vibroflow.liggghts.parameters import (contact_law_lines, model_arguments, pair_tables,
                                           seed_primes)
from vibroflow.liggghts.template import safe_name

__all__ = ["BALL_DUMP", "DECK_NAME", "PAIR_DUMP", "POST_DIR", "SERIES_FILE", "START_FILE",
           "WALL_DUMP", "DeckInfo", "DemFill", "DumpSnapshot", "dem_fill", "contact_law_lines", "export_deck",
           "find_liggghts", "import_run", "iter_dump", "loop_times", "model_arguments",
           "mpirun_command", "pair_tables", "read_dump", "run_deck", "safe_name", "seed_primes"]
