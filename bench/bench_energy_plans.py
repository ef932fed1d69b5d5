"""Are the energy-optimal plans really cheaper? Every shipped scenario, measured at the
controller rate (the plans' 1 kHz replays, which is what every plan now reports).

For each scenario:

* the time and the energy plan as ``sbmpc compare`` reports them (each search's own
  plan, and which one was kept: compare adopts the other search's plan when it is
  better on the cost, ``found_by``);
* the energy plan's spread over Halton seeds 0-7 (each seed its own searches; the plan
  ``sbmpc plan --cost energy`` reports: the energy search's, or the time search's where
  that uses less energy, ``planner.energy_vs_time``), and the
  time plan's travel time for the same seeds (does every seed find a plan that holds
  at 1 kHz?), with both plans' re-plans after the 1 kHz check (``repairs``) and
  planning times;
* the energy plan of a long unweighted search (w = 1, 10 x the expansion budget, at
  most ``--long-time-s``, guided by the admissible grid alone: ``value: false``) as the
  reference for how much the weighted, anytime search loses (``--keep-reference``: the
  one in the results file, unchanged by the value).

    python bench/bench_energy_plans.py [--seeds 8] [--scenarios flat hill_tradeoff ...] [--long-time-s 600]

writes ``bench/results/energy_plans.json``. Energies in J, times in s, one run each.
"""
from __future__ import annotations

import argparse
import json
import statistics
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
import stamp  # noqa: E402  (bench/, beside this script)
OUT = ROOT / "bench" / "results" / "energy_plans.json"


def _summary(p) -> dict:
    return {"status": p.status, "energy_J": p.energy_J, "travel_time_s": p.travel_time_s,
            "expansions": p.nodes_expanded, "planning_time_s": round(p.planning_time_s, 3),
            "repairs": p.repairs, "found_by": p.found_by or f"{p.cost} search", "reason": p.reason,
            "polish": p.polish.to_json() if p.polish else None}


def main(argv=None) -> int:
    from sbmpc.planning import plan as PL
    from sbmpc.planning import world as WO
    from sbmpc import scenario as SC
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--scenarios", nargs="*", default=None)
    ap.add_argument("--long-time-s", type=float, default=600.0,
                    help="wall-clock budget of the long unweighted search [s]")
    ap.add_argument("--keep-reference", action="store_true",
                    help="take the long unweighted search's plan from the results file instead of searching again "
                         "(it is guided by the grid alone: the value does not change it; the model must be the same)")
    args = ap.parse_args(argv)
    stored = json.loads(OUT.read_text()).get("scenarios", {}) if args.keep_reference and OUT.exists() else {}
    names = args.scenarios or sorted(p.stem for p in (ROOT / "scenarios").glob("*.yaml") if p.stem != "unreachable")
    res = {"measured_at": "controller rate (1 kHz replays of the plans' controls)", "scenarios": {}}
    for name in names:
        scn = SC.load(ROOT / "scenarios" / f"{name}.yaml")
        world = WO.resolve(scn)
        both = PL.plan_both(world)
        row = {"reported": {c: _summary(p) for c, p in both.items()}}
        seeds, times, repairs, seconds, adopted = [], [], [], [], 0
        for s in range(args.seeds):
            w = WO.resolve(replace(scn, planner=replace(scn.planner, seed=s)))
            # the energy plan as ``sbmpc plan --cost energy`` reports it (plan.plan: checked
            # against the time plan), without searching for time twice
            pt = PL.search_plan(w, "time")
            pe = PL.cross_checked(PL.search_plan(w, "energy"), pt)
            adopted += bool(pe.found_by)
            seeds.append(pe.energy_J)
            times.append(pt.travel_time_s)
            repairs.append([pt.repairs, pe.repairs])
            seconds.append([round(pt.planning_time_s, 2), round(pe.planning_time_s, 2)])
        found = [e for e in seeds if e is not None]
        row["energy_by_seed_J"] = seeds
        row["time_plan_by_seed_s"] = times
        row["repairs_by_seed"] = repairs           # [time plan, energy plan]: re-plans after the 1 kHz check
        row["planning_s_by_seed"] = seconds        # [time search, energy plan (both searches where it is the time plan)], every core
        row["seeds_whose_energy_plan_is_the_time_plan"] = adopted
        if found:
            row["seed_spread_pct"] = round(100 * (max(found) - min(found)) / min(found), 2)
            row["seed_median_J"] = statistics.median(found)
        ps = scn.planner
        e = both["energy"].energy_J
        if name in stored and "unweighted_10x" in stored[name]:
            row["unweighted_10x"] = dict(stored[name]["unweighted_10x"], kept_from_results_file=True)
            ref_e = row["unweighted_10x"]["energy_J"]
        else:
            # A* with the admissible grid alone (the value is no bound), 10x the budget
            long = WO.resolve(replace(scn, planner=replace(ps, energy_weight=1.0, value=False,
                                                           max_expansions=10 * ps.max_expansions,
                                                           time_budget_s=args.long_time_s)))
            ref = PL.search_plan(long, "energy")
            row["unweighted_10x"] = _summary(ref)
            ref_e = ref.energy_J if ref.found else None
        if ref_e is not None and e is not None:
            row["reported_vs_unweighted_pct"] = round(100 * (e - ref_e) / ref_e, 2)
        t = both["time"].energy_J
        row["energy_plan_no_dearer_than_time_plan"] = (e is not None and t is not None and e <= t + 1e-9)
        res["scenarios"][name] = row
        print(name, json.dumps({k: v for k, v in row.items() if k != "reported"}), flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    if args.scenarios and OUT.exists():          # measured in parts: keep the others
        old = json.loads(OUT.read_text())
        res["scenarios"] = {**old.get("scenarios", {}), **res["scenarios"]}
    stamp.write(OUT, res)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
