"""The whole study in one command (`vibroflow run`): a pipeline of stages.

    dem          -> DIR/dem           run_dem (resumes from its checkpoint)
    calibration  -> DIR/calibration   calibrate DIR/dem: calibration.toml, fields.nc, pictures
    <method>     -> DIR/<method>      every continuum formulation of `methods.METHODS`
    comparison   -> DIR/comparison    probes, circulation, E against the DEM, cost;
                                      writes DIR/summary.json
    report       -> DIR/report        DIR/report.html (vibroflow.report.stage: the layer above
                                      the study, so the commands hand it over as an extra stage)

Each stage keeps DIR/<stage>/stage.json (written atomically, last) with the hash of its inputs
(the scenario fields it depends on, its options, the upstream stages' hashes and the vibroflow
version); a rerun skips the stages whose hash matches.  `load(DIR)` reads a finished study back.
"""
from vibroflow.study.methods import METHODS, ContinuumMethod
from vibroflow.study.pipeline import run_study
from vibroflow.study.results import load

__all__ = ["METHODS", "ContinuumMethod", "run_study", "load"]
