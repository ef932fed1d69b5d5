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
                       "timeline, the ICP pose chained, a segment where the log is not continuous. "
                       "'borealtc': a BorealTC Clearpath Husky pro_XX.csv (github.com/norlab-ulaval/BorealTC): "
                       "wheel speeds and motor currents; it logs no commands, so the measured wheel speeds stand in "
                       "for them, and its currents are magnitudes, signed here by the wheel's direction of travel.")
    p.add_argument("dataset", choices=("drive", "borealtc"), help="the dataset the source comes from")
    p.add_argument("source", type=Path, help="the dataset's file")
    p.add_argument("--out", type=Path, required=True, help="run CSV to write")
    p.add_argument("--terrain", help="terrain of the run: a DRIVE terrain (asphalt, gravel, sand) or a BorealTC one "
                   "(ASPHALT, FLOORING, ICE, MIXED, SANDY_LOAM, SNOW), written as the nearest shipped terrain, or any "
                   "shipped name or file (default: from the file's name, or for BorealTC its folder's)")
    p.set_defaults(func=run_import)


def run_import(args) -> int:
    from dynamics.runs import RunError, write_run
    from ..realdata import BOREALTC_TERRAINS, read_borealtc_run, read_drive_windows
    Outputs([args.source]).file(args.out, "--out")
    drive = args.dataset == "drive"
    kind = "a DRIVE windows CSV" if drive else "a BorealTC pro_XX.csv"
    if not args.source.is_file():
        raise InputError(f"{args.source}: expected {kind} file, found no such file")
    known = DRIVE_TERRAINS if drive else BOREALTC_TERRAINS
    name = args.terrain
    if name is None:
        where = args.source.stem.lower() if drive else args.source.resolve().parent.name
        name = next((k for k in known if (k in where if drive else k == where.upper())), None)
        if name is None:
            raise InputError(f"--terrain: expected the run's terrain (the {'file' if drive else 'folder'} name "
                             f"'{args.source.name if drive else where}' names none of {', '.join(known)}), "
                             "found nothing")
    key = name if drive else name.upper()
    shipped = known.get(key, name)
    try:
        run = read_drive_windows(args.source, shipped) if drive else read_borealtc_run(args.source, shipped)
    except RunError as exc:
        raise InputError(str(exc)) from None
    if key in known:
        run.meta["note"] = (f"{run.meta.get('note', '')}; {'DRIVE' if drive else 'BorealTC'} terrain {key}, "
                            f"nearest shipped terrain {shipped}")
    with atomic(args.out) as tmp:
        write_run(tmp, run)
    segs = run.segments()
    print(f"wrote {args.out}: {len(run)} samples, {run.t[-1] - run.t[0]:.0f} s, {len(segs)} segment(s), "
          f"vehicle {run.meta['vehicle']}, terrain {shipped}")
    return 0
