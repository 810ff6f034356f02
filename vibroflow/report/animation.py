"""An animated GIF of the DEM's mid-length slice over the last few vibration cycles.

Frames are the DEM's snapshots (dem.h5, `run.phases_per_cycle` a cycle, so a movie of a few
cycles shows both the bed's oscillation within a cycle and the slow roll from one cycle to the
next).  Each frame draws the balls whose centre lies within `half_thickness` of the tub's
mid-length plane y = L/2, as circles of their true size in the TUB frame (x across, z up from the
bottom of the U: the U outline stays put and the balls move relative to it), coloured by their
speed relative to the tub (vibroflow.calibration.dem_result.DEMResult gives positions and
velocities in that frame).  The GIF is written with Pillow to a temporary name in the target
folder and moved into place, so a reader never sees a partial file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.collections import EllipseCollection
from matplotlib.colors import Normalize
from PIL import Image

from vibroflow.calibration.dem_result import DEMResult
from vibroflow.io.atomic import atomic_path
from vibroflow.io.pictures import pyplot
from vibroflow.tub.geometry import geometry_of

#: frames at most (the last snapshots of the run), and the frame duration (ms)
MAX_FRAMES = 48
FRAME_MS = 90
COLORS = 48      # GIF palette size: enough for the colour scale, keeps the file small
WIDTH_IN = 4.6   # figure width (inches) at DPI: ~ 410 px
DPI = 90


def slice_frames(run_dir, max_frames: int = MAX_FRAMES, half_thickness: float | None = None):
    """The frames' data: (frames, geometry, diameter (m), slab half-thickness (m)) with frames
    a list of dicts {time (s), x, z (m, tub frame), radius (m), speed (m/s, relative to the
    tub)} of the slab's balls, for the last `max_frames` snapshots.  half_thickness (m) defaults
    to 1.5 ball diameters (a slab three balls thick), at most half the tub's length."""
    with DEMResult.open(run_dir) as res:
        geo = geometry_of(res.scenario)
        d = res.diameter
        ht = 1.5 * d if half_thickness is None else float(half_thickness)
        ht = min(ht, 0.5 * geo.length) if geo.length > 0 else ht
        n = res.times.size
        idx = np.arange(max(0, n - max_frames), n)
        radius = res.radius
        frames = []
        for _, snap in res.iter_snapshots(idx, contacts=False):
            p = snap["positions_tub"]
            v = snap["velocities_rel_tub"]
            sel = np.abs(p[:, 1] - 0.5 * geo.length) < ht
            frames.append({"time": snap["time"], "x": p[sel, 0], "z": p[sel, 2],
                           "radius": radius[sel], "speed": np.linalg.norm(v[sel], axis=1)})
    return frames, geo, d, ht


def write_slice_gif(run_dir, path, max_frames: int = MAX_FRAMES,
                    half_thickness: float | None = None) -> Path:
    """Write the animation of the DEM run in run_dir (a folder with dem.h5) to `path`; returns
    the path.  Frame count: min(max_frames, snapshots); ~ 410 px wide."""
    frames, geo, d, ht = slice_frames(run_dir, max_frames, half_thickness)
    if not frames:
        raise ValueError(f"{run_dir}: the DEM result holds no snapshots")
    speeds = np.concatenate([f["speed"] for f in frames])
    vmax = float(np.percentile(speeds, 99)) if speeds.size else 1.0
    norm = Normalize(0.0, vmax if vmax > 0 else 1.0)
    ztop = max((float((f["z"] + f["radius"]).max()) for f in frames if f["z"].size),
               default=geo.rim_height)
    ztop = min(geo.rim_height, ztop + 2.0 * d)
    R = geo.radius
    aspect = (ztop + 0.05 * R) / (2.1 * R)
    plt = pyplot()
    fig = plt.figure(figsize=(WIDTH_IN, WIDTH_IN * aspect * 0.86 + 0.6), dpi=DPI)
    ax = fig.add_axes([0.02, 0.02, 0.80, 0.86])
    cax = fig.add_axes([0.85, 0.1, 0.035, 0.7])
    prof = geo.profile(300)
    ax.plot(prof[:, 0], prof[:, 1], "k-", lw=1.2)
    ax.set_xlim(-1.05 * R, 1.05 * R)
    ax.set_ylim(-0.05 * R, ztop)
    ax.set_aspect("equal")
    ax.set_axis_off()
    sm = plt.cm.ScalarMappable(norm=norm, cmap="viridis")
    fig.colorbar(sm, cax=cax, label="|v - v_tub| (m/s)")
    title = fig.suptitle("", fontsize=9)
    images = []
    coll = None
    for f in frames:
        if coll is not None:
            coll.remove()
        coll = EllipseCollection(2 * f["radius"], 2 * f["radius"], np.zeros(f["x"].size),
                                 units="xy", offsets=np.column_stack([f["x"], f["z"]]),
                                 offset_transform=ax.transData, cmap="viridis", norm=norm,
                                 edgecolors="k", linewidths=0.2)
        coll.set_array(f["speed"])
        ax.add_collection(coll)
        title.set_text(f"DEM slice |y - L/2| < {1e3 * ht:.1f} mm, "
                       f"tub frame, t = {f['time']:.4f} s")
        fig.canvas.draw()
        rgba = np.asarray(fig.canvas.buffer_rgba())
        # no dithering: flat colours compress several times better in the GIF's LZW
        images.append(Image.fromarray(rgba[..., :3].copy()).quantize(
            colors=COLORS, dither=Image.Dither.NONE))
    plt.close(fig)
    path = Path(path)
    with atomic_path(path) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                       duration=FRAME_MS, loop=0, disposal=1)
    return path
