"""Rerun recordings of plans: the terrain as a lit, coloured mesh, the paths, start and
goal, the vehicle (its own footprint) animated along the ``time`` timeline, and time
series of speed, wheel torques, currents, power and energy. Saved to ``.rrd`` with a
blueprint (:func:`blueprint`: the 3-D view beside one time-series view per quantity,
named with its unit, every plan in its path's colour: speed, power and energy in sight,
the wheel torques and motor currents in tabs below them); ``rerun FILE.rrd`` opens it on a
desktop. The world is Z-up, right-handed (x east, y north), in metres.

Entities (one set per plan label, e.g. ``time`` and ``energy``)::

    terrain                      Mesh3D with vertex normals, static
    markers/start, markers/goal  Points3D (labelled) and the goal disc's circle, static
    paths/<label>                LineStrips3D, static; paths/<label>/label: Points3D on the path
                                 with the plan's name, time and energy
    vehicle/<label>              Transform3D over time; vehicle/<label>/body Boxes3D (its own size),
                                 vehicle/<label>/arrow LineStrips3D along its heading, above the body and
                                 the markers, sized to the map (:func:`arrow_length`) to find it at a glance
    plots/speed/<label>          Scalars [m/s]
    plots/tau_l/<label>, plots/tau_r/<label>   Scalars [N m]
    plots/i_l/<label>, plots/i_r/<label>       Scalars [A]
    plots/power/<label>          Scalars [W]
    plots/energy/<label>         Scalars [J]
    margins/<label>/drive, margins/<label>/tip   Points3D (labelled: how much) on a stem
                                 (LineStrips3D): where the plan runs closest to the drive's limit
                                 and to tipping over, static

No two always-on labels overlap as the default eye sees them (:func:`labels`).

A receding-horizon run (:func:`write_run`) has the label ``executed`` and the paths of
its plans as ``plans/<k>``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

# the plans' colours: neither is found in the terrain's colour map (greens, browns, white)
COLOURS = {"time": (240, 110, 20), "energy": (130, 50, 210)}
CAMERA_ELEVATION_DEG = 28.0   # the default eye looks down this steeply: low enough to show the relief
ALONG = {"time": 0.35, "energy": 0.65}     # where along its path a plan's label sits (labels apart)
# always-on labels are laid out as the default eye sees them (:func:`place_labels`)
FOV_Y_DEG = 55.0              # the viewer's default vertical field of view
VIEW_PX = 600.0               # a small 3-D view's height [px] (in a taller one, labels lie further apart)
CHAR_PX, LINE_PX = 6.5, 24.0  # a label's width per character and its height [px], its box included (~6 and 20)
LIFTS = 0.3 * np.arange(31)   # [m] the heights above its place a label may be lifted to, in turn
# the time series views in two rows, so that each is tall enough for its y axis to label at
# least two values in a 1280 x 720 window (the viewer labels ticks at powers of ten where they
# are 20 px apart or more: some 210 px of plot for data from 0 to just under a power of ten,
# and three rows left under 170 px there). The top row keeps the trade-off in sight; the
# drive's views share the second, one pair at a time, in tabs (the currents are the torques
# through the motor constant: the same curves).
TOP_ROW = ("speed", "power", "energy")
TABS = (("wheel torques", ("tau_l", "tau_r")), ("motor currents", ("i_l", "i_r")))
ROW_SHARES = (1.0, 1.0)       # the top row and the tabs (whose bar takes some 24 px of theirs)
# the 3-D view's and the plots' shares of the width: at 1280 px, the 3-D view wide enough for
# the whole map from the default eye (some 1.08 times its height, 652 px there) and each
# top-row view for its title with its unit (some 187 px); at 1600 x 900 the map's nearest
# corner reaches a few pixels past the view's left edge
COLUMN_SHARES = (5.0, 4.0)
# (entity, trajectory key, view title: short enough for a third of the plots' width)
SERIES = (("speed", "v", "speed [m/s]"), ("tau_l", "tau_l", "left torque [N m]"),
          ("tau_r", "tau_r", "right torque [N m]"), ("i_l", "i_l", "left current [A]"),
          ("i_r", "i_r", "right current [A]"), ("power", "power_W", "power [W]"),
          ("energy", "energy_J", "energy [J]"))


def display(label: str) -> str:
    """A plan's name in views and legends: 'time-optimal', 'energy-optimal', else the label."""
    return f"{label}-optimal" if label in COLOURS else label


def camera(emap) -> tuple:
    """(eye position, look target) [m] of the default 3-D view: from the map's south-west,
    CAMERA_ELEVATION_DEG above its mean height, far enough to see the whole map."""
    ny, nx = emap.shape
    ox, oy = emap.origin
    w, h = (nx - 1) * emap.resolution, (ny - 1) * emap.resolution
    target = np.array([ox + 0.5 * w, oy + 0.5 * h, float(np.mean(emap.heights))])
    d = 0.9 * float(np.hypot(w, h))
    e = np.radians(CAMERA_ELEVATION_DEG)
    return target + d * np.array([-np.cos(e) * np.sqrt(0.5), -np.cos(e) * np.sqrt(0.5), np.sin(e)]), target


def blueprint(emap=None):
    """The layout: the 3-D scene (terrain, paths, markers, vehicles) beside time-series
    views, one per quantity, titled with its unit, in two rows (:data:`TOP_ROW`: speed,
    power and energy; below, tabs of the wheel torques and the motor currents,
    :data:`TABS`): a view must be about 210 px high for its y axis to label more than 0,
    and three rows are too low for that in a 1280 x 720 window. With a map, the 3-D view's
    eye looks at it from the south-west, low enough to show its relief (:func:`camera`),
    and the time panel, collapsed to its play bar (height for the views), plays from the
    start, looping (the vehicles move at once; a recording otherwise opens at its last
    instant)."""
    import rerun.blueprint as rrb
    title = {name: t for name, _, t in SERIES}

    def row(names, name=None):
        return rrb.Horizontal(*(rrb.TimeSeriesView(origin=f"plots/{n}", name=title[n]) for n in names), name=name)
    plots = rrb.Vertical(row(TOP_ROW), rrb.Tabs(*(row(names, tab) for tab, names in TABS), active_tab=0),
                         row_shares=list(ROW_SHARES))
    eye = None
    if emap is not None:
        pos, target = camera(emap)
        eye = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=pos, look_target=target, eye_up=[0.0, 0.0, 1.0])
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Spatial3DView(origin="/", name="terrain, paths and vehicles", eye_controls=eye),
                       plots, column_shares=list(COLUMN_SHARES)),
        rrb.TimePanel(timeline="time", play_state="playing", loop_mode="all", state="collapsed"),
        collapse_panels=True)


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


def terrain_normals(verts: np.ndarray, shape: tuple) -> np.ndarray:
    """Unit vertex normals (n, 3) of a :func:`terrain_mesh` grid of ``shape`` (rows,
    columns): (-dz/dx, -dz/dy, 1), normalised, from central differences."""
    a, b = shape
    X, Y, Z = (verts[:, k].reshape(a, b) for k in range(3))
    dzdy = np.gradient(Z, Y[:, 0], axis=0) if a > 1 else np.zeros_like(Z)
    dzdx = np.gradient(Z, X[0, :], axis=1) if b > 1 else np.zeros_like(Z)
    n = np.stack([-dzdx, -dzdy, np.ones_like(Z)], axis=-1).reshape(-1, 3)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def body_half_sizes(vehicle) -> tuple:
    """Half sizes [m] of a box around the vehicle: the wheels' extent (contact patches
    plus a wheel radius fore and aft; track plus a patch width across; a wheel diameter
    high). The P3-AT when no vehicle is given."""
    if vehicle is None:
        from dynamics import load_vehicle
        vehicle = load_vehicle("p3at")
    r = vehicle.wheel_radius
    return (vehicle.patch_outer / 2.0 + r, vehicle.width / 2.0 + vehicle.patch_width / 2.0, r)


def arrow_length(emap) -> float:
    """Length [m] of the arrow over each vehicle: 8 % of the map's diagonal, at least 1 m,
    some 60 px at the default camera whatever the map's size (a P3-AT's own box, 0.6 m
    long, is some 10 px on a 36 m map)."""
    ny, nx = emap.shape
    return max(1.0, 0.08 * float(np.hypot(nx - 1, ny - 1)) * emap.resolution)


def heading_arrow(length: float, z: float) -> list:
    """Two strips drawing an arrow ``length`` long [m] along +x, centred on the vehicle,
    ``z`` above it: the shaft and the head's two strokes. (Lines, not Arrows3D, whose tip
    rerun's web viewer drew black once rotated.)"""
    a = 0.5 * length
    head = 0.35 * length
    return [[[-a, 0.0, z], [a, 0.0, z]], [[a - head, -0.6 * head, z], [a, 0.0, z], [a - head, 0.6 * head, z]]]


def project(emap, pts) -> np.ndarray:
    """Pixel positions (n, 2: right, down from the view's centre) of points ``pts`` [m]
    seen from the default eye (:func:`camera`) in a 3-D view VIEW_PX high."""
    pos, target = camera(emap)
    fwd = (target - pos) / np.linalg.norm(target - pos)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    d = np.atleast_2d(np.asarray(pts, float)) - pos
    f = 0.5 * VIEW_PX / np.tan(np.radians(0.5 * FOV_Y_DEG))
    return f * np.c_[d @ right, -(d @ up)] / (d @ fwd)[:, None]


def label_box(emap, p, text: str) -> np.ndarray:
    """(left, top, right, bottom) [px, :func:`project`'s frame] of the label ``text`` of a
    point at ``p`` [m], as the viewer draws it: centred under the point."""
    x, y = project(emap, p)[0]
    w = CHAR_PX * len(text)
    return np.array([x - 0.5 * w, y, x + 0.5 * w, y + LINE_PX])


def place_labels(emap, wanted: list, clear=()) -> list:
    """Positions [m] of always-on labels, ``wanted`` a list of (place [m], text, lifts [m])
    in order of precedence: each is lifted to the first of its lifts at which its box
    (:func:`label_box`) overlaps neither a box placed before it nor one of ``clear`` (boxes
    [px] to keep uncovered), else to the last."""
    boxes, out = list(clear), []
    for p, text, lifts in wanted:
        for h in lifts:
            q = np.asarray(p, float) + [0.0, 0.0, h]
            box = label_box(emap, q, text)
            if not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in boxes):
                break
        boxes.append(box)
        out.append(q)
    return out


def _plan_label(label: str, tr: dict) -> tuple:
    """(place [m], text) of a plan's label: on its path, ALONG[label] of the way (not at the
    strip's centre: a hill's, for two paths round it), 0.35 m up; its name, time and energy."""
    k = min(int(ALONG.get(label, 0.5) * len(tr["x"])), len(tr["x"]) - 1)
    text = display(label) + (f": {tr['t'][-1] - tr['t'][0]:.1f} s, {tr['energy_J'][-1] - tr['energy_J'][0]:.0f} J"
                             if "energy_J" in tr else "")
    return np.array([tr["x"][k], tr["y"][k], tr["z"][k] + 0.35]), text


def _margins(emap, margin: dict | None) -> list:
    """[(what, place on the ground [m], text)] of where a plan runs closest to the limits
    (plan.margin, :mod:`sbmpc.planning.margin`): ``drive``, the least drive headroom held
    0.5 s, and ``tip``, the least tip-over margin; each text says how much, briefly (a wide
    label needs a tall stem to clear the others; the plots show when)."""
    out = []
    for key, what, text in (("drive_headroom", "drive", "headroom {:.0f} %"),
                            ("tip", "tip", "tip margin {:.1f} deg")):
        m = (margin or {}).get(key)
        if m:
            value = 100.0 * m["least"] if key == "drive_headroom" else m["least_deg"]
            out.append((what, np.array([m["x"], m["y"], float(emap.height(m["x"], m["y"]))]),
                        text.format(value)))
    return out


def arrow_box(emap, tr: dict, k: int, vehicle=None) -> np.ndarray:
    """The box [px, :func:`project`'s frame] round a vehicle's arrow at sample ``k``, 10 px wider."""
    a = 0.5 * arrow_length(emap) * np.array([np.cos(tr["yaw"][k]), np.sin(tr["yaw"][k]), 0.0])
    c = np.array([tr["x"][k], tr["y"][k], tr["z"][k] + 2.0 * body_half_sizes(vehicle)[2] + 0.5])
    uv = project(emap, [c - a, c + a])
    return np.r_[uv.min(axis=0) - 10.0, uv.max(axis=0) + 10.0]


def labels(emap, plans: dict, scenario=None, vehicle=None) -> dict:
    """{entity path: (position [m], text)} of the always-on labels of a :func:`write`
    recording: start and goal, each plan's (:func:`_plan_label`), then its margins' (on
    stems, at least LIFTS[2] up), laid out by :func:`place_labels` so that none overlaps
    another, nor a vehicle's arrow where it waits at the start and at the end, as the
    default eye sees them."""
    wanted = {}
    if scenario is not None:
        s, g = scenario.start, scenario.goal
        wanted["markers/start"] = ([s["x"], s["y"], emap.height(s["x"], s["y"]) + 0.15], "start", [0.0])
        wanted["markers/goal"] = ([g["x"], g["y"], emap.height(g["x"], g["y"]) + 0.05], "goal", [0.0])
    found = {label: plan for label, plan in plans.items() if plan.found}
    for label, plan in found.items():
        wanted[f"paths/{label}/label"] = (*_plan_label(label, plan.trajectory), LIFTS)
    for label, plan in found.items():
        for what, place, text in _margins(emap, plan.margin):
            wanted[f"margins/{label}/{what}"] = (place, text, LIFTS[2:])
    clear = [arrow_box(emap, plan.trajectory, k, vehicle) for plan in found.values() for k in (0, -1)]
    at = place_labels(emap, list(wanted.values()), clear)
    return {e: (p, w[1]) for (e, w), p in zip(wanted.items(), at)}


def _log_trajectory(rec, label: str, tr: dict, col, every_s: float, vehicle=None, arrow_m: float = 1.0,
                    label_at=None) -> None:
    """A path (static) and its label (at ``label_at`` [m], else on the path), the vehicle
    (its box, and an arrow ``arrow_m`` long along its heading, above the box and the
    markers) animated along ``time`` and its time series."""
    import rerun as rr
    from scipy.spatial.transform import Rotation
    pts = np.c_[tr["x"], tr["y"], tr["z"] + 0.05]
    rec.log(f"paths/{label}", rr.LineStrips3D([pts], colors=[col], radii=[0.08]), static=True)
    place, text = _plan_label(label, tr)
    place = place if label_at is None else label_at
    rec.log(f"paths/{label}/label", rr.Points3D([place], colors=[col], radii=[0.12], labels=[text], show_labels=True),
            static=True)
    hx, hy, hz = body_half_sizes(vehicle)
    rec.log(f"vehicle/{label}/body", rr.Boxes3D(half_sizes=[[hx, hy, hz]], centers=[[0, 0, hz]],
                                                 colors=[col], fill_mode="solid"), static=True)
    rec.log(f"vehicle/{label}/arrow", rr.LineStrips3D(heading_arrow(arrow_m, 2.0 * hz + 0.5), colors=[col],
                                                       radii=[0.07 * arrow_m]), static=True)
    t = tr["t"] - tr["t"][0]
    step = max(1, int(round(every_s / max(float(np.median(np.diff(t))), 1e-9)))) if len(t) > 1 else 1
    keep = np.unique(np.r_[np.arange(0, len(t), step), len(t) - 1])
    pitch = tr.get("pitch", np.zeros_like(t))
    quats = Rotation.from_euler("ZY", np.c_[tr["yaw"][keep], -pitch[keep]]).as_quat()   # x, y, z, w
    times = rr.TimeColumn("time", duration=t[keep])
    rec.send_columns(f"vehicle/{label}", indexes=[times],
                     columns=rr.Transform3D.columns(translation=np.c_[tr["x"][keep], tr["y"][keep], tr["z"][keep]],
                                                    quaternion=quats))
    for name, key, _ in SERIES:
        if key not in tr:
            continue
        rec.log(f"plots/{name}/{label}", rr.SeriesLines(colors=[col], names=[display(label)], widths=[1.5]),
                static=True)
        rec.send_columns(f"plots/{name}/{label}", indexes=[rr.TimeColumn("time", duration=t)],
                         columns=rr.Scalars.columns(scalars=np.asarray(tr[key], float)))


def _open(path: Path, app: str, emap, scenario=None):
    import rerun as rr
    rec = rr.RecordingStream(app)
    rec.save(str(path), default_blueprint=blueprint(emap))
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    verts, tris, cols = terrain_mesh(emap)
    a = len(np.unique(verts[:, 1]))
    normals = terrain_normals(verts, (a, len(verts) // a))
    rec.log("terrain", rr.Mesh3D(vertex_positions=verts, triangle_indices=tris, vertex_colors=cols,
                                 vertex_normals=normals), static=True)
    if scenario is not None:
        s, g = scenario.start, scenario.goal
        zs = emap.height(s["x"], s["y"])
        rec.log("markers/start", rr.Points3D([[s["x"], s["y"], zs + 0.15]], colors=[(30, 30, 30)], radii=[0.15],
                                             labels=["start"]), static=True)
        ang = np.linspace(0.0, 2.0 * np.pi, 49)
        ring = np.c_[g["x"] + g["radius"] * np.cos(ang), g["y"] + g["radius"] * np.sin(ang)]
        rz = np.array([emap.height(x, y) for x, y in ring]) + 0.05
        rec.log("markers/goal", rr.LineStrips3D([np.c_[ring, rz]], colors=[(20, 20, 20)], radii=[0.04],
                                                labels=["goal"]), static=True)
    return rec


def _close(rec) -> None:
    rec.flush()
    rec.disconnect()


def write(path: Path | str, emap, plans: dict, app: str = "sbmpc", every_s: float = 0.1, scenario=None,
          vehicle=None) -> Path:
    """Write an .rrd of ``plans`` ({label: Plan}) over ``emap`` (with the start and goal
    of ``scenario`` and the box of ``vehicle`` when given); returns the path."""
    path = Path(path)
    rec = _open(path, app, emap, scenario)
    at = labels(emap, plans, scenario, vehicle)
    for label, plan in plans.items():
        if plan.found:
            col = COLOURS.get(label, (60, 110, 220))
            _log_trajectory(rec, label, plan.trajectory, col, every_s, vehicle, arrow_length(emap),
                            at[f"paths/{label}/label"][0])
            _log_margin(rec, label, plan.margin, emap, col, at)
    _close(rec)
    return path


def _log_margin(rec, label: str, margin: dict | None, emap, col, at: dict) -> None:
    """Where a plan runs closest to the limits (:func:`_margins`): ``margins/<label>/drive``
    and ``margins/<label>/tip``, each a labelled point in the plan's colour where
    :func:`labels` put it (``at``), on a stem from the place on the ground."""
    import rerun as rr
    for what, place, _ in _margins(emap, margin):
        top, text = at[f"margins/{label}/{what}"]
        rec.log(f"margins/{label}/{what}", rr.Points3D([top], colors=[col], radii=[0.15], labels=[text],
                                                       show_labels=True),
                rr.LineStrips3D([[place, top]], colors=[col], radii=[0.03]), static=True)


def write_run(path: Path | str, emap, result, app: str = "sbmpc run", every_s: float = 0.1, scenario=None,
              vehicle=None) -> Path:
    """Write an .rrd of a receding-horizon run (:class:`sbmpc.receding.RunResult`): the
    executed path with the vehicle and its time series under the label ``executed``, and
    every plan of the run as a static path ``plans/<k>`` (0 the first plan) with its
    start marked at ``plans/<k>/start``."""
    import rerun as rr
    path = Path(path)
    rec = _open(path, app, emap, scenario)
    for k, rp in enumerate(result.plans):
        if not rp.plan.found or not rp.plan.trajectory:     # (a horizon plan keeps no trajectory)
            continue
        tr = rp.plan.trajectory
        col = (150, 150, 230) if k else (60, 110, 220)
        rec.log(f"plans/{k}", rr.LineStrips3D([np.c_[tr["x"], tr["y"], tr["z"] + 0.04]], colors=[col], radii=[0.03]),
                static=True)
        rec.log(f"plans/{k}/start", rr.Points3D([[tr["x"][0], tr["y"][0], tr["z"][0] + 0.1]], colors=[col],
                                                radii=[0.08], labels=[rp.why]), static=True)
    if len(result.trajectory.get("t", ())) > 1:
        _log_trajectory(rec, "executed", result.trajectory, (220, 50, 50), every_s, vehicle, arrow_length(emap))
    _close(rec)
    return path


def entities(path: Path | str) -> dict:
    """{entity path: rows} of an .rrd file (used by the tests to read a recording back)."""
    from rerun.chunk import RrdReader
    out: dict = {}
    for c in RrdReader(str(path)).stream().to_chunks():
        out[str(c.entity_path)] = out.get(str(c.entity_path), 0) + int(c.num_rows)
    return out
