"""``sbmpc protocol``: a calibration drive sized to the robot and the free area, and
``sbmpc simulate --commands --run`` on it (sbmpc.protocol)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynamics.limits import top_speed
from dynamics.params import load_terrain, load_vehicle
from dynamics.runs import read_run
from sbmpc.calibration import PARAMS
from sbmpc.commands.cli import main
from sbmpc.protocol import TOP_OVER, ProtocolError, read_commands, sized


@pytest.mark.parametrize("vehicle, terrain, area", [("p3at", "vinyl", (6.0, 4.0)), ("husky", "asphalt", (10.0, 6.0)),
                                                    ("warthog", "asphalt", (25.0, 15.0))])
def test_the_drive_stays_in_its_area_and_excites_every_parameter(vehicle, terrain, area):
    """Simulated with the closed-loop model, the drive keeps the footprint inside the area
    and ends near its start; its training part (the first 70 %) has every manoeuvre
    calibrate needs (both turn directions, straights, accelerations, >= 3 s at the top
    speed for a robot without load channels); the commands stay within the drive's top
    wheel speed (the top-speed part TOP_OVER beyond it)."""
    v, t = load_vehicle(vehicle), load_terrain(terrain)
    proto, check = sized(v, t, area)
    assert check.inside
    x0, x1, y0, y1 = check.box
    a, b = check.reach
    assert -a <= x0 and x1 <= a and -b <= y0 and y1 <= b
    assert check.end_m < 0.1 * min(area)
    assert all(ok is True for ok in check.chosen.values()), check.chosen
    for part in (check.training, check.heldout):
        assert part["left_turns_s"] >= 3.0 and part["right_turns_s"] >= 3.0
        assert part["straight_s"] >= 3.0 and part["accelerations_s"] >= 3.0
    kinds = {p.kind for p in proto.parts}
    assert kinds >= {"pause", "straight", "turn", "pivot"}
    turns = [p for p in proto.parts if p.kind == "turn"]
    assert any(p.omega * p.v > 0 for p in turns) and any(p.omega * p.v < 0 for p in turns)
    w_top = top_speed(v, t) / v.wheel_radius
    for p in proto.parts:
        wl, wr = p.wheels(v)
        assert max(abs(wl), abs(wr)) <= TOP_OVER * w_top * (1 + 1e-9), p
        assert set(p.identifies) <= set(PARAMS)


@settings(max_examples=12, deadline=None)
@given(w=st.floats(2.0, 30.0), h=st.floats(1.0, 30.0), name=st.sampled_from(["p3at", "husky"]))
def test_any_area_gets_a_drive_inside_it_or_one_clear_refusal(w, h, name):
    """Over random areas: either a protocol whose simulated path stays inside (after its
    parts are shrunk) with both turn directions, or a ProtocolError naming the area."""
    v, t = load_vehicle(name), load_terrain("asphalt")
    try:
        proto, check = sized(v, t, (w, h))
    except ProtocolError as exc:
        assert str(exc).startswith("area: expected at least")
        return
    assert check.inside, (check.box, check.reach)
    assert proto.seconds >= 20.0


def test_the_cli_writes_commands_that_simulate_into_a_run_calibrate_reads(tmp_path, capsys):
    """protocol -> commands CSV -> simulate --commands --run: the run logs the protocol's
    wheel commands (held between the 20 Hz rows), at 100 Hz, with what calibrate needs."""
    out = tmp_path / "commands.csv"
    assert main(["protocol", "--vehicle", "p3at", "--terrain", "vinyl", "--area", "6,4", "--out", str(out),
                 "--duration", "120", "--json", str(tmp_path / "p.json")]) == 0
    text = capsys.readouterr().out
    assert "with wheel speeds only: fitted torque_constant" in text and "pivot" in text
    t, wl, wr, meta = read_commands(out)
    assert meta["schema"] == "sbmpc.protocol/1" and meta["vehicle"] == "p3at"
    assert np.allclose(np.diff(t), 0.05)
    doc = json.loads((tmp_path / "p.json").read_text())
    assert math.isclose(doc["seconds"], t[-1] + 0.05, abs_tol=0.06)
    run_path = tmp_path / "drive.csv"
    assert main(["simulate", "--vehicle", "p3at", "--terrain", "vinyl", "--commands", str(out),
                 "--run", str(run_path)]) == 0
    run = read_run(run_path)
    assert run.meta["vehicle"] == "p3at"
    k = np.searchsorted(t, run.t[::50] + 1e-9, side="right") - 1
    assert np.allclose(run["wl_cmd"][::50], wl[k]) and np.allclose(run["wr_cmd"][::50], wr[k])
    assert {"tau_l", "i_r", "x", "yaw"} <= set(run.columns)


def test_bad_input_gets_one_line(tmp_path, capsys):
    cases = [(["--area", "1,1"], "--area: area: expected at least"),
             (["--area", "6"], "--area: expected W,H"),
             (["--area", "6,4", "--duration", "-1"], "--duration: expected seconds"),
             (["--area", "6,4", "--vehicle", "nosuch"], "nosuch")]
    for extra, want in cases:
        args = ["protocol", "--vehicle", "p3at", "--out", str(tmp_path / "c.csv")] + extra
        assert main(args) == 2, extra
        err = capsys.readouterr().err.strip()
        assert want in err and "\n" not in err, (extra, err)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,wl_cmd,wr_cmd\n0,1,1\n0.05,1,1\n0.04,1,1\n")
    assert main(["simulate", "--commands", str(bad), "--run", str(tmp_path / "r.csv")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv line 4: expected finite numbers and t increasing" in err
    assert not (tmp_path / "r.csv").exists()
    missing = tmp_path / "missing.csv"
    missing.write_text("t,left\n0,1\n")
    assert main(["simulate", "--commands", str(missing)]) == 2
    assert "line 1: expected the columns t, wl_cmd, wr_cmd, found no 'wl_cmd'" in capsys.readouterr().err
    assert main(["simulate", "--v", "0.5", "--noise", "3"]) == 2
    assert "--noise: expected with --run" in capsys.readouterr().err


def test_the_bag_plays_the_twists_the_driver_turns_into_the_protocols_wheel_speeds(tmp_path, capsys):
    """The bag's /cmd_vel, turned into wheel speeds with the vehicle's command track (the
    Husky's diff_drive_controller's), gives the protocol's wheel commands."""
    pytest.importorskip("rosbags")
    from rosbags.typesys import Stores, get_typestore

    from maps.gridmap import any_reader
    out = tmp_path / "drive.bag"
    assert main(["protocol", "--vehicle", "husky", "--area", "10,6", "--out", str(out), "--duration", "120"]) == 0
    capsys.readouterr()
    v = load_vehicle("husky")
    with any_reader(out, get_typestore(Stores.ROS2_HUMBLE)) as reader:
        twists = [(t, reader.deserialize(raw, c.msgtype)) for c, t, raw in
                  reader.messages(connections=[c for c in reader.connections if c.topic == "/cmd_vel"])]
        labels = [reader.deserialize(raw, c.msgtype).data for c, t, raw in
                  reader.messages(connections=[c for c in reader.connections if c.topic == "/sbmpc/protocol"])]
    ts = np.array([t for t, _ in twists]) * 1e-9
    assert np.allclose(np.diff(ts), 0.05)
    vs = np.array([m.linear.x for _, m in twists])
    om = np.array([m.angular.z for _, m in twists])
    S, r = v.command_track, v.wheel_radius
    wl, wr = (vs - om * S / 2) / r, (vs + om * S / 2) / r
    assert np.max(np.abs(wr - wl)) > 1.0 and np.min(vs) < 0 < np.max(vs)
    assert any("identifies mu_sa, mu_op" in s for s in labels)


@pytest.mark.slow
def test_a_calibration_on_the_simulated_protocol_recovers_the_shipped_vehicle(tmp_path, capsys):
    """The protocol for a P3-AT in 6 x 4 m, driven by the shipped P3-AT (simulate
    --commands, sensor noise), calibrated from a prior 8-15 % off in mass, torque constant,
    mu_roll, mu_sa and mu_op: every one comes back to the shipped value within two
    standard errors or 1 %."""
    cmd, run = tmp_path / "commands.csv", tmp_path / "drive.csv"
    assert main(["protocol", "--vehicle", "p3at", "--terrain", "vinyl", "--area", "6,4", "--out", str(cmd),
                 "--duration", "150"]) == 0
    assert main(["simulate", "--vehicle", "p3at", "--terrain", "vinyl", "--commands", str(cmd), "--run", str(run),
                 "--noise", "3"]) == 0
    (tmp_path / "off_v.yaml").write_text("base: p3at\nmass: 34.72\ninertia: 0.7504\ntorque_constant: 1.2719\n")
    (tmp_path / "off_t.yaml").write_text("base: vinyl\nmu_roll: 0.0427\nmu_sa: 0.488\nmu_op: 0.2722\n")
    out = tmp_path / "cal"
    assert main(["calibrate", str(run), "--vehicle", str(tmp_path / "off_v.yaml"), "--terrain",
                 str(tmp_path / "off_t.yaml"), "--out", str(out), "--no-diagnose"]) == 0
    capsys.readouterr()
    doc = json.loads((out / "calibration.json").read_text())
    p3at, vinyl = load_vehicle("p3at"), load_terrain("vinyl")
    want = {"mass": p3at.mass, "torque_constant": p3at.torque_constant, "mu_roll": vinyl.mu_roll,
            "mu_sa": vinyl.mu_sa, "mu_op": vinyl.mu_op}
    for name, w in want.items():
        p = doc["params"][name]
        assert p["fitted"], (name, p)
        assert abs(p["value"] - w) <= max(2.0 * p["se"], 0.01 * w), (name, p, w)
