"""The model's compiled step against another revision's, in one process.

    python bench/bench_step.py --baseline e7c80a8      # writes bench/results/step.json

The baseline revision's ``dynamics`` package is extracted into a temporary folder as
``dynamics_base`` (with the top-level ``_jitcache`` of revisions that had one; kept in
the temporary folder with its compiled cache for the next run) and both are imported
side by side. Each rolls the P3-AT out on grass (``simulate``) over the same
random commands (holds of 2 s, -6 to 8 rad/s) on a random constant grade, at the
planner's step (20 ms, the continuous loop's SDIRK) and at the controller's (1 ms, the
digital PID and backward Euler). The outputs must be identical to the bit (a
restructuring of the step must not change a plan); the timings alternate between the
two, ``--rounds`` times, on one core, and the ratio current / baseline is reported as
the median over rounds with its quartiles (this machine's speed drifts; a ratio within
one run is what can be trusted).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results" / "step.json"
import stamp  # noqa: E402  (bench/, beside this script)


def extract(rev: str, dest: Path) -> None:
    """``dynamics`` of ``rev`` as ``dest/dynamics_base`` (and ``dest/_jitcache`` where the
    revision had that top-level package)."""
    files = subprocess.run(["git", "-C", str(ROOT), "ls-tree", "-r", "--name-only", rev, "dynamics", "_jitcache"],
                           check=True, capture_output=True, text=True).stdout.split()
    for f in files:
        target = dest / f.replace("dynamics/", "dynamics_base/", 1)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{f}"], check=True,
                                          capture_output=True).stdout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="git revision to compare with")
    ap.add_argument("--rounds", type=int, default=30)
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    rev = subprocess.run(["git", "-C", str(ROOT), "rev-parse", args.baseline], check=True, capture_output=True,
                         text=True).stdout.strip()
    tmp = Path(tempfile.gettempdir()) / f"sbmpc-step-{rev[:12]}"      # kept: its compiled cache too
    if not (tmp / "dynamics_base").is_dir():
        extract(rev, tmp)
    sys.path.insert(0, str(tmp))
    import numba
    numba.set_num_threads(1)
    import dynamics as CUR
    import dynamics_base as BASE
    rng = np.random.default_rng(0)
    rows = []
    for label, dt, n in (("planner step, 20 ms (SDIRK)", 0.02, 200_000), ("controller period, 1 ms", 0.001, 300_000)):
        hold = int(round(2.0 / dt))
        c = rng.uniform(-6.0, 8.0, size=(n // hold + 1, 2))
        cl, cr = np.repeat(c[:, 0], hold)[:n], np.repeat(c[:, 1], hold)[:n]
        pitch = np.full(n, np.deg2rad(rng.uniform(-8.0, 8.0)))
        runs = {}
        for name, pkg in (("current", CUR), ("baseline", BASE)):
            m = pkg.Model(pkg.load_vehicle("p3at"), pkg.load_terrain("grass"), dt)
            runs[name] = (pkg, m, pkg.simulate(m, cl, cr, pitch=pitch, dt=dt))     # compiles, or loads
        a, b = runs["current"][2], runs["baseline"][2]
        identical = set(a.data) == set(b.data) and all(np.array_equal(a.data[k], b.data[k]) for k in a.data)
        if hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[-1]})         # time on one core
        t = {"current": [], "baseline": []}
        for r in range(args.rounds):
            for name in (("current", "baseline") if r % 2 else ("baseline", "current")):
                pkg, m, _ = runs[name]
                t0 = time.perf_counter()
                pkg.simulate(m, cl, cr, pitch=pitch, dt=dt)
                t[name].append(time.perf_counter() - t0)
        ratio = np.array(t["current"]) / np.array(t["baseline"])
        row = {"case": label, "dt_s": dt, "steps": n, "identical_outputs": bool(identical),
               "us_per_step_median": {k: round(1e6 * float(np.median(v)) / n, 4) for k, v in t.items()},
               "ratio_current_to_baseline": {"median": round(float(np.median(ratio)), 3),
                                             "q25": round(float(np.quantile(ratio, 0.25)), 3),
                                             "q75": round(float(np.quantile(ratio, 0.75)), 3)}}
        rows.append(row)
        print(json.dumps(row), flush=True)
    res = {"baseline_rev": args.baseline, "rounds": args.rounds, "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(args.out, res, newline=True)
    print(f"wrote {args.out}")
    return 0 if all(r["identical_outputs"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
