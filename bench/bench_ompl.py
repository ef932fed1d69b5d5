"""SBMPC side by side with OMPL's control planners (oc.RRT, oc.KPIECE1) on the shipped
scenarios: same closed-loop model as the state propagator, same goal disc, same
wall-clock budget. Reports success rate, time to the first solution, and the travel
time and energy of each path re-simulated through the model.

    pip install ompl==2.0.1
    python bench/bench_ompl.py [--budget 10] [--seeds 3] [--scenarios flat hill_tradeoff ...]

Writes bench/results/ompl.json. How OMPL is set up:

* state: a real vector of the planner's full state (pose and the drive's internal state,
  as :mod:`sbmpc.problems.skidsteer`); every entry but (x, y, heading) is scaled by 1e-3, so that
  OMPL's sampling and nearest-neighbour distance act on the pose;
* controls: desired wheel speeds over the same range as SBMPC's samples, each held for
  one planning period (propagation step = period, min = max duration = 1 step);
* propagator: ``sbmpc.problems.skidsteer.propagate``, the very edge function the SBMPC search
  calls (through a Python callback); an invalid edge (off the map, stall, tip-over) makes
  an invalid state;
* goal: the scenario's disc (a GoalRegion with distance max(0, |xy - goal| - r)); a run
  counts as solved when its path ends in the disc, checked after every 0.25 s slice of
  solve() (so the time to the first solution is known to 0.25 s);
* KPIECE1 projects on (x, y).
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "results" / "ompl.json"
import stamp  # noqa: E402  (bench/, beside this script)
SCALE = 1e-3
DEFAULT_SCENARIOS = ("flat", "hill_tradeoff", "steep_hill", "mixed_terrain")


def ompl_plan(world, cost: str, planner_name: str, budget: float, seed: int) -> dict:
    from ompl import base as ob
    from ompl import control as oc
    from ompl import util as ou

    from dynamics import kernels as K
    from sbmpc.planning import check as CK, problem as PB
    from sbmpc.planning import world as WO
    from sbmpc.problems import skidsteer as SS

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(seed)
    prob = PB.problem(world, cost)
    Q, data = prob.params, prob.data
    n = SS.NX
    pose = (K.S_X, K.S_Y, SS.X_YAWW)
    scale = np.full(n, SCALE)
    scale[list(pose)] = 1.0
    space = ob.RealVectorStateSpace(n)
    b = ob.RealVectorBounds(n)
    x0, x1, y0, y1 = world.emap.extent
    lo = np.full(n, -1e9 * SCALE)
    hi = np.full(n, 1e9 * SCALE)
    lo[K.S_X], hi[K.S_X], lo[K.S_Y], hi[K.S_Y] = x0, x1, y0, y1
    lo[SS.X_YAWW], hi[SS.X_YAWW] = -math.pi, math.pi
    for i in range(n):
        b.setLow(i, float(lo[i]))
        b.setHigh(i, float(hi[i]))
    space.setBounds(b)
    space.registerDefaultProjection(ob.RealVectorOrthogonalProjectionEvaluator(space, [K.S_X, K.S_Y]))
    wlo, whi = WO.wheel_speed_range(world)
    cspace = oc.RealVectorControlSpace(space, 2)
    cb = ob.RealVectorBounds(2)
    cb.setLow(wlo)
    cb.setHigh(whi)
    cspace.setBounds(cb)
    ss = oc.SimpleSetup(cspace)
    edges = [0]
    buf = np.empty(n)
    out = np.empty(n)
    ctl = np.empty(2)

    def valid(state):
        return not math.isnan(state[K.S_X])

    def propagate(start, control, duration, result):
        for i in range(n):
            buf[i] = start[i] / scale[i]
        ctl[0], ctl[1] = control[0], control[1]
        c = SS.propagate(Q, data, buf, ctl, out)
        edges[0] += 1
        for i in range(n):
            result[i] = out[i] * scale[i]
        if c < 0:
            result[K.S_X] = math.nan

    ss.setStateValidityChecker(valid)
    ss.setStatePropagator(propagate)
    g = world.scenario.goal

    class Disc(ob.GoalRegion):
        def __init__(self, si):
            super().__init__(si)
            self.setThreshold(0.0)

        def distanceGoal(self, s):
            return max(0.0, math.hypot(s[K.S_X] - g["x"], s[K.S_Y] - g["y"]) - g["radius"])

    start = ss.getStateSpace().allocState()
    for i, v in enumerate(prob.start * scale):
        start[i] = float(v)
    ss.setStartState(start)
    si = ss.getSpaceInformation()
    ss.setGoal(Disc(si))
    si.setPropagationStepSize(world.scenario.planner.period_s)
    si.setMinMaxControlDuration(1, 1)
    ss.setPlanner(oc.RRT(si) if planner_name == "RRT" else oc.KPIECE1(si))
    def reached():
        if not ss.haveSolutionPath():
            return False
        path = ss.getSolutionPath()
        last = path.getState(path.getStateCount() - 1)
        return math.hypot(last[K.S_X] - g["x"], last[K.S_Y] - g["y"]) <= g["radius"]

    # solve in slices (the tree grows across calls) and check the path's end ourselves:
    # time to the first solution to 0.25 s
    t0 = time.perf_counter()
    exact = False
    while not exact and time.perf_counter() - t0 < budget:
        ss.solve(min(0.25, budget - (time.perf_counter() - t0)))
        exact = reached()
    elapsed = time.perf_counter() - t0
    res = {"planner": planner_name, "seed": seed, "solved": exact, "time_s": elapsed, "edges": edges[0]}
    if exact:
        path = ss.getSolutionPath()
        controls = [(path.getControl(i)[0], path.getControl(i)[1], world.scenario.planner.period_s)
                    for i in range(path.getControlCount())]
        traj, end, S, _ = CK.replay(world, cost, controls)
        res.update(travel_time_s=float(traj["t"][-1]), energy_J=float(traj["energy_J"][-1]), replay_end=end)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=10.0, help="wall-clock budget per plan [s]")
    ap.add_argument("--seeds", type=int, default=3, help="OMPL seeds per scenario and planner")
    ap.add_argument("--scenarios", nargs="*", default=list(DEFAULT_SCENARIOS))
    args = ap.parse_args(argv)
    try:
        import ompl  # noqa: F401
    except ImportError:
        print("bench_ompl: expected the ompl package (pip install ompl==2.0.1), found none", file=sys.stderr)
        return 2
    from dataclasses import replace

    from sbmpc.planning import plan as PL
    from sbmpc.planning import world as WO
    from sbmpc import scenario as SC
    PL.search_plan(WO.resolve(SC.load(ROOT / "scenarios" / "flat.yaml")), "time")     # warm numba
    out = {"budget_s": args.budget, "scenarios": {}}
    for name in args.scenarios:
        scn = SC.load(ROOT / "scenarios" / f"{name}.yaml")
        scn = replace(scn, planner=replace(scn.planner, time_budget_s=args.budget))
        world = WO.resolve(scn)
        rows = {}
        for cost in ("time", "energy"):
            p = PL.search_plan(world, cost)
            rows[f"SBMPC/{cost}"] = [{"solved": p.found, "time_s": p.planning_time_s, "edges": p.edges_simulated,
                                      "travel_time_s": p.travel_time_s, "energy_J": p.energy_J}]
        for pl in ("RRT", "KPIECE1"):
            rows[pl] = [ompl_plan(world, "time", pl, args.budget, seed) for seed in range(1, args.seeds + 1)]
        summary = {}
        for k, runs in rows.items():
            ok = [r for r in runs if r["solved"]]
            summary[k] = {"success": f"{len(ok)}/{len(runs)}",
                          "time_to_solution_s": statistics.median(r["time_s"] for r in ok) if ok else None,
                          "travel_time_s": statistics.median(r["travel_time_s"] for r in ok) if ok else None,
                          "energy_J": statistics.median(r["energy_J"] for r in ok) if ok else None}
        out["scenarios"][name] = {"runs": rows, "summary": summary}
        print(name, json.dumps(summary), flush=True)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(OUT, out)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
