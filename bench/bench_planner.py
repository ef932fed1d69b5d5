"""Planner speed: planning time, expansions and edge rollouts per second on the shipped
scenarios (both costs), serial against parallel edges and a batched search, side by
side in one run; and how planning time grows with map size and branching factor.

    python bench/bench_planner.py            # writes bench/results/planner.json

Numba is warmed up first (one small plan of each cost and configuration). Per scenario
and cost, four configurations run one after another: ``serial`` (one thread, batch 1:
the serial A*, and the polish of energy plans on one thread too), ``threads`` (a node's edges on every core, batch 1), ``batch4`` and
``batch16`` (every core, the edges of the next node and of the 3 or 15 open nodes next
in line simulated together, those of the others kept for their expansion). All four
expand the same nodes: ``same_plan`` says whether the controls came out the same, and
``extra_edges`` how many more edges than the serial search a configuration simulated.
The speed-up is the ratio of planning times within that run (these machines are noisy:
compare ratios, not seconds across runs). Map size and branching rows use the default settings (every
core, batch 16). Each row is one search's plan (``sbmpc.planning.plan.search_plan``): ``sbmpc plan
--cost energy`` also runs the time search, to check its plan against
(``planner.energy_vs_time``), and takes the time row's planning time more.
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results" / "planner.json"
import stamp  # noqa: E402  (bench/, beside this script)


CONFIGS = {"serial": dict(threads=1, batch=1), "threads": dict(threads=0, batch=1), "batch4": dict(threads=0, batch=4),
           "batch16": dict(threads=0, batch=16)}


def row(plan) -> dict:
    t = plan.planning_time_s
    return {"status": plan.status, "planning_time_s": round(t, 3), "expansions": plan.nodes_expanded,
            "edges": plan.edges_simulated, "expansions_per_s": round(plan.nodes_expanded / t),
            "edges_per_s": round(plan.edges_simulated / t),
            "travel_time_s": plan.travel_time_s, "energy_J": plan.energy_J}


def main() -> int:
    from sbmpc.planning import plan as PL
    from sbmpc.planning import world as WO
    from sbmpc import scenario as SC
    import numba
    t0 = time.perf_counter()
    flat = SC.load(ROOT / "scenarios" / "flat.yaml")
    for cfg in CONFIGS.values():                  # compile / load the cache (energy: the polish too)
        for cost in ("time", "energy"):
            PL.search_plan(WO.resolve(replace(flat, planner=replace(flat.planner, **cfg))), cost)
    warm = time.perf_counter() - t0
    res: dict = {"cores": numba.config.NUMBA_NUM_THREADS, "configs": CONFIGS,
                 "warmup_s": round(warm, 2), "scenarios": {}, "map_size": [], "branching": []}
    for path in sorted((ROOT / "scenarios").glob("*.yaml")):
        scn = SC.load(path)
        out = {}
        for c in ("time", "energy"):
            plans = {k: PL.search_plan(WO.resolve(replace(scn, planner=replace(scn.planner, **cfg))), c)
                     for k, cfg in CONFIGS.items()}
            rows = {k: row(p) for k, p in plans.items()}
            s = rows["serial"]
            for k in list(CONFIGS)[1:]:
                r = rows[k]
                r["same_plan"] = plans[k].controls == plans["serial"].controls
                r["extra_edges"] = round(r["edges"] / s["edges"] - 1.0, 4) if s["edges"] else None
                if s["status"] == r["status"] == "found":
                    r["speedup"] = round(s["planning_time_s"] / r["planning_time_s"], 2)
                    key = "travel_time_s" if c == "time" else "energy_J"
                    r["cost_vs_serial"] = round(r[key] / s[key] - 1.0, 4)
            out[c] = rows
        res["scenarios"][path.stem] = out
        print(path.stem, json.dumps(out), flush=True)
    # growth with map size: the hills field's description scaled to L x L metres
    field = SC.load(ROOT / "scenarios" / "hills_field.yaml")
    for L in (20, 40, 60, 80):
        gen = dict(field.map_spec["generate"], size=[L, L])
        gen["features"] = [dict(gen["features"][0], count=int(round(24 * (L / 60) ** 2)))]
        scn = replace(field, map_spec={"generate": gen}, goal=dict(field.goal, x=L - 5.0, y=L - 5.0))
        world = WO.resolve(scn)
        r = {"size_m": L, **{c: row(PL.search_plan(world, c)) for c in ("time", "energy")}}
        res["map_size"].append(r)
        print("size", r, flush=True)
    # growth with the branching factor, on the hill trade-off
    hill = SC.load(ROOT / "scenarios" / "hill_tradeoff.yaml")
    for b in (8, 12, 16, 24, 32):
        world = WO.resolve(replace(hill, planner=replace(hill.planner, branching=b)))
        r = {"branching": b, **{c: row(PL.search_plan(world, c)) for c in ("time", "energy")}}
        res["branching"].append(r)
        print("branching", r, flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(OUT, res)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
