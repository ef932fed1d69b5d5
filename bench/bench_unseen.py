"""Time against energy plans on maps no setting was tuned for: random hilly maps.

    python bench/bench_unseen.py             # writes bench/results/unseen.json
    python bench/bench_unseen.py --maps 4    # fewer maps (a quick look)
    taskset -c 0 python bench/bench_unseen.py --first 100 --maps 20 --threads 1 --out bench/results/unseen_value.json
                                             # a new family, one core (issue 59)

Each map is 30 x 30 m (0.25 m cells) with 8 random hills (0.4-2.0 m high, 2-5 m in
radius; ``random_hills`` with the map's number as its seed) on one shipped terrain
(asphalt, packed dirt, grass, concrete in turn), from (3, 3) heading 45 deg to a goal
disc of 0.6 m at (27, 27). Both costs are planned with the default settings (seed 0,
both cores) and every plan is the one driven at the 1 kHz controller rate. Per map:
each search's own plan (``sbmpc.planning.plan.search_plan``), whether the energy search's plan
costs more energy than the time search's, and the energy plan ``sbmpc plan --cost
energy`` reports (``sbmpc.planning.plan.plan``: checked against the time plan, the cheaper kept,
``planner.energy_vs_time``), with its planning time (both searches), and the planning
times. The summary: on how many maps the energy search's own plan and the reported
energy plan are no dearer than the time plan, the energy saved (median, spread), the
time it costs, and the planning times.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "bench" / "results" / "unseen.json"
import stamp  # noqa: E402  (bench/, beside this script)
TERRAINS = ("asphalt", "packed_dirt", "grass", "concrete")


def scenario(k: int) -> dict:
    return {"name": f"unseen_{k}", "terrain": TERRAINS[k % len(TERRAINS)], "vehicle": "p3at",
            "map": {"generate": {"size": [30, 30], "resolution": 0.25, "seed": k,
                                 "features": [{"type": "random_hills", "count": 8, "height": [0.4, 2.0],
                                               "radius": [2.0, 5.0]}]}},
            "start": {"x": 3.0, "y": 3.0, "yaw_deg": 45.0, "v": 0.0},
            "goal": {"x": 27.0, "y": 27.0, "radius": 0.6}}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", type=int, default=16)
    ap.add_argument("--first", type=int, default=0,
                    help="the first map's number (its generator seed): --first 100 --maps 20 is a family no "
                         "setting was tuned for")
    ap.add_argument("--threads", type=int, default=0, help="planner.threads (1: one core; 0: all)")
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args()
    from sbmpc.planning import plan as PL
    from sbmpc.planning import world as WO
    from sbmpc import scenario as SC
    t0 = time.perf_counter()
    flat = SC.load(ROOT / "scenarios" / "flat.yaml")
    for c in ("time", "energy"):                   # compile / load the cache
        PL.plan(WO.resolve(flat), c)
    rows = []
    for k in range(a.first, a.first + a.maps):
        d = scenario(k)
        if a.threads:
            d["planner"] = {"threads": a.threads}
        world = WO.resolve(SC.parse(d, f"unseen_{k}"))
        row = {"map": k, "terrain": TERRAINS[k % len(TERRAINS)]}
        own = {c: PL.search_plan(world, c) for c in ("time", "energy")}
        for c, p in own.items():
            row[c] = {"status": p.status, "reason": p.reason, "travel_time_s": p.travel_time_s,
                      "energy_J": p.energy_J, "planning_time_s": round(p.planning_time_s, 3),
                      "expansions": p.nodes_expanded}
        # what plan(world, "energy") reports, without searching for time twice
        rep = PL.checked_against_time(own["energy"], own["time"])
        row["energy_reported"] = {"status": rep.status, "found_by": rep.found_by or "energy search",
                                  "travel_time_s": rep.travel_time_s, "energy_J": rep.energy_J,
                                  "planning_time_s": round(rep.planning_time_s, 3)}
        t, e, r = row["time"], row["energy"], row["energy_reported"]
        if t["status"] == e["status"] == "found":
            row["energy_saved_pct"] = round(100.0 * (1.0 - e["energy_J"] / t["energy_J"]), 2)
            row["time_cost_pct"] = round(100.0 * (e["travel_time_s"] / t["travel_time_s"] - 1.0), 2)
            row["energy_search_no_dearer"] = e["energy_J"] <= t["energy_J"]
        if t["status"] == "found":
            row["energy_plan_no_dearer"] = r["status"] == "found" and r["energy_J"] <= t["energy_J"]
        rows.append(row)
        print(json.dumps(row), flush=True)
    both = [r for r in rows if "energy_saved_pct" in r]
    saved = [r["energy_saved_pct"] for r in both]
    rep = [round(100.0 * (1.0 - r["energy_reported"]["energy_J"] / r["time"]["energy_J"]), 2) for r in both]
    summary = {
        "maps": len(rows),
        "both_found": len(both),
        "neither_found": sum(r["time"]["status"] != "found" and r["energy"]["status"] != "found" for r in rows),
        "one_found": sum((r["time"]["status"] == "found") != (r["energy"]["status"] == "found") for r in rows),
        "energy_search_no_dearer": sum(r["energy_search_no_dearer"] for r in both),
        "time_found": sum(r["time"]["status"] == "found" for r in rows),
        "energy_plan_no_dearer": sum(r.get("energy_plan_no_dearer", False) for r in rows),
        "energy_saved_pct": {"median": statistics.median(saved), "min": min(saved), "max": max(saved)} if saved else None,
        "energy_plan_saved_pct": {"median": statistics.median(rep), "min": min(rep), "max": max(rep)} if rep else None,
        "time_cost_pct_median": statistics.median(r["time_cost_pct"] for r in both) if both else None,
        "planning_time_s_median": {c: statistics.median(r[c]["planning_time_s"] for r in rows)
                                   for c in ("time", "energy", "energy_reported")},
        "planning_time_s_max": {c: max(r[c]["planning_time_s"] for r in rows) for c in ("time", "energy", "energy_reported")},
    }
    res = {"settings": f"defaults (seed 0, {'one core' if a.threads == 1 else 'every core'}); maps {a.first}-{a.first + a.maps - 1}", "summary": summary, "maps": rows,
           "bench_s": round(time.perf_counter() - t0, 1)}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(a.out, res, newline=True)
    print(json.dumps(summary, indent=1))
    print("wrote", a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
