"""The value over position and heading (``planner.value``, :mod:`sbmpc.planning.value`):
what it costs to build, and what it buys the searches.

    taskset -c 0 python bench/bench_value.py                 # build times and plans A/B, one core
    taskset -c 0 python bench/bench_value.py --builds-only   # the build times alone
    taskset -c 0 python bench/bench_value.py --replans 4 --scenarios steep_hill narrow_pass hills_field \
        --costs energy --out bench/results/value_replans.json  # re-plans of runs with drawn truths

Build: per shipped scenario and per generated hills field (routes of 70, 170, 340 and
500 m: squares of 60, 130, 250 and 360 m, ``bench_horizon``'s fields), the lattice's
states, the build's wall time on one core (the Dijkstra and the lattice states; the
motion tables are made once per vehicle and terrains and timed apart), twice, the
second reported (the first may load compiled code), and the value at the start
against the admissible grid's.

Plans: every shipped scenario, both costs, ``sbmpc plan``'s defaults on one thread,
with the value (the default) and as before it (:func:`before`: ``value: false`` and the
old weights), interleaved: the
planning time (the energy plan's includes its time plan and the polish), the cost
driven at 1 kHz, the expansions, whether the plan keeps the margin.

Writes bench/results/value.json.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))
import stamp  # noqa: E402  (bench/)
OUT = ROOT / "bench" / "results" / "value.json"
SCENARIOS = ("flat", "hill_tradeoff", "mixed_terrain", "steep_hill", "runup_ramp", "narrow_pass", "hills_field")
FIELDS = {70: 60, 170: 130, 340: 250, 500: 360}


def field(route: int):
    """A hills field for a route of about ``route`` m (bench_horizon's, with a 500 m one)."""
    import bench_horizon as BH
    BH.SIDES.setdefault(500, FIELDS[500])
    return BH.field_scenario(route)


def builds(names, routes) -> list:
    from sbmpc import scenario as SC
    from sbmpc.planning import motions as MO, problem as PB, value as VA, world as WO
    from sbmpc.problems import skidsteer as SS
    rows = []
    cases = [(n, SC.load(ROOT / "scenarios" / f"{n}.yaml")) for n in names] + \
            [(f"field_{r}m", field(r)) for r in routes]
    for name, scn in cases:
        world = WO.resolve(scn)
        t = time.perf_counter()
        MO.tables(world)
        tables_s = time.perf_counter() - t
        for cost in ("time", "energy"):
            VA.build(world, cost)
            v = VA.build(world, cost)
            X = WO.start_state(world)
            Q, data = PB.pack_world(world, cost, margin=True, grid=True)
            Q[SS.Q_OFFV] = -1
            anchor = float(SS.heuristic(Q, data, X) + Q[SS.Q_GOALGAP])
            at = v.at(scn.start["x"], scn.start["y"], math.radians(scn.start["yaw_deg"]))
            row = {"scenario": name, "cost": cost, "states": int(v.V.size), "shape": list(v.V.shape),
                   "cell_m": v.cell, "build_s": round(v.seconds, 4), "tables_s": round(tables_s, 4),
                   "us_per_state": round(1e6 * v.seconds / v.V.size, 3),
                   "value_at_start": round(at, 2), "grid_at_start": round(anchor, 2)}
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def before(name: str) -> dict:
    """The planner settings of the searches before the value (2026-12-05): the value off,
    and the weights it changed back at their old defaults where the scenario's file does
    not set them (energy_weight 1.1; the horizon's 1.3 and 1.15)."""
    import yaml
    own = (yaml.safe_load((ROOT / "scenarios" / f"{name}.yaml").read_text()).get("planner") or {})
    old = {"energy_weight": 1.1, "horizon_weight": 1.3, "horizon_energy_weight": 1.15}
    return {"value": False, **{k: v for k, v in old.items() if k not in own}}


def plans(names, costs) -> list:
    import sbmpc
    rows = []
    for name in names:
        for cost in costs:
            for value in (True, False):
                kw = {} if value else before(name)
                t = time.perf_counter()
                p = sbmpc.plan_scenario(ROOT / "scenarios" / f"{name}.yaml", cost, threads=1, **kw)
                wall = time.perf_counter() - t
                row = {"scenario": name, "cost": cost, "value": value, "found": p.found,
                       "planning_s": round(p.planning_time_s, 3), "wall_s": round(wall, 3),
                       "travel_time_s": round(p.travel_time_s, 3) if p.found else None,
                       "energy_J": round(p.energy_J, 2) if p.found else None,
                       "expansions": p.nodes_expanded,
                       "keeps_margin": (p.margin or {}).get("kept") if p.found else None,
                       "found_by": (p.found_by or "")[:120]}
                rows.append(row)
                print(json.dumps(row), flush=True)
    return rows


def replans(names, costs, draws: int, seed: int = 0) -> list:
    """Closed-loop runs (``sbmpc run``, whole-route plans) with drawn truths (mass and
    grip with 10 % relative sd, ``numpy`` seed ``seed``): every re-plan's planning time,
    and how the run ended."""
    import numpy as np

    from sbmpc import receding as R, scenario as SC
    from sbmpc.planning import world as WO
    rng = np.random.default_rng(seed)
    rows = []
    for name in names:
        world = WO.resolve(SC.load(ROOT / "scenarios" / f"{name}.yaml"))
        for _ in range(draws):
            mass, grip = (float(x) for x in 1.0 + 0.1 * rng.standard_normal(2))
            for cost in costs:
                t = time.perf_counter()
                r = R.run(world, cost, WO.heavier(world.vehicle, mass), truth_grip=grip)
                d = r.to_json()
                row = {"scenario": name, "cost": cost, "truth_mass": round(mass, 3), "truth_grip": round(grip, 3),
                       "status": d["status"], "reason": (d["reason"] or "")[:200] or None,
                       "first_plan_s": d["first_planning_time_s"],
                       "replan_s": [round(x, 3) for x in d["replan_time_s"]], "stalls": d["stalls"],
                       "travel_time_s": d["travel_time_s"], "energy_J": d["energy_J"],
                       "wall_s": round(time.perf_counter() - t, 2)}
                rows.append(row)
                print(json.dumps(row), flush=True)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--routes", nargs="*", type=int, default=sorted(FIELDS), choices=sorted(FIELDS))
    ap.add_argument("--costs", nargs="+", default=["time", "energy"])
    ap.add_argument("--builds-only", action="store_true")
    ap.add_argument("--replans", type=int, default=0, metavar="N",
                    help="only closed-loop runs with N drawn truths per scenario (mass, grip 10 %% sd): re-plan times")
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args()
    doc = {"command": "taskset -c 0 python bench/bench_value.py " + " ".join(sys.argv[1:])}     # + stamp.write's
    if a.replans:
        doc["replans"] = replans(a.scenarios, a.costs, a.replans)
        times = [x for r in doc["replans"] for x in r["replan_s"]]
        if times:
            import numpy as np
            doc["replan_p95_s"] = float(np.percentile(times, 95))
            doc["replan_median_s"] = float(np.median(times))
        stamp.write(a.out, doc, newline=True)
        print(f"wrote {a.out}")
        return 0
    doc["builds"] = builds(a.scenarios, a.routes)
    if not a.builds_only:
        doc["plans"] = plans(a.scenarios, a.costs)
    stamp.write(a.out, doc, newline=True)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
