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
                       "for them, and its currents are magnitudes, signed here by the wheel's direction of travel.")
    p.add_argument("dataset", choices=("drive", "borealtc"), help="the dataset the source comes from")
    p.add_argument("source", type=path_arg, help="the dataset's file")
    p.add_argument("--out", type=path_arg, required=True, help="run CSV to write")
    p.add_argument("--terrain", help="terrain of the run: a DRIVE terrain (asphalt, gravel, sand) or a BorealTC one "
                   "(ASPHALT, FLOORING, ICE, MIXED, SANDY_LOAM, SNOW), written as the nearest shipped terrain, or any "
                   "shipped name or file (default: from the file's name, or for BorealTC its folder's)")
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
    from dynamics.runs import RunError, write_run
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
    with atomic(args.out) as tmp:
        write_run(tmp, run)
    segs = run.segments()
    print(f"wrote {args.out}: {len(run)} samples, {run.t[-1] - run.t[0]:.0f} s, {len(segs)} segment(s), "
          f"vehicle {run.meta['vehicle']}, terrain {shipped}")
    return 0
