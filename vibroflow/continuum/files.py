"""The files of a continuum tub run in its folder (docs/user-guide.md, its commands)."""

SUMMARY_NAME = "summary.json"
BULK_CSV_NAME = "bulk_velocity.csv"
SHEAR_RATE_CSV_NAME = "shear_rate.csv"
CHECKPOINT_NAME = "checkpoint.npz"
VTK_DIR = "vtk"


def sample_tag(j: int) -> str:
    """The name part of sample j's ParaView files (continuum.paraview): "NNNNN"."""
    return f"{j:05d}"


def early_tag(k: int) -> str:
    """The name part of the ParaView files of the k-th frame before the averaging window:
    "early_NNNNN"."""
    return f"early_{k:05d}"
