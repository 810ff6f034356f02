"""The files of a continuum tub run in its folder (docs/user-guide.md, its commands)."""

SUMMARY_NAME = "summary.json"
BULK_CSV_NAME = "bulk_velocity.csv"
SHEAR_RATE_CSV_NAME = "shear_rate.csv"
CHECKPOINT_NAME = "checkpoint.npz"
VTK_DIR = "vtk"
