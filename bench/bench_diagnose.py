"""Diagnosis speed: a 10-minute synthetic run at 100 Hz with a hidden effect, diagnosed on
one thread and on one thread a core (the candidates fitted side by side; the quality bar:
well under a minute), the two one after the other on each run. Writes
bench/results/diagnose.json.

    python bench/bench_diagnose.py [--minutes 10] [--threads N]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
import stamp  # noqa: E402  (bench/, beside this script)
OUT = ROOT / "bench" / "results" / "diagnose.json"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--threads", type=int, default=0, help="the threads of the side-by-side diagnosis (0: one a core)")
    args = ap.parse_args(argv)
    import os
    threads = args.threads or os.cpu_count() or 1
    from dynamics import load_terrain, load_vehicle
    from dynamics.discrepancy import diagnose
    from dynamics.synth import synth_run
    v, t = load_vehicle("p3at"), load_terrain("vinyl")
    warm, _ = synth_run("none", 1, duration=5.0)
    diagnose(warm, v, t)                                   # compile / load numba
    res = {"minutes": args.minutes, "threads": threads, "runs": []}
    for effect in ("command_delay", "wheel_radius", "none"):
        run, hidden = synth_run(effect, 3, duration=60.0 * args.minutes)
        t0 = time.perf_counter()
        d = diagnose(run, v, t, threads=1)
        el = time.perf_counter() - t0
        t0 = time.perf_counter()
        dn = diagnose(run, v, t, threads=threads)
        el_n = time.perf_counter() - t0
        same = repr(dn.to_json()) == repr(d.to_json())     # (as text: a NaN field is never == itself)
        if not same:
            raise SystemExit(f"{effect}: the diagnosis on {threads} threads differs from the one on one thread")
        res["runs"].append({"effect": effect, "hidden": hidden, "samples": len(run), "cause": d.cause,
                            "fitted": d.candidates[0].params, "diagnosis_time_s": round(el, 2),
                            "diagnosis_time_threads_s": round(el_n, 2)})
        print(res["runs"][-1], flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(OUT, res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
