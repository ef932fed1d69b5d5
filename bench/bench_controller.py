"""How long a robot's loop waits on the controller: ``Controller.step`` latency at 0.1 s.

A robot calls :class:`sbmpc.robot.Controller` every control period and must get its
command back well within it, while the planning runs in the controller's worker threads
on the same core. Here the controller drives the simulated truth (the scenario's own
vehicle, at its controller rate) in real time: every 0.1 s of wall-clock time one
``step`` (timed), then the truth driven for 0.1 s (not timed: a robot's motors do that),
then a sleep to the next tick. Nothing waits on a plan (``lockstep`` off): where a plan
is not ready the controller holds the wheels at rest and says so (``waiting``). Run it
on one core (``taskset -c 0``) with nothing else running.

Per scenario: the latency histogram, median / 95th percentile / max [ms], the steps by
status, whether the run reached the goal (each run capped at ``--cap`` seconds of driving).
Writes bench/results/controller.json and docs/controller_latency.png.

    taskset -c 0 python bench/bench_controller.py [--cap 90] [--scenarios ...] [--field 340]
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
import stamp  # noqa: E402  (bench/, beside this script)
OUT = ROOT / "bench" / "results" / "controller.json"
FIG = ROOT / "docs" / "controller_latency.png"
SCENARIOS = ("flat", "hill_tradeoff", "mixed_terrain", "steep_hill", "runup_ramp", "narrow_pass", "hills_field")
BINS_MS = [0, 1, 2, 5, 10, 20, 50, 100, 1000]


def one(world, cost: str, period: float, cap: float, beside: bool | None = None) -> dict:
    from dynamics import kernels as K
    from sbmpc import receding as R
    from sbmpc.planning import world as WO
    from sbmpc.problems import skidsteer as SS
    from sbmpc.robot import Controller
    t_build = time.perf_counter()
    ctrl = Controller(world, cost, period_s=period, beside=beside)
    build = time.perf_counter() - t_build
    real = R._Executor(world, cost)
    X = WO.start_state(world)
    statuses, end, stalled = [], 0, False
    t_next = time.perf_counter()
    try:
        while X[K.S_T] < cap:
            cmd = ctrl.step(float(X[K.S_T]), R.measured(X, world.vehicle, stalled))
            statuses.append(cmd.status)
            if cmd.done:
                break
            _, end, X = real.step(X, (cmd.wl, cmd.wr, period), record=False)
            stalled = end == -SS.STALL
            if stalled:
                R._protected(X, real)
            elif end != 0:
                break
            t_next += period
            time.sleep(max(0.0, t_next - time.perf_counter()))
    finally:
        ctrl.close()
    lat = np.array(ctrl.latencies) * 1e3
    hist, _ = np.histogram(lat, bins=BINS_MS)
    return {"status": "reached" if end == SS.IN_GOAL or ctrl.status == "reached" else
            ("stopped: " + (ctrl.reason or "")[:200] if ctrl.done else f"capped at {cap:g} s" if end == 0 else
             f"ended: {SS.CODES[-end - 1]}"),
            "driven_s": round(float(X[K.S_T]), 2),
            "to_goal_m": round(max(0.0, float(np.hypot(X[K.S_X] - world.scenario.goal["x"], X[K.S_Y] - world.scenario.goal["y"]))
                                   - world.scenario.goal["radius"]), 2), "steps": len(lat), "build_s": round(build, 3),
            "median_ms": round(float(np.median(lat)), 3), "p95_ms": round(float(np.percentile(lat, 95)), 3),
            "max_ms": round(float(lat.max()), 3), "over_period": int((lat > 1e3 * period).sum()),
            "histogram": {"bins_ms": BINS_MS, "counts": hist.tolist()},
            "statuses": {s: statuses.count(s) for s in dict.fromkeys(statuses)},
            "plans": len(ctrl.plans), "fallbacks": ctrl.horizon.fallbacks, "energy_J": round(float(X[K.S_E]), 1),
            "rejoined": ctrl.horizon.rejoined, "beside_made": len(ctrl.horizon.beside_s)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", nargs="*", default=list(SCENARIOS))
    ap.add_argument("--field", type=int, nargs="*", default=[340], help="generated hills fields (bench_horizon's)")
    ap.add_argument("--cap", type=float, default=90.0, help="seconds of driving per run at most")
    ap.add_argument("--period", type=float, default=0.1)
    ap.add_argument("--horizon", type=float, default=10.0)
    ap.add_argument("--beside", choices=("off", "on"), default=None,
                    help="run.beside for every run (default: each scenario's own)")
    ap.add_argument("--results", default=None, help="results file name in bench/results (default controller.json; "
                    "another name draws no figure)")
    ap.add_argument("--plot-only", action="store_true", help="draw the figure from the results file")
    args = ap.parse_args()
    out = OUT if args.results is None else OUT.parent / args.results
    if args.plot_only:
        plot(json.loads(OUT.read_text()))
        return 0
    from dataclasses import replace
    from sbmpc import scenario as SC
    from sbmpc.planning import world as WO
    from bench_horizon import field_scenario
    worlds = [(n, SC.load(ROOT / "scenarios" / f"{n}.yaml")) for n in args.scenarios]
    worlds += [(f"field_{r}m", field_scenario(r)) for r in args.field]
    rows = {}
    for name, scn in worlds:
        scn = replace(scn, planner=replace(scn.planner, horizon_s=args.horizon))
        w = WO.resolve(scn)
        r = one(w, scn.cost, args.period, args.cap, None if args.beside is None else args.beside == "on")
        rows[name] = dict(r, cost=scn.cost)
        print(f"{name:14s} {scn.cost:6s} {r['status'][:40]:40s} steps {r['steps']:4d}  median {r['median_ms']:6.2f} ms  "
              f"p95 {r['p95_ms']:6.2f}  max {r['max_ms']:7.2f}  over {r['over_period']}  {r['statuses']}", flush=True)
    allat = {k: v for k, v in rows.items()}
    doc = {"what": "Controller.step latency at a 0.1 s control period, the controller driving the simulated truth "
                   "in real time, planning in its worker threads on the same core (bench/bench_controller.py)",
           "period_s": args.period, "horizon_s": args.horizon, "cap_s": args.cap,
           "beside": args.beside or "the scenarios' own", "runs": allat}
    stamp.write(out, doc)            # and doc gets its date, for the figure's title
    print(f"wrote {out}")
    if out == OUT:
        plot(doc)
    return 0


def plot(doc: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    runs = doc["runs"]
    fig, ax = plt.subplots(figsize=(8, 3.6))
    names = list(runs)
    edges = BINS_MS
    width = 0.8 / len(names)
    x = np.arange(len(edges) - 1)
    for i, n in enumerate(names):
        c = np.array(runs[n]["histogram"]["counts"], float)
        ax.bar(x + i * width - 0.4 + width / 2, c / max(c.sum(), 1) * 100, width, label=n)
    ax.set_xticks(x, [f"{a}-{b}" for a, b in zip(edges[:-1], edges[1:])])
    ax.set_xlabel("step latency [ms]")
    ax.set_ylabel("steps [%]")
    # the period: the boundary between the bins below and above it
    ax.axvline(np.searchsorted(edges, 1e3 * doc["period_s"]) - 0.5, color="k", ls="--", lw=0.8)
    ax.text(np.searchsorted(edges, 1e3 * doc["period_s"]) - 0.45, 90, f"the period, {1e3 * doc['period_s']:g} ms",
            fontsize=8)
    ax.set_title(f"Controller.step at {doc['period_s']:g} s, one core, planning beside it ({doc['date']})", fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(FIG, dpi=110)
    print(f"wrote {FIG}")


if __name__ == "__main__":
    sys.exit(main())
