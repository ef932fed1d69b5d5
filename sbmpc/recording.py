"""Rerun recordings of plans: the terrain as a coloured mesh, the paths, the vehicle's pose
animated along the ``time`` timeline, and time series of speed, wheel torques, power and
energy. Saved to ``.rrd``; ``rerun FILE.rrd`` opens it on a desktop.

Entities (one set per plan label, e.g. ``time`` and ``energy``)::

    terrain                      Mesh3D, static
    paths/<label>                LineStrips3D, static
    vehicle/<label>              Transform3D over time; vehicle/<label>/body Boxes3D
    plots/speed/<label>          Scalars [m/s]
    plots/tau_l/<label>, plots/tau_r/<label>   Scalars [N m]
    plots/power/<label>          Scalars [W]
    plots/energy/<label>         Scalars [J]
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

COLOURS = {"time": (230, 120, 30), "energy": (40, 170, 80)}
SERIES = (("speed", "v"), ("tau_l", "tau_l"), ("tau_r", "tau_r"), ("power", "power_W"), ("energy", "energy_J"))


def terrain_mesh(emap, max_side: int = 160):
    """Vertices (n, 3), triangles (m, 3) and RGB colours (n, 3) of a map, subsampled so
    that neither side has more than ``max_side`` vertices."""
    from matplotlib import colormaps
    H = emap.heights
    ny, nx = H.shape
    sy = max(1, int(np.ceil(ny / max_side)))
    sx = max(1, int(np.ceil(nx / max_side)))
    js = np.r_[np.arange(0, ny, sy), ny - 1] if (ny - 1) % sy else np.arange(0, ny, sy)
    is_ = np.r_[np.arange(0, nx, sx), nx - 1] if (nx - 1) % sx else np.arange(0, nx, sx)
    ox, oy = emap.origin
    X, Y = np.meshgrid(ox + is_ * emap.resolution, oy + js * emap.resolution)
    Z = H[np.ix_(js, is_)]
    verts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    a, b = len(js), len(is_)
    idx = np.arange(a * b).reshape(a, b)
    t1 = np.c_[idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel()]
    t2 = np.c_[idx[:-1, :-1].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()]
    span = max(float(np.ptp(Z)), 1e-6)
    rgb = colormaps["terrain"](0.25 + 0.6 * (Z.ravel() - Z.min()) / span)[:, :3]
    if emap.terrain_layer is not None and len(emap.terrain_names) > 1:
        L = emap.terrain_layer[np.ix_(js, is_)].ravel()
        tint = colormaps["Set2"](L % 8)[:, :3]
        rgb = 0.55 * rgb + 0.45 * tint
    return verts, np.vstack([t1, t2]), (255 * rgb).astype(np.uint8)


def write(path: Path | str, emap, plans: dict, app: str = "sbmpc", every_s: float = 0.1) -> Path:
    """Write an .rrd of ``plans`` ({label: Plan}) over ``emap``; returns the path."""
    import rerun as rr
    from scipy.spatial.transform import Rotation

    path = Path(path)
    rec = rr.RecordingStream(app)
    rec.save(str(path))
    verts, tris, cols = terrain_mesh(emap)
    rec.log("terrain", rr.Mesh3D(vertex_positions=verts, triangle_indices=tris, vertex_colors=cols), static=True)
    for label, plan in plans.items():
        if not plan.found:
            continue
        tr = plan.trajectory
        col = COLOURS.get(label, (60, 110, 220))
        pts = np.c_[tr["x"], tr["y"], tr["z"] + 0.05]
        rec.log(f"paths/{label}", rr.LineStrips3D([pts], colors=[col], radii=[0.06]), static=True)
        rec.log(f"vehicle/{label}/body", rr.Boxes3D(half_sizes=[[0.26, 0.25, 0.12]], centers=[[0, 0, 0.15]],
                                                     colors=[col]), static=True)
        t = tr["t"] - tr["t"][0]
        step = max(1, int(round(every_s / max(float(np.median(np.diff(t))), 1e-9)))) if len(t) > 1 else 1
        keep = np.unique(np.r_[np.arange(0, len(t), step), len(t) - 1])
        pitch = tr.get("pitch", np.zeros_like(t))
        quats = Rotation.from_euler("ZY", np.c_[tr["yaw"][keep], -pitch[keep]]).as_quat()   # x, y, z, w
        times = rr.TimeColumn("time", duration=t[keep])
        rec.send_columns(f"vehicle/{label}", indexes=[times],
                         columns=rr.Transform3D.columns(translation=np.c_[tr["x"][keep], tr["y"][keep], tr["z"][keep]],
                                                        quaternion=quats))
        for name, key in SERIES:
            rec.send_columns(f"plots/{name}/{label}", indexes=[rr.TimeColumn("time", duration=t)],
                             columns=rr.Scalars.columns(scalars=np.asarray(tr[key], float)))
    rec.flush()
    rec.disconnect()
    return path


def entities(path: Path | str) -> dict:
    """{entity path: rows} of an .rrd file (used by the tests to read a recording back)."""
    from rerun.chunk import RrdReader
    out: dict = {}
    for c in RrdReader(str(path)).stream().to_chunks():
        out[str(c.entity_path)] = out.get(str(c.entity_path), 0) + int(c.num_rows)
    return out
