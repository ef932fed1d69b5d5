"""ROS bags in and out (``sbmpc import rosbag``, ``--bag`` on plan, compare and run;
:mod:`sbmpc.rosbag`), on bags written here by ``rosbags``' own writers: ROS 2 sqlite3,
ROS 2 MCAP and ROS 1."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from dynamics.discrepancy import diagnose  # noqa: E402
from dynamics.params import load_terrain, load_vehicle  # noqa: E402
from dynamics.runs import read_run  # noqa: E402
from dynamics.synth import synth_run  # noqa: E402
from sbmpc.commands.cli import main  # noqa: E402

SCN = Path(__file__).resolve().parents[1] / "scenarios"
P3AT = load_vehicle("p3at")
JOINTS = ["front_left_wheel", "rear_left_wheel", "front_right_wheel", "rear_right_wheel"]


def write_robot_bag(path: Path, run, kind: str = "mcap", *, clock_jump: bool = False, topics=None,
                    cmd_type: str = "geometry_msgs/msg/Twist", empty_joints: bool = False) -> None:
    """A bag of a skid-steer robot as its driver writes one: /cmd_vel (Twist) from the
    run's wheel commands, /joint_states with four wheels (two per side, each half the
    side's torque as effort), /odom from the pose, each message stamped with the run's time
    (from t = 100 s)."""
    topics = topics or {}
    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types
    B, r = P3AT.width, P3AT.wheel_radius
    ser = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    if ros1:
        from rosbags.rosbag1 import Writer
        w = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer
        w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3)
    t = run.t + 100.0
    if clock_jump:
        t = t.copy()
        t[len(t) // 2:] -= 5.0

    def stamp(s):
        sec = int(math.floor(s))
        return T["builtin_interfaces/msg/Time"](sec=sec, nanosec=min(int(round((s - sec) * 1e9)), 999_999_999))

    def header(s, frame=""):
        kw = {"seq": 0} if ros1 else {}
        return T["std_msgs/msg/Header"](stamp=stamp(s), frame_id=frame, **kw)
    V3 = T["geometry_msgs/msg/Vector3"]
    with w:
        cc = w.add_connection(topics.get("cmd_vel", "/cmd_vel"), cmd_type, typestore=ts)
        cj = w.add_connection(topics.get("joint_states", "/joint_states"), "sensor_msgs/msg/JointState", typestore=ts)
        co = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
        for k in range(len(t)):
            ns = int(round(t[k] * 1e9)) if not clock_jump else int(round((run.t[k] + 100.0) * 1e9))
            wl, wr = run["wl_cmd"][k], run["wr_cmd"][k]
            tw = T["geometry_msgs/msg/Twist"](linear=V3(x=0.5 * r * (wl + wr), y=0.0, z=0.0),
                                              angular=V3(x=0.0, y=0.0, z=r * (wr - wl) / B))
            msg = tw if cmd_type.endswith("/Twist") else T[cmd_type](header=header(t[k]), twist=tw)
            w.write(cc, ns, ser(msg, cmd_type))
            if not empty_joints:
                vel = np.array([run["wl"][k]] * 2 + [run["wr"][k]] * 2)
                eff = np.array([0.5 * run["tau_l"][k]] * 2 + [0.5 * run["tau_r"][k]] * 2)
                js = T["sensor_msgs/msg/JointState"](header=header(t[k]), name=JOINTS, position=np.zeros(4),
                                                     velocity=vel, effort=eff)
                w.write(cj, ns, ser(js, "sensor_msgs/msg/JointState"))
            yaw = run["yaw"][k]
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=run["x"][k], y=run["y"][k], z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))
            od = T["nav_msgs/msg/Odometry"](
                header=header(t[k], "odom"), child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)))
            w.write(co, ns, ser(od, "nav_msgs/msg/Odometry"))


@pytest.fixture(scope="module")
def short():
    run, _ = synth_run("none", 1, duration=8.0, noise=False)
    return run


@pytest.mark.parametrize("kind", ["mcap", "sqlite3", "ros1"])
def test_a_bag_of_each_kind_imports_to_the_run_it_was_written_from(short, kind, tmp_path, capsys):
    """/cmd_vel's twist back to wheel speeds with the P3-AT's track and radius, the four
    joints averaged per side (efforts summed), the pose from /odom: the run CSV matches the
    run the bag was written from, to the CSV's 6 significant digits."""
    bag = tmp_path / ("robot.bag" if kind == "ros1" else "robot")
    write_robot_bag(bag, short, kind)
    out = tmp_path / "run.csv"
    assert main(["import", "rosbag", str(bag), "--out", str(out), "--vehicle", "p3at", "--terrain", "vinyl"]) == 0
    assert "wrote" in capsys.readouterr().out
    got = read_run(out)
    assert got.meta["vehicle"] == "p3at" and got.meta["terrain"] == "vinyl"
    assert len(got) == len(short)
    np.testing.assert_allclose(got.t, short.t - short.t[0], atol=1e-6)
    for c in ("wl_cmd", "wr_cmd", "wl", "wr", "tau_l", "tau_r", "x", "y", "yaw"):
        np.testing.assert_allclose(got[c], short[c], rtol=2e-5, atol=1e-5, err_msg=c)


@pytest.mark.parametrize("kind", ["mcap", "sqlite3"])
def test_a_ros2_bag_folder_named_like_a_ros1_file_is_read_as_ros2(short, kind, tmp_path):
    """``ros2 bag record -o drive.bag`` makes a folder named drive.bag: rosbags' AnyReader
    takes it for ROS 1 by the suffix ("Is a directory"); a folder is a ROS 2 bag whatever
    its name, and the folder is left as it was."""
    bag = tmp_path / "drive.bag"
    write_robot_bag(bag, short, kind)
    before = sorted(p.name for p in bag.iterdir())
    out = tmp_path / "run.csv"
    assert main(["import", "rosbag", str(bag), "--out", str(out), "--vehicle", "p3at", "--terrain", "vinyl"]) == 0
    np.testing.assert_allclose(read_run(out)["wl"], short["wl"], rtol=2e-5, atol=1e-5)
    assert sorted(p.name for p in bag.iterdir()) == before


def test_a_bag_round_trip_finds_the_hidden_effect_as_the_csv_does(tmp_path):
    """A synthetic run with a smaller left wheel, written as a bag, imported and diagnosed:
    the same cause and parameters as the run itself."""
    run, hidden = synth_run("wheel_radius", 13, duration=60.0)
    bag = tmp_path / "robot"
    write_robot_bag(bag, run, "mcap")
    out = tmp_path / "run.csv"
    assert main(["import", "rosbag", str(bag), "--out", str(out), "--vehicle", "p3at", "--terrain", "vinyl"]) == 0
    vinyl = load_terrain("vinyl")
    a, b = diagnose(run, P3AT, vinyl, effects=("wheel_radius", "viscous_friction")), \
        diagnose(read_run(out), P3AT, vinyl, effects=("wheel_radius", "viscous_friction"))
    assert a.cause == b.cause == "wheel_radius"
    for k, v in a.candidates[0].params.items():
        assert b.candidates[0].params[k] == pytest.approx(v, abs=2e-3)
        assert v == pytest.approx(hidden[k], abs=0.02)


def test_a_topic_map_renames_topics_and_names_the_joints(short, tmp_path):
    bag = tmp_path / "robot"
    write_robot_bag(bag, short, "mcap", topics={"cmd_vel": "/husky_velocity_controller/cmd_vel",
                                                 "joint_states": "/husky/joint_states"},
                    cmd_type="geometry_msgs/msg/TwistStamped")
    m = tmp_path / "map.yaml"
    m.write_text("cmd_vel: /husky_velocity_controller/cmd_vel\njoint_states: /husky/joint_states\n"
                 "left_joints: [front_left_wheel]\nright_joints: [front_right_wheel]\n")
    out = tmp_path / "run.csv"
    assert main(["import", "rosbag", str(bag), "--out", str(out), "--vehicle", "p3at", "--terrain", "vinyl",
                 "--topics", str(m)]) == 0
    np.testing.assert_allclose(read_run(out)["wr_cmd"], short["wr_cmd"], rtol=2e-5, atol=1e-5)


@pytest.mark.parametrize("case, message", [
    ("missing", "expected the topic /cmd_vel (geometry_msgs/msg/Twist or geometry_msgs/msg/TwistStamped) for "
                "cmd_vel, found the topics /joint_states (sensor_msgs/msg/JointState)"),
    ("empty", "topic /joint_states: expected messages, found none"),
    ("jump", "topic /cmd_vel: expected time stamps that never go back, found a jump"),
    ("truncated", "expected a ROS 2 bag folder (sqlite3 or MCAP) or a ROS 1 .bag file, found one that cannot be read"),
    ("nothing", "found no such file"),
    ("badmap", "key 'cmd': expected one of cmd_vel"),
    ("wrongtype", "topic /cmd_vel: expected geometry_msgs/msg/Twist or geometry_msgs/msg/TwistStamped, found "
                  "sensor_msgs/msg/JointState"),
    ("mappedodom", "expected the topic /odometry/filtered (nav_msgs/msg/Odometry) for odom, found the topics"),
])
def test_bad_bags_get_one_line_and_exit_2(short, tmp_path, capsys, case, message):
    bag = tmp_path / "robot.bag"
    args = []
    if case == "missing":
        write_robot_bag(bag, short, "ros1", topics={"cmd_vel": "/other"})
        from rosbags.rosbag1 import Writer   # a bag with joint states only
        bag = tmp_path / "joints.bag"
        ts = get_typestore(Stores.ROS1_NOETIC)
        with Writer(bag) as w:
            w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
    elif case == "empty":
        write_robot_bag(bag, short, "ros1", empty_joints=True)
    elif case == "jump":
        write_robot_bag(bag, short, "ros1", clock_jump=True, cmd_type="geometry_msgs/msg/TwistStamped")
    elif case == "truncated":
        write_robot_bag(bag, short, "ros1")
        data = bag.read_bytes()
        bag.write_bytes(data[:len(data) // 3])
    elif case == "badmap":
        write_robot_bag(bag, short, "ros1")
        m = tmp_path / "map.yaml"
        m.write_text("cmd: /x\n")
        args = ["--topics", str(m)]
    elif case == "nothing":
        bag = tmp_path / "none.bag"
    elif case == "mappedodom":       # a topic map that names an odometry topic the bag lacks
        write_robot_bag(bag, short, "ros1")
        m = tmp_path / "map.yaml"
        m.write_text("odom: /odometry/filtered\n")
        args = ["--topics", str(m)]
    elif case == "wrongtype":        # the joint states recorded under /cmd_vel
        write_robot_bag(bag, short, "ros1", topics={"joint_states": "/cmd_vel", "cmd_vel": "/twist"})
    out = tmp_path / "run.csv"
    assert main(["import", "rosbag", str(bag), "--out", str(out), "--vehicle", "p3at", "--terrain", "vinyl",
                 *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not out.exists()


def test_plans_and_a_run_out_as_a_ros2_bag(tmp_path, capsys):
    """``plan --bag`` and ``run --bag``: an MCAP bag folder that rosbags reads back, with
    the plan's path (one pose per trajectory sample, z on the map), the map as a point
    cloud of every grid node, and the run's odometry, in the frame named."""
    out = tmp_path / "plan_bag"
    assert main(["plan", str(SCN / "hill_tradeoff.yaml"), "--cost", "time", "--bag", str(out), "--frame", "world",
                 "--json", str(tmp_path / "p.json"), "--quiet"]) == 0
    import json
    plan = json.loads((tmp_path / "p.json").read_text())
    with AnyReader([out]) as r:
        topics = {c.topic: c.msgtype for c in r.connections}
        assert topics == {"/sbmpc/map": "sensor_msgs/msg/PointCloud2", "/sbmpc/time/path": "nav_msgs/msg/Path"}
        for conn, _, raw in r.messages():
            m = r.deserialize(raw, conn.msgtype)
            assert m.header.frame_id == "world"
            if conn.topic == "/sbmpc/time/path":
                assert len(m.poses) == len(plan["trajectory"]["t"])
                assert m.poses[-1].pose.position.x == pytest.approx(plan["trajectory"]["x"][-1])
                assert m.poses[10].pose.position.z == pytest.approx(plan["trajectory"]["z"][10])
            else:
                from sbmpc import api
                e = api.load_world(SCN / "hill_tradeoff.yaml").emap
                pts = np.frombuffer(bytes(m.data), np.float32).reshape(-1, 3)
                assert m.width == e.heights.size == len(pts)
                assert pts[:, 2].max() == pytest.approx(e.heights.max(), abs=1e-5)
    run_bag = tmp_path / "run_bag"
    assert main(["run", str(SCN / "flat.yaml"), "--cost", "time", "--bag", str(run_bag), "--quiet"]) == 0
    with AnyReader([run_bag]) as r:
        assert {c.topic for c in r.connections} >= {"/sbmpc/run/odom", "/sbmpc/map"}
        n = sum(1 for c in r.connections if c.topic == "/sbmpc/run/odom" for _ in r.messages(connections=[c]))
        assert n > 100
    # an existing bag folder is not overwritten
    assert main(["plan", str(SCN / "flat.yaml"), "--bag", str(out), "--quiet"]) == 2


def write_gridmap_bag(path: Path, H: np.ndarray, res: float, center=(0.0, 0.0), kind: str = "mcap",
                      start=(0, 0), layers=("elevation", "variance"), messages: int = 1) -> None:
    """A bag with elevation_mapping's grid_map_msgs/GridMap on /elevation_mapping/elevation_map:
    ``H[j, i]`` (rows up y, columns up x) stored as grid_map does (cell (0, 0) at the
    largest x and y, column-major, a circular buffer starting at ``start``)."""
    from maps.gridmap import typestore
    ros1 = kind == "ros1"
    ts = typestore(ros1)
    T = ts.types
    ny, nx = H.shape
    M = H.T[::-1, ::-1]                                    # M[i, j]: i down x, j down y
    M = np.roll(M, start, axis=(0, 1))                     # stored from the buffer's start
    hdr = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="odom",
                                   **({"seq": 0} if ros1 else {}))
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=center[0], y=center[1], z=0.0),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    info = T["grid_map_msgs/msg/GridMapInfo"](resolution=res, length_x=nx * res, length_y=ny * res, pose=pose,
                                              **({"header": hdr} if ros1 else {}))
    D = T["std_msgs/msg/MultiArrayDimension"]
    layout = T["std_msgs/msg/MultiArrayLayout"](dim=[D(label="column_index", size=ny, stride=nx * ny),
                                                    D(label="row_index", size=nx, stride=nx)], data_offset=0)
    arrays = [T["std_msgs/msg/Float32MultiArray"](layout=layout, data=(M if k == 0 else 0.01 + 0 * M).T.ravel()
                                                  .astype(np.float32)) for k in range(len(layers))]
    msg = T["grid_map_msgs/msg/GridMap"](info=info, layers=list(layers), basic_layers=[], data=arrays,
                                         outer_start_index=start[0], inner_start_index=start[1],
                                         **({} if ros1 else {"header": hdr}))
    if ros1:
        from rosbags.rosbag1 import Writer
        w = Writer(path)
        ser = ts.serialize_ros1
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer
        w = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        ser = ts.serialize_cdr
    with w:
        c = w.add_connection("/elevation_mapping/elevation_map", "grid_map_msgs/msg/GridMap", typestore=ts)
        for k in range(messages):
            w.write(c, (k + 1) * 10**9, ser(msg, "grid_map_msgs/msg/GridMap"))


@pytest.mark.parametrize("kind, start", [("mcap", (0, 0)), ("ros1", (7, 3))])
def test_a_scenario_map_from_a_grid_map_bag(tmp_path, kind, start):
    """An asymmetric hill (highest at the north-east) written as elevation_mapping's
    GridMap (ROS 2 and ROS 1, a circular buffer that starts mid-map) is read back onto
    the same nodes, positioned about the map's centre, and plans on it."""
    from maps.io import load_map
    ny, nx, res = 40, 60, 0.25
    X, Y = np.meshgrid(np.arange(nx) * res, np.arange(ny) * res)
    H = 0.5 * np.exp(-((X - 12.0) ** 2 + (Y - 7.5) ** 2) / 4.0) + 0.01 * X
    bag = tmp_path / ("map.bag" if kind == "ros1" else "map_bag")
    write_gridmap_bag(bag, H, res, center=(20.0, 5.0), kind=kind, start=start)
    e = load_map({"file": bag.name}, tmp_path)
    np.testing.assert_allclose(e.heights, H, atol=1e-6)
    assert e.resolution == res
    assert e.origin == pytest.approx((20.0 - 0.5 * nx * res + 0.5 * res, 5.0 - 0.5 * ny * res + 0.5 * res))
    e0 = load_map({"file": bag.name, "layer": "elevation", "origin": [0, 0], "message": 0}, tmp_path)
    assert e0.origin == (0.0, 0.0)


def test_grid_map_holes_and_bad_keys_are_refused_or_walled(tmp_path, capsys):
    from maps.io import MapError, load_map
    H = np.zeros((20, 30))
    H[5, 5:9] = np.nan
    bag = tmp_path / "holes"
    write_gridmap_bag(bag, H, 0.5, messages=2)
    with pytest.raises(MapError, match="4 cells without data"):
        load_map({"file": "holes"}, tmp_path)
    e = load_map({"file": "holes", "nodata": "wall"}, tmp_path)
    assert np.isfinite(e.heights).all() and e.heights.max() == pytest.approx(100.0)
    with pytest.raises(MapError, match="expected one of the grid map's layers elevation, variance, found 'height'"):
        load_map({"file": "holes", "layer": "height"}, tmp_path)
    with pytest.raises(MapError, match=r"expected an index in \[-2, 1\]"):
        load_map({"file": "holes", "message": 5}, tmp_path)
    with pytest.raises(MapError, match="expected the topic /x"):
        load_map({"file": "holes", "topic": "/x"}, tmp_path)
    # through a scenario on the command line: one line, exit 2
    scn = tmp_path / "s.yaml"
    scn.write_text("name: s\nmap: {file: holes}\nterrain: grass\nvehicle: p3at\n"
                   "start: {x: 1, y: 1, yaw_deg: 0}\ngoal: {x: 10, y: 5, radius: 1}\n")
    assert main(["plan", str(scn), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "4 cells without data" in err[0]


@pytest.mark.parametrize("kind", ["mcap", "ros1"])
def test_shadow_writes_the_controllers_commands_and_plans_beside_the_recorded_topics(short, kind, tmp_path, capsys):
    """``sbmpc shadow``: a recorded 8 s drive (rosbags' own writers; ROS 2 MCAP, and ROS 1
    whose messages are converted) fed to the controller at 0.1 s on flat: the output bag
    holds every recorded message, one /sbmpc/cmd_vel and /sbmpc/status per step, a
    /sbmpc/plan per plan (poses on the map, from the aligned start), and the JSON's
    commands are those Twists; the summary compares them with the driver's."""
    import json
    bag = tmp_path / ("drive.bag" if kind == "ros1" else "drive")
    write_robot_bag(bag, short, kind)
    out, js = tmp_path / "shadow", tmp_path / "shadow.json"
    assert main(["shadow", str(bag), "--scenario", str(SCN / "flat.yaml"), "--bag", str(out), "--json", str(js),
                 "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "against the driver's commands" in text and "step latency" in text
    d = json.loads(js.read_text())
    n = len(d["steps"]["t"])
    assert n == pytest.approx((short.t[-1] - short.t[0]) / 0.1 + 1, abs=1)
    assert d["summary"]["plans"] >= 1 and 0.0 <= d["summary"]["same_direction"] <= 1.0
    with AnyReader([out]) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
        assert counts["/cmd_vel"] == counts["/joint_states"] == counts["/odom"] == len(short)
        assert counts["/sbmpc/cmd_vel"] == counts["/sbmpc/status"] == n
        assert counts["/sbmpc/plan"] >= 1
        conn = next(c for c in r.connections if c.topic == "/sbmpc/cmd_vel")
        v = [r.deserialize(raw, conn.msgtype).linear.x for _, _, raw in r.messages(connections=[conn])]
        np.testing.assert_allclose(v, d["steps"]["v"], atol=1e-9)
        conn = next(c for c in r.connections if c.topic == "/sbmpc/plan")
        path = r.deserialize(next(iter(r.messages(connections=[conn])))[2], conn.msgtype)
        p0 = path.poses[0].pose.position
        assert (p0.x, p0.y) == pytest.approx((2.0, 2.0), abs=0.05)      # flat's start: the aligned first pose
    assert main(["shadow", str(bag), "--scenario", str(SCN / "flat.yaml"), "--period", "3"]) == 2
    assert "--period: expected a control period in [0.05, 1] s, found 3" in capsys.readouterr().err
