"""``sbmpc shadow``: the controller on a recorded drive, its commands written beside the driver's."""
from __future__ import annotations

from ..errors import InputError
from .compiling import compile_note
from .files import Outputs, path_arg, scenario_inputs, write_json
from .plan import _world, bag_out


def add_parsers(sub):
    s = sub.add_parser("shadow", help="run the controller on a robot's recorded bag and compare its commands "
                       "with the driver's",
                       description="Shadow run: feed a recorded drive's measurements (odometry pose, joint states, "
                       "battery) to the controller a robot would run (sbmpc.robot.Controller) at its control "
                       "period, as if it were on board, and write what it would have commanded (/sbmpc/cmd_vel "
                       "Twist, its plans as nav_msgs/Path on /sbmpc/plan, its status on /sbmpc/status) beside the "
                       "recorded topics, with a summary of how far its commands are from the driver's. Its "
                       "commands are never applied: every period is planned from where the robot really was. "
                       "Needs pip install 'sbmpc[ros]'; docs/robot.md.")
    s.add_argument("source", type=path_arg, help="the recorded bag: a ROS 2 bag folder (sqlite3 or MCAP, whatever "
                   "its name) or a ROS 1 .bag")
    s.add_argument("--scenario", type=path_arg, required=True, help="scenario YAML: the map, terrains, goal, "
                   "vehicle and settings the controller plans with")
    s.add_argument("--topics", type=path_arg, help="a topic map YAML (cmd_vel, joint_states, odom, battery, "
                   "left_joints, right_joints; docs/robot.md)")
    s.add_argument("--bag", type=path_arg, metavar="OUT", help="write the recorded topics and the controller's "
                   "commands, plans and status as a ROS 2 bag folder (MCAP) here")
    s.add_argument("--frame", default="map", help="frame id of the plans in --bag (default: map)")
    s.add_argument("--json", type=path_arg, help="write the per-step commands and the summary as JSON here")
    s.add_argument("--cost", choices=("time", "energy"), help="what to minimise (default: the scenario's)")
    s.add_argument("--vehicle", help="the robot (default: the scenario's vehicle): its wheel radius and command "
                   "track turn the recorded /cmd_vel into wheel speeds and its commands into a Twist")
    s.add_argument("--period", type=float, default=0.1, metavar="S", help="control period [s] (0.05-1; default 0.1)")
    s.add_argument("--horizon", type=float, metavar="S", help="look-ahead of the controller's plans [s] "
                   "(default: the scenario's planner.horizon_s, else 10)")
    s.add_argument("--align", choices=("start", "none"), default="start", help="start (default): move the "
                   "recorded odometry so its first pose is the scenario's start; none: the odometry frame is "
                   "the map's")
    s.add_argument("--quiet", action="store_true", help="no compile note")
    s.set_defaults(func=run_shadow, seed=None)


def run_shadow(args) -> int:
    from ..robot.shadow import shadow, write_shadow_bag
    from ..rosbag import _rosbags, read_bag_timed, topic_map
    _rosbags()
    inputs = [args.source] + scenario_inputs(args.scenario) + [args.topics, args.vehicle]
    outs = Outputs(inputs)
    outs.file(args.json, "--json")
    if args.bag is not None and args.source is not None and args.bag.resolve() == args.source.resolve():
        raise InputError(f"--bag: expected a new folder, found the recorded bag '{args.source}' itself")
    bag_out(args)
    if not 0.05 <= args.period <= 1.0:
        raise InputError(f"--period: expected a control period in [0.05, 1] s, found {args.period:g}")
    if args.horizon is not None and not 0.0 < args.horizon <= 3600.0:
        raise InputError(f"--horizon: expected seconds in (0, 3600], found {args.horizon:g}")
    args.start = args.goal = None
    world = _world(args)
    topics = topic_map(args.topics)
    run, t0 = read_bag_timed(args.source, world.vehicle, world.terrains[0].name, world.vehicle.name, topics)
    compile_note(args.quiet)
    res = shadow(run, t0, world, world.scenario.cost, args.period, args.align, args.horizon)
    print(describe(args.source, res))
    if args.bag is not None:
        counts = write_shadow_bag(args.bag, args.source, res, args.frame)
        left = counts.pop("left out", [])
        print(f"wrote {args.bag}: ROS 2 bag (MCAP): " + ", ".join(f"{t} ({n})" for t, n in counts.items())
              + (f"; left out (types the writer cannot describe): {', '.join(left)}" if left else ""))
    if args.json:
        write_json(args.json, {"schema": "sbmpc.shadow/1", "source": str(args.source),
                               "scenario": world.scenario.name, "period_s": args.period, "t0_s": res.t0,
                               "summary": res.summary,
                               "steps": {"t": res.t.tolist(), "status": res.status,
                                         "wl": res.ours[:, 0].tolist(), "wr": res.ours[:, 1].tolist(),
                                         "v": res.ours[:, 2].tolist(), "omega": res.ours[:, 3].tolist(),
                                         "driver_v": res.theirs[:, 2].tolist(),
                                         "driver_omega": res.theirs[:, 3].tolist()}})
    return 0


def describe(source, res) -> str:
    """The shadow run's summary in a few lines."""
    s = res.summary
    lines = [f"shadow run of {source}: {s['steps']} steps of {res.t[1] - res.t[0] if len(res.t) > 1 else 0:.2f} s, "
             f"{s['plans']} plans; " + ", ".join(f"{k} {n}" for k, n in s["statuses"].items())]
    if s.get("v"):
        lines.append(f"  against the driver's commands ({s['compared']} steps): v off by median "
                     f"{s['v']['median']:.2f} m/s (95th percentile {s['v']['p95']:.2f}), omega by median "
                     f"{s['omega']['median']:.2f} rad/s (95th percentile {s['omega']['p95']:.2f}); same direction "
                     f"of travel on {100 * s['same_direction']:.0f} % of steps")
    if s.get("step_ms"):
        lines.append(f"  step latency: median {s['step_ms']['median']:.1f} ms, 95th percentile "
                     f"{s['step_ms']['p95']:.1f} ms, max {s['step_ms']['max']:.1f} ms (plans awaited: lockstep)")
    return "\n".join(lines)
