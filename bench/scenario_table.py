"""The README's table of shipped scenarios, from ``bench/results/planner.json`` (the
serial plans of ``python bench/bench_planner.py``: every number is a plan driven at the
vehicle's 1 kHz controller rate).

    python bench/scenario_table.py           # prints the markdown table
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SHOWS = {
    "flat": "sanity: level vinyl, 15 m",
    "hill_tradeoff": "crosses the hill (time) vs skirts it on its lower flank (energy)",
    "steep_hill": "a 26° hill (13.9° is the limit): every plan goes around",
    "runup_ramp": "a 20.6° ramp crossed only with momentum (0.7 m/s stalls)",
    "mixed_terrain": "a road around, a rough field across",
    "hills_field": "60 m x 60 m of hills, ridge and valley (branching 10, w 1.5 time, 1.2 energy)",
    "narrow_pass": "a ridge too steep to cross with one pass 1.5 m wide: both plans take the pass",
    "unreachable": "goal on a mesa with 72° cliffs",
}


def cell(r: dict) -> str:
    if r["status"] != "found":
        return "exit 1 with the reason"
    return f"{r['travel_time_s']:.1f} s, {r['energy_J']:.0f} J ({r['planning_time_s']:.2f} s to plan)"


def main() -> int:
    d = json.loads((ROOT / "bench" / "results" / "planner.json").read_text())
    print("| scenario | shows | time-optimal | energy-optimal |")
    print("|---|---|---|---|")
    for name, costs in d["scenarios"].items():
        t = costs["time"].get("serial", costs["time"])
        e = costs["energy"].get("serial", costs["energy"])
        tc, ec = cell(t), (cell(e) if t["status"] == "found" else "")
        if t["status"] == "found" and e["status"] == "found":
            # sbmpc compare keeps the better plan on each cost (plan.plan_both): say so
            if e["energy_J"] > t["energy_J"]:
                ec += f"; `compare` keeps the time plan's {t['energy_J']:.0f} J"
            if t["travel_time_s"] > e["travel_time_s"]:
                tc += f"; `compare` keeps the energy plan's {e['travel_time_s']:.1f} s"
        print(f"| `{name}` | {SHOWS.get(name, '')} | {tc} | {ec} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
