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
