"""Receding-horizon runs (``sbmpc run``): how long a run takes, what re-planning costs
against planning from scratch, and what a diagnosed model buys when the true vehicle
has a fault the planner's model does not know.

    python bench/bench_run.py     # writes bench/results/run.json and docs/run_faults.png

Faults: the right tyres 8 % smaller (``wheel_radius``) and a viscous drag of
0.2 N m s/rad per wheel (``viscous_friction``). For each, a 90 s measured-looking run of
the faulty vehicle (``dynamics.synth``) is diagnosed (``dynamics.discrepancy``) and the
scenario is run three times: planning with the baseline model, with the diagnosed
(extended) vehicle, and with the true vehicle itself. The default planner settings (every
core), numba warm.
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results" / "run.json"
import stamp  # noqa: E402  (bench/, beside this script)
FIG = ROOT / "docs" / "run_faults.png"
FAULTS = {"wheel_radius": {"scale_left": 1.0, "scale_right": 0.92}, "viscous_friction": {"c_Nms": 0.2}}
STUDY = (("flat", "time"), ("hill_tradeoff", "energy"), ("hills_field", "time"))


def summary(r, wall: float) -> dict:
    d = r.to_json()
    return {k: d[k] for k in ("status", "reason", "replans", "stalls", "periods", "planning_time_s",
                              "first_planning_time_s", "predicted", "executed", "prediction_error")} | {
        "mean_replan_time_s": (sum(d["replan_time_s"]) / len(d["replan_time_s"])) if d["replan_time_s"] else None,
        "wall_s": round(wall, 2)}


def timed_run(world, cost, truth=None, **kw):
    from sbmpc import receding as R
    t0 = time.perf_counter()
    r = R.run(world, cost, truth, **kw)
    return r, time.perf_counter() - t0


def main() -> int:
    from dynamics.discrepancy import diagnose
    from dynamics.synth import apply, synth_run
    from sbmpc.planning import world as WO
    from sbmpc import scenario as SC
    from sbmpc.figures import plot_runs

    def world(name):
        return WO.resolve(SC.load(ROOT / "scenarios" / f"{name}.yaml"))

    t0 = time.perf_counter()
    timed_run(world("flat"), "time")                       # compile / load the cache
    res: dict = {"warmup_s": round(time.perf_counter() - t0, 2), "perfect_model": {}, "faults": {}, "warm_vs_cold": {}}
    # 1. a full run on the 60 x 60 m field with a perfect model
    hf = world("hills_field")
    for cost in ("time", "energy"):
        r, wall = timed_run(hf, cost)
        res["perfect_model"][f"hills_field/{cost}"] = summary(r, wall)
        print("perfect", cost, res["perfect_model"][f"hills_field/{cost}"], flush=True)
    # 2. faults: baseline vs diagnosed vs true model
    figure_runs = None
    for effect, prm in FAULTS.items():
        for name, cost in STUDY:
            w = world(name)
            ground = w.terrains[0]
            truth = apply(w.vehicle, effect, prm, ground)[0]
            run, _ = synth_run(effect, 3, w.vehicle, ground, duration=90.0, params=prm)
            td = time.perf_counter()
            d = diagnose(run, w.vehicle, ground)
            entry = {"diagnosis": {"cause": d.cause, "gain": round(d.gain, 3),
                                   "params": d.candidates[0].params if d.candidates else {},
                                   "time_s": round(time.perf_counter() - td, 2)}}
            runs = {}
            for label, v in (("baseline", w.vehicle), ("diagnosed", d.extended_vehicle), ("true model", truth)):
                r, wall = timed_run(replace(w, vehicle=v), cost, truth)
                runs[label] = r
                entry[label] = summary(r, wall)
            res["faults"][f"{effect}/{name}/{cost}"] = entry
            print(effect, name, cost, {k: (v["status"], v["replans"], v["prediction_error"]) for k, v in entry.items()
                                       if k != "diagnosis"}, flush=True)
            if effect == "wheel_radius" and name == "hill_tradeoff":
                figure_runs = (w, runs)
    # 3. re-planning every period: warm start (incumbent) vs from scratch
    w = world("hill_tradeoff")
    truth = apply(w.vehicle, "wheel_radius", FAULTS["wheel_radius"], w.terrains[0])[0]
    every = replace(w.scenario.run, trigger="every", max_replans=1000)
    for cost in ("time", "energy"):
        row = {}
        for label, warm in (("warm", True), ("cold", False)):
            r, wall = timed_run(w, cost, truth, settings=every, warm=warm)
            row[label] = summary(r, wall)
        row["replan_time_ratio_warm_over_cold"] = (row["warm"]["mean_replan_time_s"] / row["cold"]["mean_replan_time_s"])
        row["replan_over_first_plan"] = row["warm"]["mean_replan_time_s"] / row["warm"]["first_planning_time_s"]
        res["warm_vs_cold"][f"hill_tradeoff/{cost}"] = row
        print("every period", cost, {k: (v["replans"], v["mean_replan_time_s"], v["executed"]) if isinstance(v, dict) else v
                                     for k, v in row.items()}, flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(OUT, res)
    if figure_runs:
        w, runs = figure_runs
        plot_runs(w.emap, runs, w.scenario, FIG, title="hill_tradeoff, energy cost: the true vehicle's right tyres "
                  "are 8 % smaller")
    print(f"wrote {OUT}" + (f" and {FIG}" if figure_runs else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
