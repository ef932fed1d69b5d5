"""The margin's allowance aside with and without the map's steepest-slope layer
(``maps.grid.steepest_near``): the whole-route search's time on one core, the same
search either way (the layer only skips the check where it cannot fail: the expansions
must match), interleaved rounds.

    taskset -c 0 python bench/bench_slope_layer.py            # writes bench/results/slope_layer.json

Per scenario and cost: the search alone (``Search.run``, one thread, no batch; not the
polish or the 1 kHz check), ``--rounds`` times each way (the order alternating round by round), the median and the ratio of the
medians (with the layer over without).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
import stamp  # noqa: E402  (bench/)

OUT = ROOT / "bench" / "results" / "slope_layer.json"
CASES = (("flat", "energy", False), ("hill_tradeoff", "energy", True), ("mixed_terrain", "energy", False),
         ("steep_hill", "energy", True), ("runup_ramp", "energy", True), ("narrow_pass", "time", True),
         ("hills_field", "time", True), ("hills_field", "energy", True))


def measure(name: str, cost: str, value: bool, rounds: int) -> dict:
    """One case: (seconds with, seconds without, expansions) over ``rounds`` interleaved
    rounds; ``value`` False plans without the value (a longer search: flat and
    mixed_terrain's energy searches are otherwise too short to time)."""
    import numpy as np

    import sbmpc
    from sbmpc.planning.problem import problem
    from sbmpc.planning.world import _start
    from sbmpc.problems import skidsteer as SS
    from sbmpc.search.astar import Search
    w = sbmpc.load_world(ROOT / "scenarios" / f"{name}.yaml", threads=1, **({} if value else {"value": False}))
    prob = problem(w, cost, _start(w, None))
    offs = prob.params[SS.Q_OFFS]
    got = {True: [], False: []}
    exp = set()
    Search(prob).run(200000, 300.0, batch=1, threads=1)      # compiled and warm
    for k in range(rounds):
        for on in ((True, False) if k % 2 == 0 else (False, True)):     # the order alternates
            prob.params[SS.Q_OFFS] = offs if on else -1
            t = time.perf_counter()
            r = Search(prob).run(200000, 300.0, batch=1, threads=1)
            got[on].append(time.perf_counter() - t)
            exp.add((r.status, r.iterations))
    if len(exp) != 1:
        raise SystemExit(f"{name} {cost}: the layer changed the search: {sorted(exp)}")
    a, b = float(np.median(got[True])), float(np.median(got[False]))
    return {"scenario": name, "cost": cost, "value": value, "expansions": exp.pop()[1],
            "with_s": [round(x, 4) for x in got[True]], "without_s": [round(x, 4) for x in got[False]],
            "median_with_s": round(a, 4), "median_without_s": round(b, 4), "ratio": round(a / b, 3)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args()
    rows = []
    for name, cost, value in CASES:
        row = measure(name, cost, value, a.rounds)
        print(row, flush=True)
        rows.append(row)
    stamp.write(a.out, {"what": "the allowance aside's check with and without the steepest-slope layer "
                                "(bench/bench_slope_layer.py; the search alone, one core)", "rounds": a.rounds,
                        "rows": rows})
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
