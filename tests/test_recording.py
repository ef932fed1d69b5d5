"""Rerun recordings made for this job: Z-up, lit terrain, start and goal, the vehicle's
own box, named series in the paths' colours, and a blueprint laying them out."""
import shutil
import subprocess

import numpy as np
import pytest

from dynamics import load_vehicle
from maps import ElevationMap
from sbmpc import recording


def test_terrain_normals_are_unit_and_tilt_against_the_slope():
    H = np.fromfunction(lambda j, i: 0.5 * i * 0.25, (9, 13))          # z = 0.5 x: 26.6 deg up to the east
    verts, tris, cols = recording.terrain_mesh(ElevationMap(H, 0.25, (0.0, 0.0)))
    n = recording.terrain_normals(verts, (9, 13))
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert np.allclose(n, np.array([-0.5, 0.0, 1.0]) / np.sqrt(1.25))


def test_the_vehicle_box_is_the_vehicles_own():
    p3, wh = (recording.body_half_sizes(load_vehicle(n)) for n in ("p3at", "warthog"))
    v = load_vehicle("p3at")
    assert p3 == pytest.approx((v.patch_outer / 2 + v.wheel_radius, v.width / 2 + v.patch_width / 2, v.wheel_radius))
    assert all(w > p for w, p in zip(wh, p3))                           # the Warthog is larger


def test_a_plan_recording_has_markers_series_and_a_blueprint(tmp_path):
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL, world as WO
    from pathlib import Path
    w = WO.resolve(SC.load(Path(__file__).resolve().parents[1] / "scenarios" / "flat.yaml"))
    plan = PL.plan(w, "time")
    path = recording.write(tmp_path / "p.rrd", w.emap, {"time": plan}, scenario=w.scenario, vehicle=w.vehicle)
    ents = recording.entities(path)
    for e in ("/markers/start", "/markers/goal", "/plots/i_l/time", "/plots/i_r/time", "/plots/speed/time"):
        assert e in ents, e
    if shutil.which("rerun"):
        out = subprocess.run(["rerun", "rrd", "print", str(path)], capture_output=True, text=True, timeout=120).stdout
        assert "Blueprint" in out


def test_the_default_view_tells_the_story(tmp_path):
    """What a new user saw in hill_tradeoff's compare.rrd: a green energy path lost on
    the green terrain, labels at the hill's centre, series named 'time'/'energy', a
    faint box, a camera from which the hill looked flat. Now: both plan colours are far
    (RGB distance > 100) from every colour the terrain takes; each label sits on its own
    path and names the plan; the camera looks down 28 deg at the map's centre from the
    south-west, from far enough to see it all."""
    from matplotlib import colormaps
    from pathlib import Path
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL, world as WO
    ground = 255 * colormaps["terrain"](np.linspace(0.25, 0.85, 200))[:, :3]
    for label, col in recording.COLOURS.items():
        assert np.min(np.linalg.norm(ground - np.array(col), axis=1)) > 100, label
    w = WO.resolve(SC.load(Path(__file__).resolve().parents[1] / "scenarios" / "hill_tradeoff.yaml"))
    pos, target = recording.camera(w.emap)
    d = pos - target
    assert np.degrees(np.arctan2(d[2], np.hypot(d[0], d[1]))) == pytest.approx(recording.CAMERA_ELEVATION_DEG)
    assert d[0] < 0 and d[1] < 0
    ny, nx = w.emap.shape
    assert np.linalg.norm(d) >= 0.9 * np.hypot(nx - 1, ny - 1) * w.emap.resolution - 1e-9
    plans = {c: PL.plan(w, c) for c in ("time",)}
    path = recording.write(tmp_path / "c.rrd", w.emap, plans, scenario=w.scenario, vehicle=w.vehicle)
    ents = recording.entities(path)
    assert "/paths/time/label" in ents
    from rerun.chunk import RrdReader
    tr = plans["time"].trajectory
    for c in RrdReader(str(path)).stream().to_chunks():
        if str(c.entity_path) == "/paths/time/label":
            rb = c.to_record_batch()
            label = rb.column(rb.schema.names.index("Points3D:labels")).to_pylist()[0][0]
            xyz = rb.column(rb.schema.names.index("Points3D:positions")).to_pylist()[0][0]
    assert label == f"time-optimal: {tr['t'][-1]:.1f} s, {tr['energy_J'][-1]:.0f} J"
    # on its path: within a few centimetres of a trajectory sample, 0.3 m above it
    gap = np.hypot(np.asarray(tr["x"]) - xyz[0], np.asarray(tr["y"]) - xyz[1])
    assert gap.min() < 1e-4


# --- the second pass (issue 63 item 5): what a user saw in rerun's web viewer -------------

@pytest.fixture(scope="module")
def tradeoff(tmp_path_factory):
    """hill_tradeoff's world, its time- and energy-optimal plans, and their recording."""
    from pathlib import Path
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL, world as WO
    w = WO.resolve(SC.load(Path(__file__).resolve().parents[1] / "scenarios" / "hill_tradeoff.yaml"))
    plans = {c: PL.plan(w, c) for c in ("time", "energy")}
    path = recording.write(tmp_path_factory.mktemp("rec") / "c.rrd", w.emap, plans, scenario=w.scenario,
                           vehicle=w.vehicle)
    return w, plans, path


def _read(path) -> dict:
    """{entity path: {component: first row's value}} of an .rrd's static entities."""
    from rerun.chunk import RrdReader
    out: dict = {}
    for c in RrdReader(str(path)).stream().to_chunks():
        rb = c.to_record_batch()
        for name in rb.schema.names:
            if ":" in name:
                out.setdefault(str(c.entity_path), {})[name] = rb.column(rb.schema.names.index(name)).to_pylist()[0]
    return out


def _shown_labels(path) -> list:
    """[(entity, anchor [m], text)] of every label the viewer shows without being asked: a
    point's under the point, a strip's (the goal) under its centre."""
    out = []
    for e, comps in _read(path).items():
        for arch, anchor in (("Points3D", lambda v: v[0]), ("LineStrips3D", lambda v: np.mean(v[0], axis=0))):
            if comps.get(f"{arch}:labels") and comps.get(f"{arch}:show_labels", [True]) != [False]:
                key = f"{arch}:positions" if arch == "Points3D" else f"{arch}:strips"
                out.append((e, np.asarray(anchor(comps[key]), float), comps[f"{arch}:labels"][0]))
    return out


def test_no_two_labels_overlap_at_the_default_eye(tradeoff):
    """Before: both plans' 'least drive headroom 0 %' labels at one point by the start, and
    the time-optimal plan's label under its tip-over margin's. Now every label shown
    always, boxed as the viewer draws it (centred under its point, 6.5 px a character,
    24 px high, seen from the default eye in a 600 px high view: the eye's 55 deg field
    of view put start and goal within 2 px of where a 1600x900 screenshot shows them),
    overlaps none of the others nor the vehicles' arrows at the start; and no two are
    within 0.5 m of each other."""
    w, plans, path = tradeoff
    shown = _shown_labels(path)
    names = {e for e, _, _ in shown}
    assert {"/markers/start", "/markers/goal", "/paths/time/label", "/paths/energy/label",
            "/margins/time/drive", "/margins/energy/drive", "/margins/time/tip", "/margins/energy/tip"} <= names
    boxes = {e: recording.label_box(w.emap, p, text) for e, p, text in shown}
    arrows = [recording.arrow_box(w.emap, plans[c].trajectory, 0, w.vehicle) for c in plans]

    def apart(a, b):
        return a[2] <= b[0] or b[2] <= a[0] or a[3] <= b[1] or b[3] <= a[1]
    for i, (e, p, _) in enumerate(shown):
        for f, q, _ in shown[i + 1:]:
            assert apart(boxes[e], boxes[f]) and np.linalg.norm(p - q) > 0.5, (e, f)
        if e not in ("/markers/start", "/markers/goal"):            # (those are where they are)
            assert all(apart(boxes[e], a) for a in arrows), e
    # each margin's marker stands on a stem from where it is
    for c, plan in plans.items():
        for what, key in (("drive", "drive_headroom"), ("tip", "tip")):
            comps = _read(path)[f"/margins/{c}/{what}"]
            (ground, top), = [np.asarray(s) for s in comps["LineStrips3D:strips"]]
            assert ground[:2] == pytest.approx([plan.margin[key]["x"], plan.margin[key]["y"]], abs=1e-3)
            assert top == pytest.approx(comps["Points3D:positions"][0]) and top[2] > ground[2] + 0.5


def test_the_vehicles_show_at_a_glance(tradeoff):
    """Before: each vehicle only its own box, some 10 px long at the default eye and under
    the start marker. Now its box (still its own size) carries an arrow along its heading
    at least 1 m and 6 % of the map's diagonal long, at least 50 px at the default eye
    (600 px high view), a tenth as thick as long, above the box and the start marker's top."""
    w, plans, path = tradeoff
    comps = _read(path)
    ny, nx = w.emap.shape
    diag = np.hypot(nx - 1, ny - 1) * w.emap.resolution
    hx, hy, hz = recording.body_half_sizes(w.vehicle)
    for c, plan in plans.items():
        assert comps[f"/vehicle/{c}/body"]["Boxes3D:half_sizes"][0] == pytest.approx([hx, hy, hz])
        shaft = np.asarray(comps[f"/vehicle/{c}/arrow"]["LineStrips3D:strips"][0])
        length = np.linalg.norm(shaft[1] - shaft[0])
        assert length >= max(1.0, 0.06 * diag) and shaft[1][0] > shaft[0][0]          # along the heading, +x
        assert 2 * comps[f"/vehicle/{c}/arrow"]["LineStrips3D:radii"][0] >= 0.1 * length
        assert shaft[0][2] >= 2 * hz + 0.3                                           # above the box
        tr = plan.trajectory
        c0 = np.array([tr["x"][0], tr["y"][0], tr["z"][0]])
        start_top = comps["/markers/start"]["Points3D:positions"][0][2] + comps["/markers/start"]["Points3D:radii"][0]
        assert c0[2] + shaft[0][2] > start_top
        uv = recording.project(w.emap, [c0 + shaft[0], c0 + shaft[1]])
        assert np.linalg.norm(uv[1] - uv[0]) >= 50.0


def _labelled_y_ticks(lo: float, hi: float, height_px: float) -> int:
    """How many y-axis labels a time-series view of ``height_px`` shows for data from lo to
    hi: its ticks are at powers of ten, labelled where at least 20 px apart; the range
    shows 5 % beyond the data at either end."""
    span = 1.1 * max(hi - lo, 1e-9)
    step = 10.0 ** (np.floor(np.log10(span)) - 3)
    while step * height_px / span < 20.0:
        step *= 10.0
    return int(np.floor((hi + 0.05 * span) / step) - np.ceil((lo - 0.05 * span) / step) + 1)


# the viewer's frame, measured on screenshots of rerun's web viewer (0.41) at 1280 x 720 and
# 1600 x 900: its top bar, the time panel collapsed to its play bar, a view's title bar, the
# time axis under a plot, a tab bar; a view's title with its unit shows whole where the view
# is some 110 px (icons) and 7 px a character wide ('speed [m/s]' at 187 px, not at 185)
WINDOWS = ((1280, 720), (1600, 900))
TOP_BAR, TIME_BAR, TITLE_BAR, TIME_AXIS, TAB_BAR = 36.0, 30.0, 24.0, 31.0, 24.0


def _title_px(title: str) -> float:
    return 110.0 + 7.0 * len(title)


def _layout(bp, width: float, height: float) -> dict:
    """{view: (width, height) [px]} of every view of blueprint ``bp`` in a browser window
    ``width`` x ``height``, its containers sharing their space by their shares (a tab's
    content under the tab bar; every tab counted, one shows at a time)."""
    import rerun.blueprint as rrb
    panel = {"collapsed": TIME_BAR, "expanded": 250.0, "hidden": 0.0}[str(bp.time_panel.state).lower()]
    out = {}

    def split(total, n, shares):
        shares = np.ones(n) if shares is None else np.asarray(shares, float)
        return total * shares / shares.sum()

    def walk(node, w, h):
        if isinstance(node, rrb.Horizontal):
            for child, cw in zip(node.contents, split(w, len(node.contents), node.column_shares)):
                walk(child, cw, h)
        elif isinstance(node, rrb.Vertical):
            for child, ch in zip(node.contents, split(h, len(node.contents), node.row_shares)):
                walk(child, w, ch)
        elif isinstance(node, rrb.Grid):
            cols = node.grid_columns or int(np.ceil(np.sqrt(len(node.contents))))
            rows = -(-len(node.contents) // cols)
            for child in node.contents:
                walk(child, w / cols, h / rows)
        elif isinstance(node, rrb.Tabs):
            for child in node.contents:
                walk(child, w, h - TAB_BAR)
        else:
            out[node] = (w, h)
    walk(bp.root_container, float(width), height - TOP_BAR - panel)
    return out


def test_every_plot_labels_its_y_axis(tradeoff):
    """Before: in a 1280 x 720 window 'energy used' (and speed) showed only one value on its
    y axis: seven views in three rows were some 165 px of plot each, too little for ticks
    20 px apart over 0..1 m/s or 0..950 J. Now each time-series view, in the size the
    blueprint gives it in a 1280 x 720 and in a 1600 x 900 window (views in two rows: speed,
    power and energy above, the torques and the currents in tabs below), labels at least two
    values of every series it shows; power and energy are logged in W and J, numbers
    between 0.1 and 10000."""
    import rerun.blueprint as rrb
    w, plans, path = tradeoff
    bp = recording.blueprint(w.emap)
    from rerun.chunk import RrdReader
    values: dict = {}
    for ch in RrdReader(str(path)).stream().to_chunks():
        rb = ch.to_record_batch()
        if "Scalars:scalars" in rb.schema.names:
            v = np.asarray(rb.column(rb.schema.names.index("Scalars:scalars")).to_pylist(), float).ravel()
            values[str(ch.entity_path)] = np.r_[values.get(str(ch.entity_path), []), v]
    for size in WINDOWS:
        views = {str(v.origin): h - TITLE_BAR - TIME_AXIS for v, (_, h) in _layout(bp, *size).items()
                 if isinstance(v, rrb.TimeSeriesView)}
        assert {f"plots/{name}" for name, _, _ in recording.SERIES} == set(views)
        for origin, h in views.items():
            v = np.concatenate([values[f"/{origin}/{c}"] for c in plans])
            assert _labelled_y_ticks(v.min(), v.max(), h) >= 2, (size, origin, h)
            if origin in ("plots/power", "plots/energy"):
                assert 0.1 <= np.abs(v).max() <= 1e4


def test_the_layout_reads_at_a_glance_at_1280(tradeoff):
    """Before: at 1280 x 720 the top row's titles lost their units ('speed >'). Now speed,
    power and energy are in sight together, outside any tab; every view is wide enough for
    its title with its unit at 1280 px; and the 3-D view holds the whole map as the default
    eye sees it (its corners projected, :func:`recording.project`, scaled to the view's
    height) at 1280 x 720, and at 1600 x 900 all but the tip of its nearest corner (empty
    ground, 12 px at most past the view's edge: the price of the titles at 1280 px)."""
    import rerun.blueprint as rrb
    w, plans, path = tradeoff
    bp = recording.blueprint(w.emap)

    def tabbed(node, inside=False):
        if isinstance(node, (rrb.Horizontal, rrb.Vertical, rrb.Grid, rrb.Tabs)):
            return set().union(*(tabbed(c, inside or isinstance(node, rrb.Tabs)) for c in node.contents))
        return {str(node.origin)} if inside else set()
    assert not {"plots/speed", "plots/power", "plots/energy"} & tabbed(bp.root_container)
    e = w.emap
    ny, nx = e.shape
    (ox, oy), r = e.origin, e.resolution
    corners = [[x, y, float(e.height(x, y))] for x in (ox, ox + (nx - 1) * r) for y in (oy, oy + (ny - 1) * r)]
    half = np.abs(recording.project(e, corners)[:, 0]).max() / recording.VIEW_PX     # of the drawn height
    for size, past in zip(WINDOWS, (0.0, 12.0)):
        layout = _layout(bp, *size)
        if size[0] == 1280:
            for v, (vw, _) in layout.items():
                if isinstance(v, rrb.TimeSeriesView):
                    assert vw >= _title_px(str(v.name)), (str(v.name), vw)
        (vw, vh), = [s for v, s in layout.items() if isinstance(v, rrb.Spatial3DView)]
        assert half * (vh - TITLE_BAR) - 0.5 * vw <= past, (size, vw)
