"""``sbmpc protocol``: the manoeuvres to record for a calibration, as commands or a bag."""
from __future__ import annotations

import math

from ..errors import InputError
from .files import Outputs, atomic, path_arg, write_json


def add_parsers(sub):
    p = sub.add_parser("protocol", help="the manoeuvres to record for sbmpc calibrate, sized to the robot and the "
                       "free area, as a commands CSV or a ROS 2 bag to play",
                       description="Design a calibration drive (DRIVE-like): straight driving at speeds up to the "
                       "top speed, the top speed itself, pivots, and turns whose speeds and curvatures are spread "
                       "over what the drive holds, each turn both ways, pauses between; every part drives back "
                       "along its own track, and the parts are sized so that the drive, simulated with the "
                       "closed-loop model, stays inside the free area (W along the robot's heading at the start, "
                       "H across, the robot at its centre). Prints each part and what it identifies, and what "
                       "calibrate's own rules find in the simulated run (training and held-out parts). "
                       "docs/robot.md section 3.")
    p.add_argument("--vehicle", required=True, help="shipped vehicle name or YAML path (its limits size the parts)")
    p.add_argument("--terrain", default="asphalt", help="shipped terrain name or YAML path the drive will be on "
                   "(default asphalt)")
    p.add_argument("--area", required=True, metavar="W,H", help="free area [m]: W along the robot's heading at the "
                   "start, H across it; the robot starts at its centre")
    p.add_argument("--out", type=path_arg, required=True, help="commands.csv (a name ending in .csv), or a ROS 2 "
                   "bag folder (MCAP) to play with ros2 bag play (any other name; needs pip install 'sbmpc[ros]')")
    p.add_argument("--duration", type=float, default=240.0, metavar="S", help="about how long [s] (default 240; "
                   "turns fill what the straight, top-speed and pivot parts leave)")
    p.add_argument("--topic", default="/cmd_vel", help="the Twist topic of a bag (default /cmd_vel)")
    p.add_argument("--json", type=path_arg, help="write the parts and the check as JSON here")
    p.set_defaults(func=run_protocol)


def _area(text: str) -> tuple:
    try:
        w, h = (float(x) for x in text.split(","))
    except ValueError:
        raise InputError(f"--area: expected W,H in metres (e.g. 6,4), found {text!r}") from None
    if not (math.isfinite(w) and math.isfinite(h) and 0 < w <= 1e4 and 0 < h <= 1e4):
        raise InputError(f"--area: expected W,H in (0, 10000] metres, found {text!r}")
    return w, h


def run_protocol(args) -> int:
    from dynamics import ParameterError, load_terrain, load_vehicle
    from ..protocol import ProtocolError, sized, write_bag, write_csv
    area = _area(args.area)
    outs = Outputs([args.vehicle, args.terrain])
    csv = args.out.suffix.lower() == ".csv"
    if csv:
        outs.file(args.out, "--out")
    else:
        from ..rosbag import _rosbags
        if args.out.exists():
            raise InputError(f"--out: expected a commands .csv or a new folder for the ROS 2 bag, found the "
                             f"existing '{args.out}'")
        outs.folder(args.out, "--out")
        _rosbags()
    outs.file(args.json, "--json")
    if not (math.isfinite(args.duration) and 0 < args.duration <= 3600):
        raise InputError(f"--duration: expected seconds in (0, 3600], found {args.duration:g}")
    try:
        vehicle, terrain = load_vehicle(args.vehicle), load_terrain(args.terrain)
    except ParameterError as exc:
        raise InputError(str(exc)) from None
    try:
        proto, check = sized(vehicle, terrain, area, args.duration)
    except ProtocolError as exc:
        raise InputError(f"--area: {exc}" if str(exc).startswith("area") else str(exc)) from None
    if not check.inside:
        a, b = check.reach
        raise InputError(f"--area: expected room for the drive of the {vehicle.name}, found its simulated path "
                         f"reaching x {check.box[0]:.1f}..{check.box[1]:.1f}, y {check.box[2]:.1f}..{check.box[3]:.1f} m "
                         f"from the start against +-{a:.1f}, +-{b:.1f} m even with its parts shrunk; a larger area")
    moving = [p for p in proto.parts if p.kind != "pause"]
    print(f"protocol for the {vehicle.name} on {terrain.name} in a {area[0]:g} x {area[1]:g} m area: {len(moving)} "
          f"parts, {proto.seconds:.0f} s, commands at 20 Hz")
    print(f"  {'part':>4s} {'t [s]':>6s} {'v [m/s]':>8s} {'omega [rad/s]':>13s} {'s':>5s}  what  (identifies)")
    start = 0.0
    for i, p in enumerate(proto.parts):
        if p.kind != "pause":
            print(f"  {i:4d} {start:6.1f} {p.v:8.2f} {p.omega:13.2f} {p.seconds:5.1f}  {p.label}  "
                  f"({', '.join(p.identifies)})")
        start += p.seconds
    for note in proto.notes:
        print(f"note: {note}")
    _excited(check)
    x0, x1, y0, y1 = check.box
    print(f"simulated with the closed-loop model: the path stays within x {x0:.1f}..{x1:.1f}, y {y0:.1f}..{y1:.1f} m "
          f"of the start (room +-{check.reach[0]:.1f}, +-{check.reach[1]:.1f} m) and ends {check.end_m:.2f} m from it; "
          "a real robot drifts more: watch it, and re-centre it in a pause")
    if csv:
        with atomic(args.out) as tmp:
            write_csv(tmp, proto)
    else:
        write_bag(args.out, proto, args.topic)
    print(f"wrote {args.out}")
    if args.json:
        write_json(args.json, {"schema": "sbmpc.protocol/1", "vehicle": vehicle.name, "terrain": terrain.name,
                               "area_m": list(area), "seconds": proto.seconds, "notes": list(proto.notes),
                               "parts": [{"kind": p.kind, "label": p.label, "v": p.v, "omega": p.omega,
                                          "seconds": p.seconds, "identifies": list(p.identifies)}
                                         for p in proto.parts],
                               "check": {"box_m": list(check.box), "reach_m": list(check.reach),
                                         "end_m": check.end_m, "training": check.training,
                                         "heldout": check.heldout, "fitted": check.chosen}})
    return 0


def _excited(check) -> None:
    """What calibrate's rules find in the simulated run's training and held-out parts."""
    from ..calibration import MIN_SECONDS, PARAMS
    tr, ho = check.training, check.heldout
    print(f"what calibrate sees in the simulated run (training part / held-out part; a parameter needs "
          f"{MIN_SECONDS:g} s):")
    rows = [("straight driving", "straight_s"), ("left turns", "left_turns_s"), ("right turns", "right_turns_s"),
            ("accelerations", "accelerations_s"), ("at the top speed", "top_speed_s")]
    for what, key in rows:
        print(f"  {what:18s} {tr[key]:6.1f} s / {ho[key]:5.1f} s")
    from ..calibration import chosen
    for what, exc in (("with efforts or currents logged", tr),
                      ("with wheel speeds only", {**tr, "efforts": False, "currents": False})):
        why = chosen(exc)
        fitted = [n for n in PARAMS if why[n] is True]
        kept = [n for n in PARAMS if why[n] is not True]
        print(f"  {what}: fitted {', '.join(fitted) or 'none'}"
              + (f"; kept at the prior {', '.join(kept)}" if kept else ""))
