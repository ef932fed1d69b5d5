"""``sbmpc import``: public measured datasets into the run CSV (docs/formats.md)."""
from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .files import Outputs, atomic, path_arg

# DRIVE's terrains and the nearest shipped terrain (what `# terrain:` names)
DRIVE_TERRAINS = {"asphalt": "asphalt", "gravel": "packed_dirt", "sand": "grass"}


def add_parsers(sub):
    p = sub.add_parser("import", help="convert a public dataset's log into a run CSV for sbmpc diagnose",
                       description="Convert a public measured dataset into the run CSV of docs/formats.md, "
                       "with its metadata (# vehicle:, # terrain:, # note:), ready for sbmpc diagnose. "
                       "'drive': a Norlab DRIVE Clearpath Warthog windows CSV (github.com/norlab-ulaval/DRIVE, "
                       "converted from its pickles to CSV with one row per sample): the 2 s windows joined into one "
                       "timeline, the ICP pose chained, a segment where the log is not continuous. "
                       "'borealtc': a BorealTC Clearpath Husky pro_XX.csv (github.com/norlab-ulaval/BorealTC): "
                       "wheel speeds and motor currents; it logs no commands, so the measured wheel speeds stand in "
                       "for them, and its currents are magnitudes, kept so ('# currents: unsigned': the replay compares magnitudes). "
                       "'rosbag': a ROS 2 bag folder (sqlite3 or MCAP) or a ROS 1 .bag of a skid-steer robot "
                       "(/cmd_vel, /joint_states, /odom, /battery_state by default; --topics renames them; needs "
                       "pip install 'sbmpc[ros]'; docs/robot.md).")
    p.add_argument("dataset", choices=("drive", "borealtc", "rosbag"), help="the dataset the source comes from")
    p.add_argument("source", type=path_arg, help="the dataset's file (rosbag: the bag folder or .bag file)")
    p.add_argument("--out", type=path_arg, required=True, help="run CSV to write")
    p.add_argument("--terrain", help="terrain of the run: a DRIVE terrain (asphalt, gravel, sand) or a BorealTC one "
                   "(ASPHALT, FLOORING, ICE, MIXED, SANDY_LOAM, SNOW), written as the nearest shipped terrain, or any "
                   "shipped name or file (default: from the file's name, or for BorealTC its folder's)")
    p.add_argument("--vehicle", help="rosbag: the robot, a shipped vehicle name or YAML (its track and wheel radius "
                   "turn /cmd_vel into wheel speeds; written as # vehicle:)")
    p.add_argument("--topics", type=path_arg, help="rosbag: a topic map YAML (cmd_vel, joint_states, odom, battery, "
                   "left_joints, right_joints; docs/robot.md)")
    p.set_defaults(func=run_import)


def _datasets() -> dict:
    """Per dataset: (its name, what a source file is, its terrains -> the nearest shipped
    ones, the terrain a source names by default and what names it, the reader)."""
    from ..realdata import BOREALTC_TERRAINS, read_borealtc_run, read_drive_windows

    def drive_terrain(source: Path) -> tuple:
        stem = source.stem.lower()
        return next((k for k in DRIVE_TERRAINS if k in stem), None), f"the file name '{source.name}'"

    def borealtc_terrain(source: Path) -> tuple:
        folder = source.resolve().parent.name
        return (folder.upper() if folder.upper() in BOREALTC_TERRAINS else None), f"the folder name '{folder}'"

    return {"drive": ("DRIVE", "a DRIVE windows CSV", DRIVE_TERRAINS, drive_terrain, str.lower, read_drive_windows),
            "borealtc": ("BorealTC", "a BorealTC pro_XX.csv", BOREALTC_TERRAINS, borealtc_terrain, str.upper,
                         read_borealtc_run)}


def run_import(args) -> int:
    from dynamics.runs import RunError
    if args.dataset == "rosbag":
        return _import_rosbag(args)
    for flag in ("vehicle", "topics"):
        if getattr(args, flag) is not None:
            raise InputError(f"--{flag}: expected only with the rosbag dataset, found it with {args.dataset}")
    label, kind, known, named, key_of, read = _datasets()[args.dataset]
    Outputs([args.source]).file(args.out, "--out")
    if not args.source.is_file():
        found = "a folder" if args.source.is_dir() else "no such file"
        raise InputError(f"{args.source}: expected {kind} file, found {found}")
    name = args.terrain
    if name is None:
        name, namer = named(args.source)
        if name is None:
            raise InputError(f"--terrain: expected the run's terrain ({namer} names none of {', '.join(known)}), "
                             "found nothing")
    key = key_of(name)
    shipped = known.get(key, name)
    if key not in known:
        from dynamics import ParameterError, load_terrain
        try:
            load_terrain(name)
        except ParameterError:
            raise InputError(f"--terrain: expected a {label} terrain ({', '.join(known)}), or a shipped terrain name "
                             f"or terrain file, found {name!r}") from None
    if key not in known and Path(name).is_file():      # a terrain file: named from where the run CSV will be
        import os
        shipped = os.path.relpath(Path(name).resolve(), Path(args.out).resolve().parent)
    try:
        run = read(args.source, shipped)
    except RunError as exc:
        raise InputError(str(exc)) from None
    if key in known:
        run.meta["note"] = f"{run.meta.get('note', '')}; {label} terrain {key}, nearest shipped terrain {shipped}"
    return _written(args.out, run, f"{run.t[-1] - run.t[0]:.0f} s", f"vehicle {run.meta['vehicle']}, terrain {shipped}")


def _import_rosbag(args) -> int:
    from dynamics import ParameterError, load_terrain, load_vehicle
    from ..rosbag import read_bag, topic_map
    Outputs([args.source] + ([args.topics] if args.topics else [])).file(args.out, "--out")
    for flag in ("vehicle", "terrain"):
        if getattr(args, flag) is None:
            raise InputError(f"--{flag}: expected the robot's {flag} (a shipped name or a YAML file) for a ROS bag, "
                             "found nothing")
    try:
        vehicle = load_vehicle(args.vehicle)
    except ParameterError as exc:
        raise InputError(f"--vehicle: {exc}") from None
    try:
        load_terrain(args.terrain)
    except ParameterError as exc:
        raise InputError(f"--terrain: {exc}") from None
    run = read_bag(args.source, vehicle, args.terrain, args.vehicle, topic_map(args.topics))
    return _written(args.out, run, f"{run.t[-1] - run.t[0]:.1f} s",
                    f"vehicle {args.vehicle}, terrain {args.terrain}; {run.meta['note']}")


def _written(out, run, span: str, about: str) -> int:
    """Write the run CSV atomically and say what it holds: samples, ``span``, segments, ``about``."""
    from dynamics.runs import write_run
    with atomic(out) as tmp:
        write_run(tmp, run)
    print(f"wrote {out}: {len(run)} samples, {span}, {len(run.segments())} segment(s), {about}")
    return 0
