"""Diagnosis speed: a 10-minute synthetic run at 100 Hz with a hidden effect, diagnosed on
one core (the quality bar: well under a minute). Writes bench/results/diagnose.json.

    python bench/bench_diagnose.py [--minutes 10]
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
    args = ap.parse_args(argv)
    from dynamics import load_terrain, load_vehicle
    from dynamics.discrepancy import diagnose
    from dynamics.synth import synth_run
    v, t = load_vehicle("p3at"), load_terrain("vinyl")
    warm, _ = synth_run("none", 1, duration=5.0)
    diagnose(warm, v, t)                                   # compile / load numba
    res = {"minutes": args.minutes, "runs": []}
    for effect in ("command_delay", "wheel_radius", "none"):
        run, hidden = synth_run(effect, 3, duration=60.0 * args.minutes)
        t0 = time.perf_counter()
        d = diagnose(run, v, t)
        el = time.perf_counter() - t0
        res["runs"].append({"effect": effect, "hidden": hidden, "samples": len(run), "cause": d.cause,
                            "fitted": d.candidates[0].params, "diagnosis_time_s": round(el, 2)})
        print(res["runs"][-1], flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(OUT, res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
