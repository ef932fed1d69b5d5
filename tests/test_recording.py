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
    from sbmpc import plan as PL, scenario as SC, world as WO
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
