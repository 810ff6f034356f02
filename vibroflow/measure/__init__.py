"""What is measured on a run, the same for every method (DEM, imported LIGGGHTS runs, both
continua): tub47.md "What is measured".  Each solver measures its own results with these, so
they sit below the solvers; the comparisons of runs with each other are `vibroflow.analysis`.

* stats       -- batch means over whole vibration cycles (standard errors)
* bulk        -- the cell table (bulk velocity relative to the tub, solid fraction), its CSV,
                 probe values
* circulation -- stream function of the solid flux, circulation strength and sense
* contacts    -- wall-contact friction ratios, impact speeds
* phase_shear -- the shear rate of the phase-resolved velocity on the analysis cells
* column      -- the run-out and height of a collapsed column
* floor_force -- the U floor's force over the cycle, the bed's take-off, the U wall's feed by
                 region and phase (floor.csv, wall_feed.csv)
* summary     -- tub_summary(dem.h5, scenario): the run's summary dict and bulk_velocity.csv
"""
from vibroflow.measure.bulk import (
                                    CellAccumulator,
                                    CellTable,
                                    cell_table,
                                    probe_values,
                                    read_csv,
                                    write_csv,
)
from vibroflow.measure.circulation import Circulation, circulation, stream_function
from vibroflow.measure.contacts import impact_stats, mean_by_region, wall_contact_stats
from vibroflow.measure.stats import batch_means, batches_of_whole_cycles
from vibroflow.measure.summary import tub_summary

__all__ = [
    "CellAccumulator", "CellTable", "cell_table", "probe_values", "read_csv", "write_csv",
    "Circulation", "circulation", "stream_function",
    "impact_stats", "mean_by_region", "wall_contact_stats",
    "batch_means", "batches_of_whole_cycles", "tub_summary",
]
