"""Converged edges: does the planner's edge agree with the controller-rate solution, and
what does an edge cost?

    python bench/bench_edges.py                    # writes bench/results/edges.json
    python bench/bench_edges.py --baseline d8bfefd # cost per edge against that commit too

Agreement per terrain for --seed, and over --seeds seeds (default 4: 4 800 edges).

Convergence: ``--per-terrain`` random edges (default 200) on every shipped terrain,
``dynamics.convergence.random_edges``: entry at rest, moving and turning; commands over
the planner's whole sampled range (pivots included); grades up to the steepest
sustainable grade + 5 deg, both ways. Each is rolled out for one planning period at the
planner's step (0.02 s) and at the controller period (1 ms, the paper's 1 kHz digital
PID) and compared: stall verdict, energy, end pose. Then the same on the shipped hilly
maps (``--per-map`` edges on each, ``map_convergence``), through the planner's own edge,
where the grade changes along the way.

Cost: the planner's own expansion (``sbmpc.problems.skidsteer.expand``, all edges of a node) on
nodes spread over the hill_tradeoff map, timed in a child process per source tree;
with ``--baseline REV`` that commit is checked out into a temporary git worktree and the
two are timed alternately in one run (this machine's speed drifts), reported as the
median ratio over rounds. Twice: on random entries (a steady cruise at a random speed,
place and heading), and on nodes of each tree's own energy search (the first
SEARCH_EXPANSIONS expansions, ``cost_on_search_nodes``): the states a planner really
expands, mostly mid-transient, where a scheme that saves steady steps saves less.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
import stamp  # noqa: E402  (bench/, beside this script)
OUT = ROOT / "bench" / "results" / "edges.json"

TIMER = r'''
import sys, time, math
import numba
import numpy as np
numba.set_num_threads(1)               # one core (an expander may loop in parallel)
sys.path.insert(0, sys.argv[1])
# only the tree given: an editable install's finder would fill in the modules an old
# tree lacks from the working tree (a mix of the two)
sys.meta_path = [f for f in sys.meta_path if "editable" not in getattr(f, "__module__", "") + repr(f)]
sys.path_hooks = [h for h in sys.path_hooks if "editable" not in getattr(h, "__module__", "") + repr(h)]
sys.path_importer_cache.clear()
from sbmpc import scenario as SC
try:                                   # the layout since plan.py's split
    from sbmpc.planning import problem as PB, world as WO
    from sbmpc.problems import skidsteer as SS
except ImportError:
    try:                               # subpackages, the problem still in plan.py
        from sbmpc.planning import plan as PB, world as WO
        from sbmpc.problems import skidsteer as SS
    except ImportError:                # before the search's refactor (world and problem in plan.py)
        from sbmpc.planning import plan as PB
        WO = PB
        from sbmpc import skidsteer as SS
from dynamics import kernels as K
world = WO.resolve(SC.load(sys.argv[2]))
prob = PB.problem(world, "energy")
rng = np.random.default_rng(0)
X0 = prob.start
e = world.emap
x0, x1, y0, y1 = e.extent
states = []
if len(sys.argv) > 4:                  # the search's own nodes: its first argv[4] expansions
    try:
        from sbmpc.search.astar import Search
    except ImportError:
        from sbmpc.astar import Search
    search = Search(prob)
    res = search.run(int(sys.argv[4]))
    pick = np.random.default_rng(1).choice(res.nodes, min(int(sys.argv[3]), res.nodes), replace=False)
    states = [search.X[i].copy() for i in pick]
for i in range(0 if states else int(sys.argv[3])):
    x = rng.uniform(x0 + 2, x1 - 2); y = rng.uniform(y0 + 2, y1 - 2); yaw = rng.uniform(-math.pi, math.pi)
    v = rng.uniform(0.0, 0.8)
    p, _ = e.pitch_roll(x, y, yaw, world.half_length, world.half_width)
    w = v / world.vehicle.wheel_radius
    S = world.model(x, y).state(w, w, p, x, y, yaw, e.height(x, y))
    X = X0.copy(); X[:K.NS] = S; X[SS.X_YAWW] = yaw; X[SS.X_V] = v
    states.append(X)
C = prob.controls[:prob.branching]
children = np.empty((C.shape[0], X0.size)); costs = np.empty(C.shape[0]); work = np.empty(0)
SS.expand(prob.params, prob.data, work, states[0], C, children, costs)
t0 = time.perf_counter()
for X in states:
    SS.expand(prob.params, prob.data, work, X, C, children, costs)
dt = time.perf_counter() - t0
print(dt / (len(states) * C.shape[0]))
'''


def convergence(per_terrain: int, dt: float, period: float, seed: int, seeds: int = 1) -> dict:
    """Per terrain for ``seed``; "all" over every terrain; with seeds > 1 also
    "all_seeds" over every terrain and the seeds seed .. seed + seeds - 1."""
    from dynamics.convergence import Agreement, compare, random_edges, shipped_models
    cat = lambda parts, f: np.concatenate([getattr(a, f) for a in parts])
    fields = ("stall_ref", "stall_agrees", "energy_ref", "energy_err", "pos_err", "yaw_err")
    out = {}
    agg = []
    for k in range(seeds):
        part = []
        for m in shipped_models():
            edges = random_edges(m, per_terrain, np.random.default_rng(seed + k))
            a = compare(edges, dt, period)
            part.append(a)
            if k == 0:
                out[m.terrain.name] = a.summary()
                print(m.terrain.name, out[m.terrain.name], flush=True)
        if k == 0:
            out["all"] = Agreement(*(cat(part, f) for f in fields)).summary()
            print("all", out["all"], flush=True)
        agg += part
    if seeds > 1:
        out["all_seeds"] = dict(Agreement(*(cat(agg, f) for f in fields)).summary(),
                                seeds=list(range(seed, seed + seeds)))
        print("all seeds", out["all_seeds"], flush=True)
    return out


MAP_SCENARIOS = ("hill_tradeoff", "steep_hill", "hills_field", "mixed_terrain", "narrow_pass")


def map_convergence(per_map: int, seed: int, period: float = 1.0) -> dict:
    """The planner's own edge (``problems.skidsteer.edge``: the map's grade under the
    vehicle changes along the edge) at the planner's step against 1 ms, on the shipped
    hilly maps: per map ``per_map`` edges from random places and headings (where the
    vehicle stands), entry at rest, moving or turning, commands uniform over the sampled
    wheel-speed range. The constant-grade edges of :func:`convergence` cannot show an
    error that grows with the grade's change along the way."""
    import math
    from dynamics import kernels as K
    from sbmpc import scenario as SC
    from sbmpc.planning import problem as PB, world as WO
    from sbmpc.problems import skidsteer as SS
    from dynamics.convergence import _feasible
    out, allrows = {}, []
    for name in MAP_SCENARIOS:
        world = WO.resolve(SC.load(ROOT / "scenarios" / f"{name}.yaml"))
        coarse = PB.pack_world(world, "energy")
        fine = PB.pack_world(world, "energy", 1.0 / world.vehicle.controller_rate)
        lo, hi = WO.wheel_speed_range(world)
        X0 = WO.start_state(world)
        e = world.emap
        x0, x1, y0, y1 = e.extent
        rng = np.random.default_rng(seed)
        rows = []
        while len(rows) < per_map:
            x, y = rng.uniform(x0 + 3, x1 - 3), rng.uniform(y0 + 3, y1 - 3)
            yaw = rng.uniform(-math.pi, math.pi)
            pitch, roll = e.pitch_roll(x, y, yaw, world.half_length, world.half_width)
            if max(abs(pitch), abs(roll)) > math.radians(world.scenario.planner.tip_over_deg) - 0.05:
                continue
            kind = len(rows) % 3
            wl, wr = (0.0, 0.0) if kind == 0 else ((w := rng.uniform(0.1, 0.9) * hi), w) if kind == 1 \
                else tuple(rng.uniform(lo, hi, size=2))
            X = X0.copy()
            model = world.model(x, y)
            # a steady entry the drive cannot hold enters at its limit (as in convergence)
            X[:K.NS] = _feasible(model, model.state(wl, wr, pitch, x, y, yaw, e.height(x, y)))
            X[SS.X_YAWW] = yaw
            cl, cr = rng.uniform(lo, hi, size=2)
            ends = []
            for Q, data in (coarse, fine):
                S = X.copy()
                end, _ = SS.edge(Q, data, S, cl, cr, round(period / Q[SS.Q_DT]), np.zeros((0, K.NR)), 0, np.empty(K.NO))
                ends.append((end, S))
            (ec, Sc), (ef, Sf) = ends
            if ec == SS.IN_GOAL or ef == SS.IN_GOAL or -SS.OFF_MAP in (ec, ef):
                continue
            de = Sf[K.S_E] - X[K.S_E]
            rows.append((ec < 0, ef < 0, abs(Sc[K.S_E] - Sf[K.S_E]) <= max(0.02 * abs(de), 0.05),
                         math.hypot(Sc[K.S_X] - Sf[K.S_X], Sc[K.S_Y] - Sf[K.S_Y]),
                         math.degrees(math.remainder(Sc[K.S_YAW] - Sf[K.S_YAW], 2 * math.pi)),
                         math.degrees(Sf[K.S_YAW] - X[K.S_YAW])))
        allrows += rows
        out[name] = _map_summary(rows)
        print(name, out[name], flush=True)
    out["all"] = _map_summary(allrows)
    print("all maps", out["all"], flush=True)
    return out


def _map_summary(rows) -> dict:
    r = np.array(rows, float)
    both = (r[:, 0] == 0) & (r[:, 1] == 0)
    pos, yaw, turn = r[both, 3], r[both, 4], r[both, 5]
    return {"edges": len(r), "stall_agrees": round(float(np.mean(r[:, 0] == r[:, 1])), 4),
            "energy_within_2pct": round(float(np.mean(r[both, 2])), 4),
            "pose_within_5cm_2deg": round(float(np.mean((pos <= 0.05) & (np.abs(yaw) <= 2.0))), 4),
            "pos_err_mm_median_p99": [round(1e3 * float(np.median(pos)), 3), round(1e3 * float(np.quantile(pos, 0.99)), 3)],
            "yaw_err_deg_median_p99": [round(float(np.median(np.abs(yaw))), 5), round(float(np.quantile(np.abs(yaw), 0.99)), 4)],
            "yaw_err_over_turn_median": round(float(np.median(np.abs(yaw) / np.maximum(np.abs(turn), 0.1))), 5)}


SEARCH_EXPANSIONS = 5000   # the search whose nodes the second timer draws from


def edge_cost(baseline: str | None, rounds: int, nodes: int, search: bool = False) -> dict:
    scen = str(ROOT / "scenarios" / "hill_tradeoff.yaml")
    trees = {"current": str(ROOT)}
    tmp = None
    if baseline:
        tmp = tempfile.mkdtemp(prefix="sbmpc-baseline-")
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", tmp, baseline],
                       check=True, capture_output=True)
        trees["baseline"] = tmp
    try:
        times: dict = {k: [] for k in trees}
        extra = [str(SEARCH_EXPANSIONS)] if search else []
        for _name, tree in trees.items():     # warm-up: compile and cache each tree
            subprocess.run([sys.executable, "-c", TIMER, tree, scen, "4"] + extra, check=True, capture_output=True)
        for _ in range(rounds):
            for name, tree in trees.items():
                r = subprocess.run([sys.executable, "-c", TIMER, tree, scen, str(nodes)] + extra, check=True,
                                   capture_output=True, text=True)
                times[name].append(float(r.stdout.strip().splitlines()[-1]))
        res = {k: {"us_per_edge_median": round(1e6 * float(np.median(v)), 2),
                   "us_per_edge_all": [round(1e6 * x, 2) for x in v]} for k, v in times.items()}
        if baseline:
            ratios = np.array(times["current"]) / np.array(times["baseline"])
            res["baseline_rev"] = baseline
            res["ratio_current_to_baseline"] = {"median": round(float(np.median(ratios)), 3),
                                                "min": round(float(ratios.min()), 3),
                                                "max": round(float(ratios.max()), 3)}
        return res
    finally:
        if tmp:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", tmp], capture_output=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-terrain", type=int, default=200)
    ap.add_argument("--dt", type=float, default=0.02)
    ap.add_argument("--period", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--seeds", type=int, default=4, help="also aggregate this many seeds from --seed")
    ap.add_argument("--baseline", default=None, help="git revision to time against")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--nodes", type=int, default=300)
    ap.add_argument("--per-map", type=int, default=300, help="random edges on each shipped hilly map")
    args = ap.parse_args()
    if args.seeds < 1:
        ap.error("--seeds: expected at least 1")
    t0 = time.perf_counter()
    res = {"dt": args.dt, "period_s": args.period, "per_terrain": args.per_terrain, "seed": args.seed,
           "seeds": args.seeds,
           "convergence": convergence(args.per_terrain, args.dt, args.period, args.seed, args.seeds),
           "on_maps": map_convergence(args.per_map, args.seed, args.period)}
    res["cost"] = edge_cost(args.baseline, args.rounds, args.nodes)
    print("cost", res["cost"], flush=True)
    res["cost_on_search_nodes"] = edge_cost(args.baseline, args.rounds, args.nodes, search=True)
    print("cost on search nodes", res["cost_on_search_nodes"], flush=True)
    res["bench_s"] = round(time.perf_counter() - t0, 1)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    stamp.write(OUT, res)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
