"""``sbmpc sweep``: many scenarios, costs, seeds, settings and vehicle variants in one
command, on Ray (:mod:`sbmpc.sweep`)."""
from __future__ import annotations

import sys

from ..errors import InputError
from .files import Outputs, path_arg


def add_parsers(sub):
    s = sub.add_parser("sweep", help="plan every combination of a sweep spec (on Ray) and tabulate the results",
                       description="Plan every combination of scenarios, costs, seeds, planner settings and "
                       "vehicle variants of a sweep spec YAML (docs/commands.md), optionally replaying each plan on "
                       "vehicles drawn from parameter distributions; rows stream into DIR/results.parquet, a summary "
                       "table is printed and DIR/summary.png drawn. Runs on Ray when it is installed "
                       "(pip install 'sbmpc[sweep]'), else one task after another.")
    s.add_argument("spec", type=path_arg, help="sweep spec YAML file")
    s.add_argument("--out", type=path_arg, required=True, help="output folder (created if missing)")
    s.add_argument("--workers", type=int, default=0, help="Ray workers on this machine (default: every core)")
    s.add_argument("--address", help="address of a running Ray cluster (default: start Ray on this machine)")
    s.add_argument("--resume", action="store_true", help="skip the tasks whose rows are already in --out")
    s.add_argument("--batch-size", type=int, default=0, help="tasks per Ray task (default: 1, or tasks / (64 x workers) where that is more)")
    s.add_argument("--serial", action="store_true", help="run the tasks one after another, without Ray")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.set_defaults(func=run_sweep)


def run_sweep(args) -> int:
    from .. import sweep as SW
    if not 0 <= args.workers <= 4096:
        raise InputError(f"--workers: expected an integer in [0, 4096], found {args.workers}")
    if not 0 <= args.batch_size <= 100000:
        raise InputError(f"--batch-size: expected an integer in [0, 100000], found {args.batch_size}")
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise InputError("sweep writes its results as Parquet tables, which need pyarrow: "
                         "pip install 'sbmpc[sweep]'") from None
    spec = SW.load_spec(args.spec)
    Outputs([args.spec] + list(spec["scenarios"]) + [p for p, _ in spec["families"]]).folder(
        args.out, "--out", ("results.parquet", "summary.png"))
    tasks = SW.tasks(spec)
    if not args.serial and SW._ray() is None:
        print("note: Ray is not installed (pip install 'sbmpc[sweep]'); running the tasks one after another",
              file=sys.stderr)

    def progress(done, total, elapsed):
        if not args.quiet:
            eta = elapsed / done * (total - done) if done else 0.0
            print(f"  {done}/{total} tasks, {elapsed:.0f} s, about {eta:.0f} s left", file=sys.stderr, flush=True)
    res = SW.execute(tasks, args.out, workers=args.workers, address=args.address, batch_size=args.batch_size,
                     resume=args.resume, progress=progress, use_ray=not args.serial)
    rows = res["rows"]
    print(f"{len(tasks)} tasks: {res['ran']} run ({res['engine']}, {res['workers']} worker"
          f"{'s' if res['workers'] != 1 else ''}, {res['wall_s']:.1f} s), {res['skipped']} already done")
    print(SW.summary_table(rows))
    SW.plot_summary(rows, args.out / "summary.png")
    errors = [r for r in rows if r["status"] == "error"]
    for r in errors[:5]:
        where = ", ".join(str(x) for x in (r["cost"] or "scenario's cost",
                                           None if r["family_seed"] is None else f"map seed {r['family_seed']}",
                                           None if r["seed"] is None else f"seed {r['seed']}", r["variant"])
                          if x is not None)
        print(f"error: {r['scenario']} [{where}]: {r['reason']}", file=sys.stderr)
    print(f"wrote {args.out / 'results.parquet'}, {args.out / 'summary.png'}")
    return 0
