"""Runs compared with each other, as tub47.md judges them ("How results are judged"): above the
solvers and the calibration, since it reads any method's results; what is measured on one run
is `vibroflow.measure`.

* compare -- field difference E(a, b), agreement of strengths and fields, seed scatter
* judge   -- runs judged against a reference method's seeds (`vibroflow compare`)
"""
from vibroflow.analysis.compare import field_difference, fields_agree, strengths_agree

__all__ = ["field_difference", "fields_agree", "strengths_agree"]
