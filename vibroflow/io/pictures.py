"""Pictures as files: matplotlib's pyplot on the Agg backend (no display needed).

pyplot is imported inside `pyplot()`, not at the top: the backend is chosen before pyplot
loads and only when a picture is drawn, so importing vibroflow never changes the backend of a
caller's own plots (a notebook's, say).
"""
from __future__ import annotations


def pyplot():
    """matplotlib.pyplot, on the Agg backend."""
    import matplotlib  # noqa: PLC0415  (see the module's docstring)
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt  # noqa: PLC0415
    return plt
