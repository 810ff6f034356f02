"""Analysis shared by every method (DEM, imported LIGGGHTS runs, continuum): tub47.md "What is
measured".

* stats       -- batch means over whole vibration cycles (standard errors)
* bulk        -- the cell table (bulk velocity relative to the tub, solid fraction), its CSV,
                 probe values
* circulation -- stream function of the solid flux, circulation strength and sense
* compare     -- field difference E(a, b), agreement tests
* contacts    -- wall-contact friction ratios, impact speeds
* summary     -- tub_summary(dem.h5, scenario): the run's summary dict and bulk_velocity.csv
* vtk         -- ParaView output (imported on demand: `from vibroflow.analysis import vtk`)
"""
from vibroflow.analysis.bulk import (CellAccumulator, CellTable, cell_table, probe_values,
                                     read_csv, write_csv)
from vibroflow.analysis.circulation import Circulation, circulation, stream_function
from vibroflow.analysis.compare import field_difference, fields_agree, strengths_agree
from vibroflow.analysis.contacts import impact_stats, mean_by_region, wall_contact_stats
from vibroflow.analysis.stats import batch_means, batches_of_whole_cycles
from vibroflow.analysis.summary import tub_summary

__all__ = [
    "CellAccumulator", "CellTable", "cell_table", "probe_values", "read_csv", "write_csv",
    "Circulation", "circulation", "stream_function",
    "field_difference", "fields_agree", "strengths_agree",
    "impact_stats", "mean_by_region", "wall_contact_stats",
    "batch_means", "batches_of_whole_cycles", "tub_summary",
]
