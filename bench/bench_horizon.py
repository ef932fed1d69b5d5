"""Receding-horizon SBMPC (``planner.horizon_s``) against whole-route re-planning.

    python bench/bench_horizon.py                      # shipped scenarios and 70/170 m fields, both costs
    python bench/bench_horizon.py --fields --truths heavy slippery --out bench/results/horizon_truths.json
    taskset -c 0 python bench/bench_horizon.py --threads 1    # one core, as the targets are stated
    taskset -c 0 python bench/bench_horizon.py --threads 1 --fields --costs energy --seeds 8
                                                       # executed cost over seeds 0-7: horizon_seeds.json

For every scenario, cost and truth, two closed-loop runs of ``sbmpc run`` on the same
world: whole-route plans (today's default: a whole-route first plan, whole-route re-plans
where the vehicle leaves the tolerance) and horizon plans (``--horizon``, default 10 s).
Recorded: whether each reached the goal, its executed travel time and energy (the truth
at its 1 kHz controller rate), its stalls; for the horizon run every plan's wall-clock
time (the first one's includes the cost-to-go grid), the whole-route fallbacks and theirs;
for the whole-route run its first plan's and its re-plans' times.

Fields: random hills at ``hills_field``'s density (24 hills per 3 600 m^2, 0.5-3 m high),
start and goal 5 m in from opposite corners (routes of 70, 170, 340 m for squares of 60,
130, 250 m), ``hills_field``'s planner block. Truths: ``nominal`` (the planning vehicle),
``heavy`` (10 % heavier), ``slippery`` (10 % less grip).

Writes bench/results/horizon.json; ``--plot`` draws docs/horizon.png from it (the
latency histogram of every horizon plan and the executed cost of each case against the
whole-route run's).
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
OUT = ROOT / "bench" / "results" / "horizon.json"
import stamp  # noqa: E402  (bench/, beside this script)
FIG = ROOT / "docs" / "horizon.png"
SCENARIOS = ("flat", "hill_tradeoff", "mixed_terrain", "steep_hill", "runup_ramp", "narrow_pass", "hills_field")
SIDES = {70: 60, 170: 130, 340: 250, 500: 360}      # route [m] -> square side [m]
TRUTHS = {"nominal": (1.0, 1.0), "heavy": (1.1, 1.0), "slippery": (1.0, 0.9)}


def field_scenario(route: int, seed: int = 7):
    """A field of random hills for a route of about ``route`` m (module doc), drawn with
    the map generator's ``seed``."""
    import yaml

    from sbmpc import scenario as SC
    side = SIDES[route]
    d = yaml.safe_load((ROOT / "scenarios" / "hills_field.yaml").read_text())
    d["name"] = f"field_{route}m" if seed == 7 else f"field_{route}m_seed{seed}"
    d["map"]["generate"] = {"size": [side, side], "resolution": 0.5, "seed": seed, "features": [
        {"type": "random_hills", "count": int(round(24 * side * side / 3600)), "height": [0.5, 3.0],
         "radius": [2.5, 6.0]}]}
    d["goal"] = {"x": side - 5.0, "y": side - 5.0, "radius": 1.0}
    path = ROOT / "bench" / "results" / f".{d['name']}.yaml"
    path.write_text(yaml.safe_dump(d))
    try:
        return SC.load(path)
    finally:
        path.unlink()


def one_run(world, cost, truth: str) -> dict:
    from sbmpc import receding as R
    from sbmpc.planning.world import heavier
    mass, grip = TRUTHS[truth]
    vehicle = heavier(world.vehicle, mass) if mass != 1.0 else None
    t0 = time.perf_counter()
    r = R.run(world, cost, vehicle, truth_grip=grip)
    d = r.to_json()
    out = {"status": d["status"], "reason": (d["reason"] or "")[:300] or None, "travel_time_s": d["travel_time_s"],
           "energy_J": d["energy_J"], "stalls": d["stalls"], "periods": d["periods"],
           "wall_s": round(time.perf_counter() - t0, 2)}
    if "horizon" in d:
        hz = d["horizon"]
        out["horizon"] = hz
        out["plan_s"] = [round(p["planning_time_s"], 5) for p in d["plans"] if p["why"] == "start"
                         or not p["why"].endswith("whole-route plan") and "whole-route" not in p["why"]]
    else:
        out["first_plan_s"] = d["first_planning_time_s"]
        out["replan_s"] = d["replan_time_s"]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--fields", nargs="*", type=int, default=[70, 170], choices=sorted(SIDES))
    ap.add_argument("--costs", nargs="+", default=["time", "energy"])
    ap.add_argument("--truths", nargs="+", default=["nominal"], choices=sorted(TRUTHS))
    ap.add_argument("--horizon", type=float, default=10.0)
    ap.add_argument("--threads", type=int, default=None, help="planner.threads (1: one core)")
    ap.add_argument("--out", type=Path, default=OUT, help="results file (default bench/results/horizon.json; "
                    "the figure is drawn from that one only)")
    ap.add_argument("--plot", action="store_true", help="only draw docs/horizon.png from the results file")
    ap.add_argument("--seeds", type=int, default=0,
                    help="N > 0: horizon runs only, for Halton seeds 0..N-1 (planner.seed), and the spread of "
                         "their executed cost beside the whole-route energy plans' (bench/results/energy_plans.json); "
                         "writes --out (default bench/results/horizon_seeds.json)")
    args = ap.parse_args()
    if args.plot:
        plot(json.loads(OUT.read_text()))
        return 0
    from sbmpc import scenario as SC
    from sbmpc.planning import world as WO
    scns = [SC.load(ROOT / "scenarios" / f"{s}.yaml") for s in args.scenarios]
    scns += [field_scenario(r) for r in args.fields]
    if args.seeds > 0:
        return seeds(scns, args)
    rows = []
    for scn in scns:
        over = {} if args.threads is None else {"threads": args.threads}
        for cost in args.costs:
            for truth in args.truths:
                row = {"scenario": scn.name, "cost": cost, "truth": truth}
                for label, hz in (("whole_route", 0.0), ("horizon", args.horizon)):
                    world = WO.resolve(replace(scn, planner=replace(scn.planner, horizon_s=hz, **over)))
                    row[label] = one_run(world, cost, truth)
                w, h = row["whole_route"], row["horizon"]
                key = "travel_time_s" if cost == "time" else "energy_J"
                row["cost_ratio"] = (h[key] / w[key] if w["status"] == h["status"] == "reached" else None)
                rows.append(row)
                print(f"{scn.name:14} {cost:6} {truth:8} whole {w['status']:7} {w[key] or 0:9.1f}  "
                      f"horizon {h['status']:7} {h[key] or 0:9.1f}  ratio {row['cost_ratio'] or float('nan'):.3f}  "
                      f"first {h['horizon']['first_s'] * 1e3:.0f} ms p95 {h['horizon']['replan_p95_s'] * 1e3:.0f} ms "
                      f"fallbacks {h['horizon']['fallbacks']}", flush=True)
    lat = np.array([s for r in rows for s in r["horizon"]["plan_s"][1:]])
    firsts = np.array([r["horizon"]["horizon"]["first_s"] for r in rows])
    ratios = np.array([r["cost_ratio"] for r in rows if r["cost_ratio"] is not None])
    summary = {
        "cases": len(rows),
        "horizon_reached": sum(r["horizon"]["status"] == "reached" for r in rows),
        "whole_route_reached": sum(r["whole_route"]["status"] == "reached" for r in rows),
        "horizon_plans": int(lat.size),
        "replan_p50_s": float(np.median(lat)) if lat.size else None,
        "replan_p95_s": float(np.percentile(lat, 95)) if lat.size else None,
        "replan_within_0.1s": float(np.mean(lat <= 0.1)) if lat.size else None,
        "first_max_s": float(firsts.max()),
        "cases_with_fallback": sum(r["horizon"]["horizon"]["fallbacks"] > 0 for r in rows),
        "cost_ratio_median": float(np.median(ratios)) if ratios.size else None,
        "cost_ratio_range": [float(ratios.min()), float(ratios.max())] if ratios.size else None,
        "within_5pct": int(np.sum(ratios <= 1.05)),
    }
    stamp.write(args.out, {"horizon_s": args.horizon, "threads": args.threads, "summary": summary, "rows": rows})
    print(json.dumps(summary, indent=1))
    if args.out == OUT:
        plot(json.loads(OUT.read_text()))
    return 0


def seeds(scns, args) -> int:
    """Item 4 of issue 44: the spread over Halton seeds of executed receding-horizon runs
    (the truth the planning model), beside the spread of the whole-route energy plans."""
    from sbmpc.planning import world as WO
    out = args.out if args.out != OUT else OUT.with_name("horizon_seeds.json")
    plans = json.loads((ROOT / "bench" / "results" / "energy_plans.json").read_text())["scenarios"]
    over = {} if args.threads is None else {"threads": args.threads}
    rows, summary = [], {}
    for scn in scns:
        for cost in args.costs:
            key = "travel_time_s" if cost == "time" else "energy_J"
            got = []
            for seed in range(args.seeds):
                world = WO.resolve(replace(scn, planner=replace(scn.planner, horizon_s=args.horizon, seed=seed,
                                                                **over)))
                r = one_run(world, cost, "nominal")
                rows.append({"scenario": scn.name, "cost": cost, "seed": seed, **r})
                if r["status"] == "reached":
                    got.append(r[key])
                print(f"{scn.name:14} {cost:6} seed {seed} {r['status']:8} {r[key] or 0:9.1f} "
                      f"fallbacks {r['horizon']['fallbacks']}", flush=True)
            pl = plans.get(scn.name, {})
            summary[f"{scn.name} {cost}"] = {
                "reached": len(got), "runs": args.seeds,
                "median": float(np.median(got)) if got else None,
                "spread_pct": round(100 * (max(got) - min(got)) / min(got), 2) if got else None,
                "whole_route_plans_spread_pct": pl.get("seed_spread_pct") if cost == "energy" else None,
                "whole_route_plans_median_J": pl.get("seed_median_J") if cost == "energy" else None}
    stamp.write(out, {"horizon_s": args.horizon, "threads": args.threads, "seeds": args.seeds, "summary": summary,
                      "rows": rows})
    print(json.dumps(summary, indent=1))
    return 0


def plot(d: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = d["rows"]
    lat = np.array([s for r in rows for s in r["horizon"]["plan_s"][1:]])
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    bins = np.logspace(-4, 0.5, 40)
    a.hist(np.clip(lat, 1e-4, None), bins=bins, color="#4477aa")
    a.axvline(0.1, color="k", ls="--", lw=1)
    a.set_xscale("log")
    a.set_xlabel("horizon plan wall-clock time [s]")
    a.set_ylabel("plans")
    s = d["summary"]
    a.set_title(f"{s['horizon_plans']} horizon plans ({d['horizon_s']:g} s ahead): median "
                f"{s['replan_p50_s'] * 1e3:.0f} ms, p95 {s['replan_p95_s'] * 1e3:.0f} ms", fontsize=9)
    labels = [f"{r['scenario']} {r['cost'][0]}" + ("" if r["truth"] == "nominal" else f" {r['truth']}") for r in rows]
    vals = [r["cost_ratio"] if r["cost_ratio"] is not None else np.nan for r in rows]
    colors = ["#cc6677" if r["horizon"]["status"] != "reached" else
              ("#ddcc77" if r["horizon"]["horizon"]["fallbacks"] else "#117733") for r in rows]
    y = np.arange(len(rows))
    b.barh(y, [v if np.isfinite(v) else 0 for v in vals], color=colors)
    b.axvline(1.0, color="k", lw=1)
    b.axvline(1.05, color="k", ls="--", lw=1)
    b.set_yticks(y, labels, fontsize=7)
    b.invert_yaxis()
    b.set_xlabel("executed cost, horizon / whole-route run")
    b.set_title("green: horizon plans only; yellow: with a whole-route fallback; red: failed", fontsize=9)
    fig.tight_layout()
    fig.savefig(FIG, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
