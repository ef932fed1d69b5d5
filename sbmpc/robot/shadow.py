"""Shadow runs (``sbmpc shadow``): a recorded drive's measurements fed to the controller at
its period, and what it would have commanded written beside what the driver did.

The step a robotics team takes before it gives a planner the wheels: the robot drives as
it always does (a person with a joystick, another planner); the controller watches the
bag as if it were on board and answers every ``period_s`` with wheel speeds and a
``cmd_vel``. Its commands are never applied, so the drive leaves its predictions
(every period is planned from the measured state): what it shows is what it would have
done from where the robot really was, and how far that is from the driver.

The pose comes from the bag's odometry (``/odom``), moved so that its first pose is the
scenario's start (``align='start'``; ``'none'``: the odometry frame is the map's); wheel
speeds and efforts from the joint states; the voltage from the battery where recorded.
Each channel is sampled at the controller's times (the last row of the imported run at or
before each; the import itself interpolates the pose between odometry messages). The
estimator predicts through the driver's commands, which the drive really got. In lockstep
the controller's step latencies include the waits for its plans: the latency a robot
sees is ``bench/bench_controller.py``'s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from .controller import Controller
from .messages import Measurement, to_twist

ALIGNS = ("start", "none")


@dataclass
class ShadowResult:
    """A shadow run: per controller step its time [s from the bag's first sample],
    command (wl, wr [rad/s], v [m/s], omega [rad/s]) and status, the driver's command at
    that time (NaN where none yet), the plans' paths, and the bag time [s] of t = 0."""

    t: np.ndarray
    ours: np.ndarray              # (n, 4): wl, wr, v, omega
    theirs: np.ndarray            # (n, 4)
    status: list
    paths: list
    t0: float
    latencies: np.ndarray
    plans: int
    summary: dict = field(default_factory=dict)


def _aligned(run, world, align: str) -> tuple:
    """(x, y, yaw) arrays of the run's pose in the map's frame (module doc)."""
    if "x" not in run.columns or np.all(np.isnan(run["x"])):
        raise InputError(f"{run.source}: expected the pose (nav_msgs/Odometry on the odom topic) for a shadow run, "
                         f"found none")
    x, y, yaw = run["x"].copy(), run["y"].copy(), run["yaw"].copy()
    ok = np.flatnonzero(~np.isnan(x))
    if align == "start":
        s = world.scenario.start
        k = ok[0]
        d = math.radians(s["yaw_deg"]) - yaw[k]
        c, sn = math.cos(d), math.sin(d)
        dx, dy = x - x[k], y - y[k]
        x, y, yaw = s["x"] + c * dx - sn * dy, s["y"] + sn * dx + c * dy, yaw + d
    return x, y, yaw


def shadow(run, t0: float, world, cost: str | None = None, period_s: float = 0.1, align: str = "start",
           horizon_s: float | None = None) -> ShadowResult:
    """The controller over a measured run (a ROS bag read by
    :func:`sbmpc.rosbag.read_bag_timed`, bag time ``t0`` [s] at its t = 0), at
    ``period_s`` (module doc)."""
    if align not in ALIGNS:
        raise InputError(f"align: expected one of {', '.join(ALIGNS)}, found {align!r:.30}")
    x, y, yaw = _aligned(run, world, align)
    ctrl = Controller(world, cost, period_s=period_s, horizon_s=horizon_s, lockstep=True, keep_paths=True)
    v = world.vehicle
    t = run.t
    have = set(run.columns)
    first = int(np.flatnonzero(~np.isnan(x))[0])
    ts = np.arange(t[first], t[-1] + 1e-9, period_s)
    rows, theirs, status = [], [], []
    prev = None
    try:
        for tk in ts:
            k = int(np.searchsorted(t, tk + 1e-9, side="right")) - 1
            if np.isnan(x[k]):
                continue
            kw = {}
            if "wl" in have and np.isfinite(run["wl"][k]):
                kw.update(wl=float(run["wl"][k]), wr=float(run["wr"][k]))
            if "tau_l" in have and np.isfinite(run["tau_l"][k]) and np.isfinite(run["tau_r"][k]):
                kw.update(tau_l=float(run["tau_l"][k]), tau_r=float(run["tau_r"][k]))
            if "v_batt" in have and np.isfinite(run["v_batt"][k]):
                kw.update(voltage=float(run["v_batt"][k]))
            if not world.emap.contains(x[k], y[k]):
                x0, x1, y0, y1 = world.emap.extent
                raise InputError(f"{run.source}: the pose at t = {tk:.2f} s, ({x[k]:.2f}, {y[k]:.2f}) in the map's "
                                 f"frame: expected it on the scenario's map (x {x0:g}..{x1:g}, y {y0:g}..{y1:g} m), "
                                 f"found it off (align: {align})")
            # the estimator predicts through what the drive was given: the driver's commands
            applied = (prev if prev is not None and np.all(np.isfinite(prev)) else (0.0, 0.0))
            cmd = ctrl.step(float(tk), Measurement(float(x[k]), float(y[k]), float(yaw[k]), **kw), applied=applied)
            prev = (float(run["wl_cmd"][k]), float(run["wr_cmd"][k]))
            rows.append((cmd.wl, cmd.wr, cmd.v, cmd.omega))
            status.append(cmd.status)
            wl_c, wr_c = run["wl_cmd"][k], run["wr_cmd"][k]
            theirs.append((wl_c, wr_c, *to_twist(wl_c, wr_c, v)))
    finally:
        ctrl.close()
    out = ShadowResult(ts[:len(rows)], np.array(rows, float).reshape(-1, 4), np.array(theirs, float).reshape(-1, 4),
                       status, ctrl.paths, t0, np.array(ctrl.latencies), len(ctrl.plans))
    out.summary = summary(out, ctrl)
    return out


def summary(res: ShadowResult, ctrl: Controller | None = None) -> dict:
    """How far the controller's commands are from the driver's: per channel (v [m/s],
    omega [rad/s]) the median and 95th percentile of |ours - theirs| and their RMS, the
    share of steps where both drive the same way (sign of v, or both still), the
    steps per status, plans made and the steps' wall-clock latency [ms]."""
    d = res.ours - res.theirs
    ok = np.all(np.isfinite(res.theirs), axis=1)
    out = {"steps": int(len(res.t)), "compared": int(ok.sum()),
           "statuses": {s: res.status.count(s) for s in dict.fromkeys(res.status)}, "plans": res.plans}
    for j, name in ((2, "v"), (3, "omega")):
        a = np.abs(d[ok, j])
        out[name] = ({"median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
                      "rms": float(np.sqrt(np.mean(a ** 2)))} if a.size else None)
    if ok.any():
        sv = np.sign(np.where(np.abs(res.ours[ok, 2]) < 0.02, 0.0, res.ours[ok, 2]))
        tv = np.sign(np.where(np.abs(res.theirs[ok, 2]) < 0.02, 0.0, res.theirs[ok, 2]))
        out["same_direction"] = float(np.mean(sv == tv))
    lat = res.latencies * 1e3
    if lat.size:
        out["step_ms"] = {"median": float(np.median(lat)), "p95": float(np.percentile(lat, 95)),
                          "max": float(lat.max())}
    return out


def write_shadow_bag(out: Path, source: Path, res: ShadowResult, frame: str = "map") -> dict:
    """The recorded bag's topics (copied as they are; a ROS 1 bag's decoded and written
    with ROS 2 Humble's message definitions, types Humble lacks left out) with ``/sbmpc/cmd_vel`` (geometry_msgs/Twist, every controller step),
    ``/sbmpc/plan`` (nav_msgs/Path, every plan found, in ``frame``) and ``/sbmpc/status``
    (std_msgs/String) beside them, as a ROS 2 bag folder (MCAP) at ``out``. Returns
    {topic: messages}."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from ..rosbag import _pose, _time, open_bag
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    counts: dict = {}
    reader = open_bag(source)
    try:
        with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
            # a ROS 2 bag's messages are copied as they are; a ROS 1 bag's are decoded and
            # written with ROS 2 Humble's definitions (a Header loses its seq)
            ros1 = not reader.is2
            conns = {}
            for c in reader.connections:
                try:
                    if ros1 and c.msgtype not in ts.types:
                        raise KeyError(c.msgtype)
                    conns[c.id] = w.add_connection(c.topic, c.msgtype, typestore=ts if ros1 else reader.typestore)
                except Exception:         # a type the writer cannot describe: left out, and said so
                    counts.setdefault("left out", []).append(c.topic)
            for c, t_bag, raw in reader.messages(connections=[c for c in reader.connections if c.id in conns]):
                data = ts.serialize_cdr(reader.deserialize(raw, c.msgtype), c.msgtype) if ros1 else raw
                w.write(conns[c.id], t_bag, data)
                counts[c.topic] = counts.get(c.topic, 0) + 1

            def put(topic, msgtype, msgs):
                conn = w.add_connection(topic, msgtype, typestore=ts)
                for s, m in msgs:
                    w.write(conn, int(round(s * 1e9)), ts.serialize_cdr(m, msgtype))
                counts[topic] = len(msgs)

            V3 = T["geometry_msgs/msg/Vector3"]
            put("/sbmpc/cmd_vel", "geometry_msgs/msg/Twist",
                [(res.t0 + tk, T["geometry_msgs/msg/Twist"](linear=V3(x=float(c[2]), y=0.0, z=0.0),
                                                            angular=V3(x=0.0, y=0.0, z=float(c[3]))))
                 for tk, c in zip(res.t, res.ours)])
            put("/sbmpc/status", "std_msgs/msg/String",
                [(res.t0 + tk, T["std_msgs/msg/String"](data=s)) for tk, s in zip(res.t, res.status)])
            paths = []
            for tk, p in res.paths:
                s = res.t0 + tk
                poses = [_pose(ts, p["x"][i], p["y"][i], p["z"][i], p["yaw"][i], s, frame) for i in range(len(p["x"]))]
                paths.append((s, T["nav_msgs/msg/Path"](header=T["std_msgs/msg/Header"](stamp=_time(ts, s), frame_id=frame),
                                                        poses=poses)))
            put("/sbmpc/plan", "nav_msgs/msg/Path", paths)
    finally:
        reader.close()
    return counts


__all__ = ["ALIGNS", "ShadowResult", "shadow", "summary", "write_shadow_bag"]
