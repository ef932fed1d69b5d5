"""Whole-route planning time against route length (issue 44, item 3).

    taskset -c 0 python bench/bench_route.py          # margin 0: writes bench/results/route.json
    taskset -c 0 python bench/bench_route.py --seeds 7 --margins 0.1 --out bench/results/route_margin.json
    taskset -c 0 python bench/bench_route.py --polish every --routes 170 340 --seeds 7 --margins 0 0.1 \
        --costs energy                                  # the polish at every control: route_every.json
    taskset -c 0 python bench/bench_route.py --ab 3 --routes 170 340   # the time plan's check: route_ab.json

Plans ``sbmpc plan`` would make on fields of random hills at ``hills_field``'s density
(``bench_horizon.field_scenario``: routes of 70, 170 and 340 m, map seeds 7, 8 and 9),
both costs, on one thread, without the plans' margin (``planner.margin`` 0, as issue 44 measured; ``--margins``
0.1 as shipped). Recorded per plan: whether it was found, the planning time (the
time search the energy plan is checked against included), expansions, the polish's
seconds and gain, and the plan as driven at 1 kHz (travel time, energy). ``--polish
every`` runs the polish at every control whatever the plan's length (the polish before
long plans were polished at their head and tail only, :mod:`sbmpc.planning.polish`), to
compare plans and times against. Per cost and margin: the median planning time over the
seeds at each route length, and the slope of a least-squares line of planning time
against route length over the found plans (one map per seed and length: a map whose
goal lies by a steep flank costs its search more than any length does).

``--ab N``: energy plans only, each map N times with the time plan always checked at 1 kHz
(``plan.TIME_CHECK_SLACK`` 2, as before 2026-12-03) and N times as shipped (the time plan
checked only where it could be the energy plan), interleaved A B, B A, ...; per map the
median ratio of the two planning times (shipped / always checked), the plans' energies
and whether the time plan was checked; writes ``bench/results/route_ab.json``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
import stamp  # noqa: E402  (bench/)
OUT = ROOT / "bench" / "results" / "route.json"


def one(world, cost: str) -> dict:
    from sbmpc.planning import plan as PL
    t0 = time.perf_counter()
    p = PL.plan(world, cost)
    wall = time.perf_counter() - t0
    pol = p.polish.to_json() if p.polish is not None else None
    return {"status": p.status, "found_by": p.found_by, "planning_time_s": round(p.planning_time_s, 3),
            "wall_s": round(wall, 3), "expansions": p.nodes_expanded, "controls": len(p.controls or []),
            "travel_time_s": p.travel_time_s, "energy_J": p.energy_J, "polish": pol,
            "reason": (p.reason or "")[:200] or None}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--routes", nargs="*", type=int, default=[70, 170, 340])
    ap.add_argument("--seeds", nargs="*", type=int, default=[7, 8, 9], help="the fields' map seeds")
    ap.add_argument("--margins", nargs="*", type=float, default=[0.0])
    ap.add_argument("--costs", nargs="*", default=["time", "energy"])
    ap.add_argument("--polish", choices=["auto", "every"], default="auto")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--ab", type=int, default=0, metavar="N",
                    help="energy plans with and without the time plan's check, N pairs per map (module doc)")
    args = ap.parse_args()
    from bench_horizon import field_scenario
    from sbmpc.planning import polish as PO, world as WO
    from sbmpc.planning import plan as PL
    from sbmpc import scenario as SC
    if args.polish == "every":
        PO.EXACT_UP_TO = 1 << 30
    out = (args.out or (OUT if args.polish == "auto" else OUT.with_name("route_every.json"))).resolve()
    flat = SC.load(ROOT / "scenarios" / "flat.yaml")
    for cost in ("time", "energy"):                  # compile / load the cache
        PL.plan(WO.resolve(replace(flat, planner=replace(flat.planner, threads=1))), cost)
    if args.ab:
        return ab(args, out if args.out else OUT.with_name("route_ab.json"))
    rows = []
    for route in args.routes:
        for seed in args.seeds:
            scn = field_scenario(route, seed)
            for margin in args.margins:
                w = WO.resolve(replace(scn, planner=replace(scn.planner, threads=1, margin=margin)))
                for cost in args.costs:
                    r = {"route_m": route, "seed": seed, "margin": margin, "cost": cost, **one(w, cost)}
                    rows.append(r)
                    print(json.dumps(r)[:300], flush=True)
    slopes = {}
    for margin in args.margins:
        for cost in args.costs:
            sel = [r for r in rows if r["margin"] == margin and r["cost"] == cost]
            med = {route: float(np.median([r["planning_time_s"] for r in sel if r["route_m"] == route]))
                   for route in args.routes if any(r["route_m"] == route for r in sel)}
            pts = [(r["route_m"], r["planning_time_s"]) for r in sel if r["status"] == "found"]
            entry = {"median_s": med}
            if len({x for x, _ in pts}) >= 2:
                x, y = np.array(pts, float).T
                b, a = np.polyfit(x, y, 1)
                entry.update({"s_per_100m": round(100 * b, 3), "intercept_s": round(a, 3), "points": len(pts)})
            slopes[f"{cost}, margin {margin:g}"] = entry
    res = {"polish": args.polish, "head_tail": [PO.HEAD, PO.TAIL], "exact_up_to": PO.EXACT_UP_TO,
           "rows": rows, "slopes": slopes}
    stamp.write(out, res)
    print(json.dumps(slopes, indent=1))
    print("wrote", out.relative_to(ROOT))
    return 0


def ab(args, out: Path) -> int:
    """``--ab N`` (module doc): the time plan's 1 kHz check, always against as shipped."""
    from bench_horizon import field_scenario
    from sbmpc.planning import plan as PL, world as WO
    shipped = PL.TIME_CHECK_SLACK
    rows, summary = [], {}
    for route in args.routes:
        for seed in args.seeds:
            scn = field_scenario(route, seed)
            for margin in args.margins:
                w = WO.resolve(replace(scn, planner=replace(scn.planner, threads=1, margin=margin)))
                ratios = []
                for k in range(args.ab):
                    got = {}
                    for label in (("checked", "shipped") if k % 2 == 0 else ("shipped", "checked")):
                        PL.TIME_CHECK_SLACK = 2.0 if label == "checked" else shipped
                        t0 = time.perf_counter()
                        p = PL.plan(w, "energy")
                        got[label] = {"s": round(time.perf_counter() - t0, 3), "energy_J": p.energy_J,
                                      "time_plan_checked": (p.rival or {}).get("checked")}
                    PL.TIME_CHECK_SLACK = shipped
                    ratios.append(got["shipped"]["s"] / got["checked"]["s"])
                    rows.append({"route_m": route, "seed": seed, "margin": margin, "pair": k, **got})
                    print(json.dumps(rows[-1]), flush=True)
                summary[f"{route} m, map {seed}, margin {margin:g}"] = {
                    "ratio_median": round(float(np.median(ratios)), 3),
                    "ratio_range": [round(min(ratios), 3), round(max(ratios), 3)],
                    "checked_s_median": float(np.median([r["checked"]["s"] for r in rows[-args.ab:]])),
                    "shipped_s_median": float(np.median([r["shipped"]["s"] for r in rows[-args.ab:]])),
                    "same_energy": all(r["checked"]["energy_J"] == r["shipped"]["energy_J"] for r in rows[-args.ab:])}
    stamp.write(out, {"pairs": args.ab, "time_check_slack": shipped, "summary": summary, "rows": rows})
    print(json.dumps(summary, indent=1))
    print("wrote", out.relative_to(ROOT))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
