"""ROS bags without ROS (the optional ``rosbags`` package: ``pip install 'sbmpc[ros]'``).

* :func:`read_bag`: a ROS 2 bag folder (sqlite3 or MCAP) or a ROS 1 ``.bag`` into a
  measured run (:class:`dynamics.runs.Run`, the CSV that ``sbmpc diagnose`` reads).
  Defaults that fit common skid-steer drivers (Husky, Jackal, Warthog, Pioneer's
  ``rosaria``/``p2os``): wheel commands from ``geometry_msgs/Twist`` (or ``TwistStamped``)
  on ``/cmd_vel``, converted to wheel speeds as the robot's driver converts them, with the vehicle's
  command track and wheel radius (w = (v -+ omega B / 2) / r, B = ``Vehicle.command_track``:
  a ROS diff_drive_controller's wheel separation times its separation multiplier); measured wheel speeds and efforts from
  ``sensor_msgs/JointState`` on ``/joint_states``, the joints whose names hold ``left``
  and ``right`` averaged per side (efforts summed: a side's torque); pose from
  ``nav_msgs/Odometry`` on ``/odom``; battery voltage from ``sensor_msgs/BatteryState``
  where there is one. Every channel is resampled onto the wheel speeds' time base (the
  last command before each sample; pose, efforts and voltage linear between their
  samples); a gap in the wheel speeds longer than ``dynamics.runs.GAP_FACTOR`` median
  steps starts a new segment. A topic map (YAML) renames the topics and names the
  joints of each side.
* :func:`write_bag`: plans and a run out as a ROS 2 bag folder (MCAP storage), readable
  by ``rosbags``, ``ros2 bag`` and Foxglove: ``nav_msgs/Path`` per plan with z on the map,
  the executed run's ``nav_msgs/Odometry``, and the map as ``sensor_msgs/PointCloud2``
  (x, y, z float32), all in the frame the user names.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from dynamics.runs import GAP_FACTOR, Run

from .errors import InputError

TOPICS = {"cmd_vel": "/cmd_vel", "joint_states": "/joint_states", "odom": "/odom", "battery": "/battery_state"}
MAP_KEYS = (*TOPICS, "left_joints", "right_joints")
CMD_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


def _rosbags():
    try:
        import rosbags  # noqa: F401
    except ImportError:
        raise InputError("ROS bags need the rosbags package: pip install 'sbmpc[ros]'") from None


def topic_map(path: Path | None) -> dict:
    """The topic map: :data:`TOPICS` updated from a YAML file of ``key: value`` lines
    (keys :data:`MAP_KEYS`; ``left_joints``, ``right_joints``: lists of joint names)."""
    out = dict(TOPICS, left_joints=None, right_joints=None, named=())
    if path is None:
        return out
    from dynamics.params import read_yaml_text
    try:
        d = read_yaml_text(Path(path))
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: expected a topic map YAML file, found one that cannot be read ({exc})") from None
    if not isinstance(d, dict):
        raise InputError(f"{path}: expected a mapping of {', '.join(MAP_KEYS)}, found {type(d).__name__}")
    for k, v in d.items():
        if k not in MAP_KEYS:
            raise InputError(f"{path}: key '{k}': expected one of {', '.join(MAP_KEYS)}, found an unknown key")
        if k.endswith("_joints"):
            if not (isinstance(v, list) and v and all(isinstance(x, str) for x in v)):
                raise InputError(f"{path}: key '{k}': expected a list of joint names, found {v!r:.60}")
        elif not (isinstance(v, str) and v.startswith("/")):
            raise InputError(f"{path}: key '{k}': expected a topic name starting with '/', found {v!r:.60}")
        out[k] = v
    out["named"] = tuple(d)           # the keys the map names: an optional topic it names must be there
    return out


def _stamp(msg, t_bag: int) -> float:
    """A message's time [s]: its header stamp where it has a non-zero one, else the bag's."""
    h = getattr(msg, "header", None)
    if h is not None and (h.stamp.sec or h.stamp.nanosec):
        return h.stamp.sec + 1e-9 * h.stamp.nanosec
    return 1e-9 * t_bag


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _side(names, want: list | None, word: str, path, topic) -> list:
    if want:
        idx = [i for i, n in enumerate(names) if n in want]
        if len(idx) != len(want):
            missing = [w for w in want if w not in names]
            raise InputError(f"{path}: topic {topic}: expected the joints {', '.join(missing)} (topic map), "
                             f"found the joints {', '.join(names)}")
        return idx
    idx = [i for i, n in enumerate(names) if word in n.lower()]
    if not idx:
        raise InputError(f"{path}: topic {topic}: expected joints with '{word}' in their names (or left_joints/"
                         f"right_joints in --topics), found the joints {', '.join(names) or 'none'}")
    return idx


def open_bag(path: Path):
    """An opened ``rosbags`` AnyReader of the bag at ``path``: a folder is a ROS 2 bag
    whatever its name (``drive.bag`` too), a file a ROS 1 bag
    (:func:`maps.gridmap.any_reader`). Messages without embedded definitions decode with
    ROS 2 Humble's types."""
    from rosbags.typesys import Stores, get_typestore

    from maps.gridmap import any_reader
    reader = any_reader(path, get_typestore(Stores.ROS2_HUMBLE))
    reader.open()
    return reader


def read_bag(path: Path, vehicle, terrain_name: str, vehicle_name: str, topics: dict) -> Run:
    """A measured run from the bag at ``path`` (module doc); ``vehicle`` gives the track
    and wheel radius that turn ``/cmd_vel`` into wheel speeds. InputError (one line: the
    file, what was expected, what was found) on a bag that cannot be read, a missing
    topic or field, an empty topic, or a clock that jumps back."""
    return read_bag_timed(path, vehicle, terrain_name, vehicle_name, topics)[0]


def read_bag_timed(path: Path, vehicle, terrain_name: str, vehicle_name: str, topics: dict) -> tuple:
    """(:func:`read_bag`'s run, the bag time [s] of its first row: the run's t = 0)."""
    _rosbags()
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: expected a ROS 2 bag folder or a ROS 1 .bag file, found no such file")
    try:
        reader = open_bag(path)
    except Exception as exc:          # rosbags raises its own errors for every kind of broken bag
        raise InputError(f"{path}: expected a ROS 2 bag folder (sqlite3 or MCAP) or a ROS 1 .bag file, found one "
                         f"that cannot be read ({' '.join(str(exc).split())[:200]})") from None
    try:
        have = {c.topic: c.msgtype for c in reader.connections}
        listed = ", ".join(f"{t} ({m})" for t, m in sorted(have.items())) or "none"

        def need(key, types):
            t = topics[key]
            if t not in have:
                raise InputError(f"{path}: expected the topic {t} ({' or '.join(types)}) for {key}, found the "
                                 f"topics {listed}")
            if have[t] not in types:
                raise InputError(f"{path}: topic {t}: expected {' or '.join(types)}, found {have[t]}")
            return t

        cmd = need("cmd_vel", CMD_TYPES)
        js = need("joint_states", ("sensor_msgs/msg/JointState",))
        # the optional topics: skipped where the bag lacks them, unless the topic map names them
        odom = need("odom", ("nav_msgs/msg/Odometry",)) if "odom" in topics.get("named", ()) else \
            (topics["odom"] if have.get(topics["odom"]) == "nav_msgs/msg/Odometry" else None)
        batt = need("battery", ("sensor_msgs/msg/BatteryState",)) if "battery" in topics.get("named", ()) else \
            (topics["battery"] if have.get(topics["battery"]) == "sensor_msgs/msg/BatteryState" else None)
        want = [t for t in (cmd, js, odom, batt) if t]
        rows = {t: [] for t in want}
        conns = [c for c in reader.connections if c.topic in want]
        try:
            for conn, t_bag, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                rows[conn.topic].append((_stamp(msg, t_bag), msg))
        except Exception as exc:
            raise InputError(f"{path}: expected readable messages, found a bag that breaks off or holds a message "
                             f"that cannot be decoded ({' '.join(str(exc).split())[:200]})") from None
    finally:
        reader.close()
    for t in (cmd, js):
        if not rows[t]:
            raise InputError(f"{path}: topic {t}: expected messages, found none")
    for t, r in rows.items():
        ts = np.array([s for s, _ in r])
        back = np.flatnonzero(np.diff(ts) < 0)
        if back.size:
            k = int(back[0])
            raise InputError(f"{path}: topic {t}: expected time stamps that never go back, found a jump from "
                             f"{ts[k]:.3f} s to {ts[k + 1]:.3f} s (message {k + 2})")
    # measured wheel speeds (the time base) and efforts, per side
    names = list(rows[js][0][1].name)
    left = _side(names, topics["left_joints"], "left", path, js)
    right = _side(names, topics["right_joints"], "right", path, js)
    t, wl, wr, el, er = [], [], [], [], []
    for k, (s, m) in enumerate(rows[js]):
        if list(m.name) != names:
            raise InputError(f"{path}: topic {js}: expected the same joints in every message, found "
                             f"{', '.join(m.name)} in message {k + 1} after {', '.join(names)}")
        v = np.asarray(m.velocity, float)
        if v.size != len(names):
            raise InputError(f"{path}: topic {js}: expected a velocity per joint ({len(names)}), found "
                             f"{v.size} in message {k + 1}")
        e = np.asarray(m.effort, float)
        t.append(s)
        wl.append(v[left].mean())
        wr.append(v[right].mean())
        el.append(e[left].sum() if e.size == len(names) else np.nan)
        er.append(e[right].sum() if e.size == len(names) else np.nan)
    t = np.array(t)
    keep = np.r_[True, np.diff(t) > 0]            # repeated stamps: the first
    t = t[keep]
    cols = {"wl": np.array(wl)[keep], "wr": np.array(wr)[keep]}
    if len(t) < 2:
        raise InputError(f"{path}: topic {js}: expected at least 2 messages at distinct times, found {len(t)}")
    # commands: the last one before each sample (zero-order hold, as a driver applies them)
    ct = np.array([s for s, _ in rows[cmd]])
    tw = [m.twist if hasattr(m, "twist") else m for _, m in rows[cmd]]
    v = np.array([x.linear.x for x in tw])
    w = np.array([x.angular.z for x in tw])
    B, r = vehicle.command_track, vehicle.wheel_radius       # the driver's own conversion
    k = np.searchsorted(ct, t + 1e-6, side="right") - 1     # (a command stamped within 1 us of a sample: at it)
    before = k < 0
    k = np.clip(k, 0, len(ct) - 1)
    cols["wl_cmd"] = np.where(before, np.nan, (v[k] - 0.5 * B * w[k]) / r)
    cols["wr_cmd"] = np.where(before, np.nan, (v[k] + 0.5 * B * w[k]) / r)
    if not np.all(np.isnan(np.array(el)[keep])):
        cols["tau_l"], cols["tau_r"] = np.array(el)[keep], np.array(er)[keep]

    def interp(ts, vals):
        out = np.interp(t, ts, vals)
        out[(t < ts[0]) | (t > ts[-1])] = np.nan
        return out
    if odom and rows[odom]:
        ot = np.array([s for s, _ in rows[odom]])
        P = [m.pose.pose for _, m in rows[odom]]
        cols["x"] = interp(ot, np.array([p.position.x for p in P]))
        cols["y"] = interp(ot, np.array([p.position.y for p in P]))
        cols["z"] = interp(ot, np.array([p.position.z for p in P]))
        cols["yaw"] = interp(ot, np.unwrap(np.array([_yaw(p.orientation) for p in P])))
    if batt and rows[batt]:
        bt = np.array([s for s, _ in rows[batt]])
        cols["v_batt"] = interp(bt, np.array([m.voltage for _, m in rows[batt]]))
    # segments: a gap in the wheel speeds, or no command yet
    dt = np.diff(t)
    seg = np.r_[0, np.cumsum(dt > GAP_FACTOR * np.median(dt))]
    good = ~before
    if not good.any():
        raise InputError(f"{path}: topic {cmd}: expected commands during the wheel speeds' span "
                         f"({t[0]:.3f}-{t[-1]:.3f} s), found them all after it")
    cols = {c: a[good] for c, a in cols.items()}
    cols["segment"] = seg[good].astype(float)
    cols["t"] = t[good] - t[good][0]
    meta = {"vehicle": vehicle_name, "terrain": terrain_name,
            "note": f"imported from ROS bag {path.name}: {cmd} -> wl_cmd/wr_cmd (command track {B:g} m, wheel radius {r:g} m), "
                    f"{js} joints {', '.join(names[i] for i in left)} | {', '.join(names[i] for i in right)}"
                    + (f", pose {odom}" if odom and rows[odom] else "") + (f", voltage {batt}" if batt and rows[batt] else "")}
    return Run(cols, meta, str(path)), float(t[good][0])


# ---- out ---------------------------------------------------------------------------
def _time(ts, s: float):
    sec = int(math.floor(s))
    return ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((s - sec) * 1e9)) % 1_000_000_000)


def _pose(ts, x, y, z, yaw, t, frame):
    T = ts.types
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw))
    p = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z)),
                                    orientation=q)
    return T["geometry_msgs/msg/PoseStamped"](header=T["std_msgs/msg/Header"](stamp=_time(ts, t), frame_id=frame),
                                              pose=p)


def write_bag(out: Path, emap, plans: dict, frame: str = "map", run=None, t0: float = 0.0) -> dict:
    """Write plans {label: Plan} (and a run's executed trajectory) as a ROS 2 bag folder
    ``out`` (MCAP storage; module doc). Message times start at ``t0`` [s]. Returns
    {topic: messages}."""
    _rosbags()
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    counts = {}
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        def put(topic, msgtype, msgs):
            conn = w.add_connection(topic, msgtype, typestore=ts)
            for t, m in msgs:
                w.write(conn, int(round((t0 + t) * 1e9)), ts.serialize_cdr(m, msgtype))
            counts[topic] = len(msgs)

        # the map: one cloud of the grid's nodes
        ny, nx = emap.shape
        X, Y = np.meshgrid(emap.origin[0] + emap.resolution * np.arange(nx),
                           emap.origin[1] + emap.resolution * np.arange(ny))
        pts = np.column_stack([X.ravel(), Y.ravel(), emap.heights.ravel()]).astype(np.float32)
        F = T["sensor_msgs/msg/PointField"]
        fields = [F(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate("xyz")]     # 7: FLOAT32
        cloud = T["sensor_msgs/msg/PointCloud2"](
            header=T["std_msgs/msg/Header"](stamp=_time(ts, t0), frame_id=frame), height=1, width=len(pts),
            fields=fields, is_bigendian=False, point_step=12, row_step=12 * len(pts),
            data=np.frombuffer(pts.tobytes(), np.uint8), is_dense=True)
        put("/sbmpc/map", "sensor_msgs/msg/PointCloud2", [(0.0, cloud)])
        for label, p in plans.items():
            if not p.found:
                continue
            tr = p.trajectory
            poses = [_pose(ts, tr["x"][i], tr["y"][i], tr["z"][i], tr["yaw"][i], t0 + tr["t"][i], frame)
                     for i in range(len(tr["t"]))]
            path = T["nav_msgs/msg/Path"](header=T["std_msgs/msg/Header"](stamp=_time(ts, t0), frame_id=frame),
                                          poses=poses)
            put(f"/sbmpc/{label}/path", "nav_msgs/msg/Path", [(0.0, path)])
        if run is not None and run.trajectory:
            tr = run.trajectory
            msgs = []
            for i in range(len(tr["t"])):
                ps = _pose(ts, tr["x"][i], tr["y"][i], tr["z"][i], tr["yaw"][i], t0 + tr["t"][i], frame)
                tw = T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=float(tr["v"][i]), y=0.0, z=0.0),
                                                  angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0,
                                                                                         z=float(tr["yaw_rate"][i])))
                od = T["nav_msgs/msg/Odometry"](
                    header=ps.header, child_frame_id="base_link",
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=ps.pose, covariance=np.zeros(36)),
                    twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)))
                msgs.append((float(tr["t"][i]), od))
            put("/sbmpc/run/odom", "nav_msgs/msg/Odometry", msgs)
    return counts


__all__ = ["TOPICS", "open_bag", "read_bag", "read_bag_timed", "topic_map", "write_bag"]
