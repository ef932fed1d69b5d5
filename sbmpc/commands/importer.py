"""``sbmpc import``: public measured datasets into the run CSV (docs/formats.md)."""
from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from .files import Outputs, atomic

# DRIVE's terrains and the nearest shipped terrain (what `# terrain:` names)
DRIVE_TERRAINS = {"asphalt": "asphalt", "gravel": "packed_dirt", "sand": "grass"}


def add_parsers(sub):
    p = sub.add_parser("import", help="convert a public dataset's log into a run CSV for sbmpc diagnose",
                       description="Convert a public measured dataset into the run CSV of docs/formats.md, "
                       "with its metadata (# vehicle:, # terrain:, # note:), ready for sbmpc diagnose. "
                       "'drive': a Norlab DRIVE Clearpath Warthog windows CSV (github.com/norlab-ulaval/DRIVE, "
                       "converted from its pickles to CSV with one row per sample): the 2 s windows joined into one "
                       "timeline, the ICP pose chained, a segment where the log is not continuous.")
    p.add_argument("dataset", choices=("drive",), help="the dataset the source comes from")
    p.add_argument("source", type=Path, help="the dataset's file")
    p.add_argument("--out", type=Path, required=True, help="run CSV to write")
    p.add_argument("--terrain", help="terrain of the run: a DRIVE terrain (asphalt, gravel, sand: written as the "
                   "nearest shipped terrain) or any shipped name or file (default: from the file name)")
    p.set_defaults(func=run_import)


def run_import(args) -> int:
    from dynamics.runs import RunError, write_run
    from ..realdata import read_drive_windows
    Outputs([args.source]).file(args.out, "--out")
    if not args.source.is_file():
        raise InputError(f"{args.source}: expected a DRIVE windows CSV file, found no such file")
    name = args.terrain
    if name is None:
        stem = args.source.stem.lower()
        name = next((k for k in DRIVE_TERRAINS if k in stem), None)
        if name is None:
            raise InputError(f"--terrain: expected the run's terrain (the file name '{args.source.name}' names none "
                             f"of {', '.join(DRIVE_TERRAINS)}), found nothing")
    shipped = DRIVE_TERRAINS.get(name, name)
    try:
        run = read_drive_windows(args.source, shipped)
    except RunError as exc:
        raise InputError(str(exc)) from None
    if name in DRIVE_TERRAINS:
        run.meta["note"] = f"{run.meta.get('note', '')}; DRIVE terrain {name}, nearest shipped terrain {shipped}"
    with atomic(args.out) as tmp:
        write_run(tmp, run)
    segs = run.segments()
    print(f"wrote {args.out}: {len(run)} samples, {run.t[-1] - run.t[0]:.0f} s, {len(segs)} segment(s), "
          f"vehicle {run.meta['vehicle']}, terrain {shipped}")
    return 0
