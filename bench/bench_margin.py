"""Plans with margin (``planner.margin``): what the margin costs, and what it buys.

    python bench/bench_margin.py                       # every shipped scenario, both costs
    python bench/bench_margin.py --scenarios hills_field steep_hill --margins 0 0.05 0.1 0.2

For every scenario, cost and margin (Halton seed 0, default settings otherwise):

* the plan's travel time and energy at the controller rate, and its price against the
  plan without margin;
* p_stall and p_miss: the plan's controls replayed open loop at 1 kHz by ``samples``
  vehicles whose mass, mu_sa and mu_op are drawn around the nominal with relative
  standard deviations of 5 % and of 10 % (the draw of ``sbmpc sweep``'s robustness);
* closed loop: ``sbmpc run`` (receding horizon, re-planning from the measured state)
  with a true vehicle 10 % heavier, and with 10 % less grip (mu_sa and mu_op).

Writes bench/results/margin.json (one run, this machine; numba warm after the first plan).

    python bench/bench_margin.py --curve --seeds 3    # the README figure: docs/margin.png

``--curve``: time and energy plans of ``hills_field`` and ``steep_hill`` at margins 0 to
0.2 (p_stall under the 5 % draw, no runs) for Halton seeds 0 to ``--seeds`` - 1 (planner.seed),
written to bench/results/margin_curve.json and plotted as price against margin with
p_stall: the median over the seeds, the range as a band (each seed's price against the
same seed's plan without margin).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
OUT = ROOT / "bench" / "results" / "margin.json"
CURVE = ROOT / "bench" / "results" / "margin_curve.json"
import stamp  # noqa: E402  (bench/, beside this script)
FIG = ROOT / "docs" / "margin.png"
SCENARIOS = ("flat", "hill_tradeoff", "mixed_terrain", "steep_hill", "runup_ramp", "narrow_pass", "hills_field")


def closed_loop(world, cost, mass=1.0, grip=1.0) -> dict:
    from sbmpc import receding as R
    from sbmpc.planning.world import heavier
    truth = heavier(world.vehicle, mass) if mass != 1.0 else None
    t0 = time.perf_counter()
    r = R.run(world, cost, truth, truth_grip=grip)
    d = r.to_json()
    return {"status": d["status"], "reason": (d["reason"] or "")[:300] or None, "travel_time_s": d["travel_time_s"],
            "energy_J": d["energy_J"], "replans": d["replans"], "stalls": d["stalls"], "guarded": d["guarded"],
            "weaker_from_t": d["weaker_from_t"], "wall_s": round(time.perf_counter() - t0, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", nargs="+", default=list(SCENARIOS))
    ap.add_argument("--costs", nargs="+", default=["time", "energy"])
    ap.add_argument("--configs", nargs="+", default=["margin=0,margin_tip_deg=0", "default"],
                    help="planner settings to compare, each 'key=value,key=value' or 'default'")
    ap.add_argument("--samples", type=int, default=20)
    ap.add_argument("--seeds", type=int, default=1, help="Halton seeds 0..N-1 (planner.seed) of every plan")
    ap.add_argument("--resume", action="store_true", help="keep the rows --out holds already; plan the others")
    ap.add_argument("--no-runs", action="store_true", help="skip the closed-loop runs")
    ap.add_argument("--runs-only", action="store_true",
                    help="run again only the closed-loop runs of --out's rows (the plans' rows kept as they are)")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--curve", action="store_true", help="the README figure's sweep over the margin (module doc)")
    ap.add_argument("--replot", action="store_true", help="redraw docs/margin.png from bench/results/margin_curve.json")
    ap.add_argument("--table", action="store_true", help="print the markdown table of --out's results (docs/planner.md)")
    args = ap.parse_args()
    if args.table:
        print(table(json.loads(args.out.read_text())["rows"]))
        return 0
    if args.replot:
        d = json.loads(CURVE.read_text())
        # the rows' own stamps kept, else those of the commit that stored them (not today's)
        stamp.write(CURVE, {**stamp.stored(CURVE), **d, "curve": curve(d["rows"])})
        figure(d["rows"], FIG)
        return 0
    if args.curve:
        args.scenarios, args.out, args.no_runs = ["hills_field", "steep_hill"], CURVE, True
        args.configs = [f"margin={m},margin_tip_deg={t}" for m, t in ((0, 0), (0.05, 5), (0.1, 5), (0.15, 5), (0.2, 5))]
    from sbmpc import api
    from sbmpc.planning.margin import robustness
    old = json.loads(args.out.read_text()) if args.out.exists() else {}
    rows = {(r["scenario"], r["cost"], r["config"], r.get("seed", 0)): r for r in old.get("rows", [])}
    for name in args.scenarios:
        for cost in args.costs:
            if not args.runs_only:
                # rows of seeds beyond --seeds (an earlier run's) would mix into the medians
                for key in [k for k in rows if k[:2] == (name, cost) and k[2] in args.configs and k[3] >= args.seeds]:
                    del rows[key]
            for conf, seed in ((c, s) for c in args.configs for s in range(args.seeds)):
                if args.resume and not args.runs_only and (name, cost, conf, seed) in rows:
                    continue
                over = {} if conf == "default" else {k: float(v) for k, v in (kv.split("=") for kv in conf.split(","))}
                over["seed"] = seed
                w = api.load_world(ROOT / "scenarios" / f"{name}.yaml", **over)
                if args.runs_only:
                    row = rows.get((name, cost, conf, seed))
                    if row is None or row["status"] != "found":
                        continue
                    row["run_mass_1.1"] = closed_loop(w, cost, mass=1.1)
                    row["run_grip_0.9"] = closed_loop(w, cost, grip=0.9)
                    print(json.dumps({k: row.get(k, 0) for k in ("scenario", "cost", "config", "seed", "run_mass_1.1",
                                                                "run_grip_0.9")}),
                          flush=True)
                    _write(args, rows)
                    continue
                m = w.scenario.planner.margin
                from sbmpc.planning import plan as PL
                t0 = time.perf_counter()
                p = PL.plan(w, cost)
                row = {"scenario": name, "cost": cost, "config": conf, "seed": seed, "margin": m, "status": p.status,
                       "planning_time_s": round(time.perf_counter() - t0, 2), "expansions": p.nodes_expanded,
                       "travel_time_s": p.travel_time_s, "energy_J": p.energy_J,
                       "margin_report": p.margin}
                if p.found:
                    for sd in (0.05, 0.10):
                        row[f"draw_{round(sd * 100)}pct"] = robustness(w, cost, p.controls, args.samples, sd)
                    if not args.no_runs:
                        row["run_mass_1.1"] = closed_loop(w, cost, mass=1.1)
                        row["run_grip_0.9"] = closed_loop(w, cost, grip=0.9)
                rows[(name, cost, conf, seed)] = row
                print(json.dumps(row), flush=True)
                _write(args, rows)
    if args.curve:
        _write(args, rows)
        figure(list(rows.values()), FIG)
    return 0


def _write(args, rows: dict) -> None:
    stamp.write(args.out, {"samples": args.samples,
                           **({"seeds": args.seeds, "curve": curve(list(rows.values()))} if args.curve else {}),
                           "rows": list(rows.values())})


def table(rows: list) -> str:
    """docs/planner.md#margin's table (seed 0's rows): per scenario and cost, the plan without margin and
    with the default, their price, p_stall / p_tip under the 5 % and 10 % draws, and the
    closed-loop runs with a 10 % heavier vehicle and with 10 % less grip."""
    def cost(r):
        return r["travel_time_s"] if r["cost"] == "time" else r["energy_J"]

    def outcome(run):
        why = run.get("reason") or ""
        if run.get("status") == "reached":
            return "reached"
        if "tipped over" in why:
            return "**tipped over**"
        if why.startswith("stopped at"):          # the guard: it stops rather than tip over
            return "**stopped** (guard)"
        return "**failed**" if run else "-"

    def runs(r):
        return " / ".join(outcome(r.get(k, {})) for k in ("run_mass_1.1", "run_grip_0.9"))

    out = ["| scenario | cost | margin 0: cost, p_stall 5 % (10 %) | runs +10 % mass / -10 % grip | default: cost (price) | "
           "p_stall 5 % (10 %) | p_tip 5 % | runs +10 % mass / -10 % grip |", "|---|---|---|---|---|---|---|---|"]
    base = {(r["scenario"], r["cost"]): r for r in rows if r["margin"] == 0 and not r.get("seed")}
    for r in rows:
        if r.get("seed"):
            continue
        b = base.get((r["scenario"], r["cost"]))
        if r["margin"] == 0 or b is None or r["status"] != "found" or b["status"] != "found":
            continue
        unit = "s" if r["cost"] == "time" else "J"
        d5, d10, b5, b10 = r["draw_5pct"], r["draw_10pct"], b["draw_5pct"], b["draw_10pct"]
        out.append(f"| `{r['scenario']}` | {r['cost']} | {cost(b):.1f} {unit}, {b5['p_stall']:.2f} ({b10['p_stall']:.2f}) | "
                   f"{runs(b)} | {cost(r):.1f} {unit} ({100 * (cost(r) / cost(b) - 1):+.1f} %)"
                   f"{'' if r['margin_report']['kept'] else ' (no plan kept it)'} | "
                   f"{d5['p_stall']:.2f} ({d10['p_stall']:.2f}) | {d5['p_tip']:.2f} | {runs(r)} |")
    return "\n".join(out)


def curve(rows: list) -> dict:
    """Per (scenario, cost): [(margin, price median, min, max [%], p_stall median, min, max,
    seeds)] over the seeds whose plans at that margin and at margin 0 were both found; a
    seed's price is against its own plan without margin. Also the summary's numbers."""
    out = {}
    for name, cost in sorted({(r["scenario"], r["cost"]) for r in rows}):
        key = "travel_time_s" if cost == "time" else "energy_J"
        mine = [r for r in rows if (r["scenario"], r["cost"]) == (name, cost) and r["status"] == "found"]
        base = {r.get("seed", 0): r[key] for r in mine if r["margin"] == 0}
        pts = []
        for m in sorted({r["margin"] for r in mine}):
            at = [r for r in mine if r["margin"] == m and r.get("seed", 0) in base]
            if not at:
                continue
            price = np.array([100.0 * (r[key] / base[r.get("seed", 0)] - 1.0) for r in at])
            ps = np.array([r["draw_5pct"]["p_stall"] for r in at])
            pts.append((m, float(np.median(price)), float(price.min()), float(price.max()),
                        float(np.median(ps)), float(ps.min()), float(ps.max()), len(at)))
        out[f"{name} {cost}"] = pts
    return out


def figure(rows: list, path: Path) -> None:
    """Price of the margin (cost against the same seed's plan without it) and p_stall under
    the 5 % draw, against the margin, per scenario and cost: the median over the seeds,
    the range as a band."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    seeds = len({r.get("seed", 0) for r in rows})
    for (label, pts), style in zip(curve(rows).items(), ("o-", "s--", "^-", "v--")):
        if not pts:
            continue
        m, p, plo, phi, s, slo, shi, _ = (np.array(c) for c in zip(*pts))
        line, = a.plot(m, p, style, label=f"{label} plan")
        a.fill_between(m, plo, phi, color=line.get_color(), alpha=0.15)
        b.plot(m, s, style, color=line.get_color(), label=f"{label} plan")
        b.fill_between(m, slo, shi, color=line.get_color(), alpha=0.15)
    a.set_xlabel("planner.margin")
    a.set_ylabel("price: cost against margin 0 [%]")
    a.axhline(5, color="grey", lw=0.8, ls=":")
    b.set_xlabel("planner.margin")
    b.set_ylabel("p_stall (open loop, 5 % draw)")
    b.axhline(0.05, color="grey", lw=0.8, ls=":")
    a.legend(fontsize=8)
    a.grid(alpha=0.3)
    b.grid(alpha=0.3)
    fig.suptitle(f"Plans with margin: price and p_stall of 20 drawn vehicles; median over {seeds} seed"
                 f"{'s' if seeds > 1 else ''}, band: range", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    raise SystemExit(main())
