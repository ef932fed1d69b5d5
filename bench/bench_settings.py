"""Planner settings side by side: for every shipped scenario, both costs and Halton seeds
0-7, each search's own plan (``sbmpc.planning.plan.search_plan``: the energy plan without its
check against the time plan) under each configuration, in one run.

    python bench/bench_settings.py --config hold_periods=1 --config hold_periods=2
    python bench/bench_settings.py --config period_s=1.0 --config period_s=2.0 --costs energy

writes ``bench/results/settings.json`` (or ``--out``): per configuration, scenario and cost the plans'
costs at the controller rate (energy [J] or travel time [s]) by seed, their median, the
spread (max - min) / min [%], the median expansions and planning time [s] (every
core; compare within one run). docs/performance.md#energy-plans quotes it.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results" / "settings.json"
import stamp  # noqa: E402  (bench/, beside this script)


def _config(text: str) -> dict:
    """'key=value,key=value' as planner overrides (numbers parsed as YAML would)."""
    import yaml
    out = {}
    for part in text.split(","):
        key, _, value = part.partition("=")
        out[key.strip()] = yaml.safe_load(value)
    return out


def main(argv=None) -> int:
    from sbmpc.planning import plan as PL
    from sbmpc import scenario as SC
    from sbmpc.planning import world as WO
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", action="append", required=True, help="planner overrides, e.g. hold_periods=2")
    ap.add_argument("--costs", nargs="+", default=["energy", "time"], choices=["energy", "time"])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--scenarios", nargs="*", default=None)
    ap.add_argument("--out", type=Path, default=OUT, help=f"results file (default {OUT.relative_to(ROOT)})")
    args = ap.parse_args(argv)
    names = args.scenarios or sorted(p.stem for p in (ROOT / "scenarios").glob("*.yaml") if p.stem != "unreachable")
    res = {"measured_at": "controller rate (1 kHz replays of the plans' controls)", "configs": {}}
    for text in args.config:
        over = _config(text)
        rows = res["configs"].setdefault(text, {})
        for name in names:
            scn = SC.load(ROOT / "scenarios" / f"{name}.yaml")
            for cost in args.costs:
                values, expansions, seconds = [], [], []
                for s in range(args.seeds):
                    w = WO.resolve(replace(scn, planner=replace(scn.planner, seed=s, **over)))
                    t = time.perf_counter()
                    p = PL.search_plan(w, cost)
                    seconds.append(round(time.perf_counter() - t, 3))
                    values.append((p.energy_J if cost == "energy" else p.travel_time_s) if p.found else None)
                    expansions.append(p.nodes_expanded)
                found = [v for v in values if v is not None]
                row = {"by_seed": values, "expansions_by_seed": expansions, "planning_s_by_seed": seconds,
                       "median": statistics.median(found) if found else None,
                       "spread_pct": round(100 * (max(found) - min(found)) / min(found), 2) if found else None,
                       "median_expansions": statistics.median(expansions),
                       "median_planning_s": statistics.median(seconds)}
                rows[f"{name}/{cost}"] = row
                print(text, name, cost, json.dumps({k: row[k] for k in ("median", "spread_pct", "median_expansions",
                                                                        "median_planning_s")}), flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(args.out, res)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
