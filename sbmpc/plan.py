"""Planning a scenario: build the search problem of a world (:mod:`sbmpc.world`), search,
check the plan at the controller rate (and repair it), replay.

``plan(world, cost)`` returns a :class:`Plan` whose controls, replayed through the
closed-loop model over the map (:func:`replay`), reproduce its trajectory and end in
the goal; the plan's trajectory *is* that replay.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from dynamics import kernels as K
from dynamics.resistance import friction_table

from .heuristics import _bounds, _lowest_in_disc, _max_rise, cost_to_go, unreachable_reason
from .problems import skidsteer as SS
from .search.astar import Problem, Search, SearchResult
from .polish import Polished, polish
from .world import FIXED_CONTROLS, World, _start, capability, control_set, wheel_speed_range

RECORD_EVERY = 0.05   # s: trajectory samples in the plan JSON
SETTLE_DEPTH = 3      # edges from the start within which a child may stay in its parent's grid cell


def pack_world(world: World, cost: str, dt: float | None = None) -> tuple:
    """(params, data) flat arrays of :mod:`sbmpc.skidsteer` for a world and cost, with
    the edges integrated at ``dt`` [s] (default the planner's step)."""
    scn, e, v = world.scenario, world.emap, world.vehicle
    ps = scn.planner
    dt = ps.dt if dt is None else dt
    ny, nx = e.shape
    blocks = [np.concatenate([K.pack(v, t), friction_table(v, t)]) for t in world.terrains]
    parts = [e.heights.ravel()]
    offl = -1
    if e.terrain_layer is not None and len(world.terrains) > 1:
        offl = nx * ny
        parts.append(e.terrain_layer.astype(float).ravel())
    offt = sum(p.size for p in parts)
    ctg, slack = cost_to_go(world, cost)
    offd = offt + sum(b.size for b in blocks)
    data = np.ascontiguousarray(np.concatenate(parts + blocks + [ctg.ravel()]))
    Q = np.zeros(SS.NQ)
    Q[SS.Q_DT] = dt
    Q[SS.Q_NSTEP] = max(1, round(ps.period_s / dt))
    Q[SS.Q_GX], Q[SS.Q_GY], Q[SS.Q_GR] = scn.goal["x"], scn.goal["y"], scn.goal["radius"]
    Q[SS.Q_HL], Q[SS.Q_HW] = world.half_length, world.half_width
    tip = math.radians(ps.tip_over_deg)
    Q[SS.Q_TIP] = tip
    Q[SS.Q_RES], (Q[SS.Q_OX], Q[SS.Q_OY]) = e.resolution, e.origin
    Q[SS.Q_NX], Q[SS.Q_NY] = nx, ny
    Q[SS.Q_COST] = SS.COST_TIME if cost == "time" else SS.COST_ENERGY
    Q[SS.Q_VBOUND], Q[SS.Q_FROLL], Q[SS.Q_MG] = _bounds(world)
    Q[SS.Q_MKE] = max(b[K.P_M11] + abs(b[K.P_M12]) for b in blocks)
    Q[SS.Q_ZG] = _lowest_in_disc(e, scn.goal["x"], scn.goal["y"], scn.goal["radius"])
    Q[SS.Q_MARGIN] = world.margin
    Q[SS.Q_OFFL] = offl
    Q[SS.Q_OFFT] = offt
    Q[SS.Q_BLOCK] = blocks[0].size
    Q[SS.Q_OFFD] = offd
    Q[SS.Q_DSLACK] = slack
    return Q, data


def problem(world: World, cost: str, start: np.ndarray | None = None, dt: float | None = None) -> Problem:
    """The search problem of a world and cost, from ``start`` (a planner state, default
    the scenario's start state), its edges integrated at ``dt`` [s] (default the
    planner's step)."""
    ps = world.scenario.planner
    Q, data = pack_world(world, cost, dt)
    dims = np.array([K.S_X, K.S_Y, SS.X_YAWW, SS.X_V], np.int64)
    res = np.array([ps.cell_xy, ps.cell_xy, math.radians(ps.cell_yaw_deg), ps.cell_v])
    X0 = _start(world, start)
    if on_gpu(ps):
        from .problems.skidsteer_cuda import CudaEdges
        batch = CudaEdges(Q, data)
    else:
        batch = SS.expand_batch
    return Problem(SS.expand, SS.heuristic, SS.is_goal, Q, data, X0, control_set(world),
                   dims, res, ps.branching, rotate=ps.samples == "rotating",
                   fixed_controls=len(FIXED_CONTROLS), snap=False, codes=SS.CODES, settle_depth=SETTLE_DEPTH,
                   weight=ps.weight(cost), refine=ps.refine, expand_batch=batch)


GPU_BATCH = 64     # nodes per batch on a GPU (batch 0: auto): 1024 edges at branching 16


def device_note(ps) -> str | None:
    """One line when the scenario asks for the GPU and it cannot be used (the CPU plans
    instead), else None."""
    if ps.device != "cuda":
        return None
    from .problems.skidsteer_cuda import unavailable
    why = unavailable()
    return None if why is None else f"device cuda: {why}; planning on the CPU"


def on_gpu(ps) -> bool:
    """Whether the edges of this planner's searches run on the GPU."""
    return ps.device == "cuda" and device_note(ps) is None


def batch_size(ps) -> int:
    """Nodes expanded together: the scenario's, or with 0 (auto) 1 on the CPU and
    GPU_BATCH on a GPU."""
    return ps.batch or (GPU_BATCH if on_gpu(ps) else 1)


# ---- the plan ------------------------------------------------------------------------
TRAJECTORY_KEYS = ("t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r", "power_W",
                   "energy_J", "pitch", "i_l", "i_r")


def trajectory_json(traj: dict) -> dict:
    """The JSON ``trajectory`` object (docs/formats.md keys plus pitch and currents)."""
    return {k: [float(a) for a in traj[k]] for k in TRAJECTORY_KEYS if k in traj}

def trajectory_span(tr: dict, key: str) -> float | None:
    """Last minus first sample of channel ``key`` of a trajectory (None if it has none)."""
    return float(tr[key][-1] - tr[key][0]) if len(tr.get(key, ())) else None


def trajectory_length(tr: dict) -> float | None:
    """Length of a trajectory's xy path, m (None if it has no samples)."""
    return float(np.sum(np.hypot(np.diff(tr["x"]), np.diff(tr["y"])))) if len(tr.get("x", ())) else None


@dataclass
class Plan:
    """The result of planning one scenario for one cost (docs/formats.md plan JSON). The
    trajectory, travel time and energy are those of the controls driven at the vehicle's
    controller rate (``check``), not the search's coarser prediction."""

    scenario: str
    cost: str
    status: str
    reason: str | None
    controls: list = field(default_factory=list)       # [(wl, wr, duration_s)]
    trajectory: dict = field(default_factory=dict)     # channel -> np.ndarray
    planning_time_s: float = 0.0
    nodes_expanded: int = 0
    edges_simulated: int = 0
    nodes: int = 0
    invalid_edges: dict = field(default_factory=dict)
    found_by: str = ""            # the search that produced the controls (compare may adopt the other's)
    check: Check | None = None    # the controls replayed at the controller rate
    repairs: int = 0              # re-plans from where the controller-rate replay parted from the search
    polish: "Polished | None" = None   # the local search over the found controls (sbmpc.polish)

    @property
    def found(self) -> bool:
        return self.status == "found"

    @property
    def travel_time_s(self):
        return trajectory_span(self.trajectory, "t") if self.found else None

    @property
    def energy_J(self):
        return trajectory_span(self.trajectory, "energy_J") if self.found else None

    @property
    def length_m(self):
        return trajectory_length(self.trajectory) if self.found else None

    def to_json(self) -> dict:
        return {
            "schema": "sbmpc.plan/1",
            "scenario": self.scenario,
            "cost": self.cost,
            "status": self.status,
            "reason": self.reason,
            "travel_time_s": self.travel_time_s,
            "energy_J": self.energy_J,
            "length_m": self.length_m,
            "planning_time_s": self.planning_time_s,
            "nodes_expanded": self.nodes_expanded,
            "edges_simulated": self.edges_simulated,
            "controls": [{"wl": wl, "wr": wr, "duration_s": d} for wl, wr, d in self.controls],
            "trajectory": trajectory_json(self.trajectory),
            "nodes": self.nodes,
            "invalid_edges": self.invalid_edges,
            "found_by": self.found_by or f"{self.cost} search",
            "controller_rate_check": self.check.to_json() if self.check else None,
            "repairs": self.repairs,
            "polish": self.polish.to_json() if self.polish else None,
        }


def replay(world: World, cost: str, controls, every: int = 1, start: np.ndarray | None = None,
           dt: float | None = None, hold_last: float = 0.0) -> tuple:
    """Replay controls [(wl, wr, duration_s)] through the closed-loop model over the map
    from ``start`` (a planner state; default the scenario's start) at step ``dt`` [s]
    (default the planner's). Returns (trajectory dict sampled every ``every`` steps plus
    the last step, end code (0 or IN_GOAL, negative if invalid), final state, number of
    controls used: a replay stops at the first control that enters the goal or fails).
    ``hold_last`` [s] holds the last control that much longer (it stops in the goal)."""
    dt = world.scenario.planner.dt if dt is None else dt
    Q, data = pack_world(world, cost, dt)
    cl = np.array([c[0] for c in controls], float)
    cr = np.array([c[1] for c in controls], float)
    n = np.array([max(0, round(c[2] / dt)) for c in controls], np.int64)
    if len(n) and hold_last > 0:
        n[-1] += int(round(hold_last / dt))
    rec = np.zeros((int(n.sum()) + 1, K.NR))
    X0 = _start(world, start)
    rows, S, end, early = SS.replay(Q, data, X0, cl, cr, n, rec)
    idx = np.unique(np.r_[np.arange(0, rows, every), rows - 1])
    traj = {name: rec[idx, i].copy() for i, name in enumerate(K.CHANNELS)}
    return traj, int(end), S, (len(controls) if early < 0 else int(early) + 1)


@dataclass(frozen=True)
class Check:
    """A plan's controls replayed at the vehicle's controller rate (the paper's 1 kHz
    digital PID): does the vehicle really get there, and at what cost? ``miss_m`` [m]:
    how far outside the goal disc the replay's closest approach stays (0 when it enters);
    ``drift_m`` [m]: the allowance for that (DRIFT_PER_M of the distance driven)."""

    dt: float
    reached: bool
    travel_time_s: float | None
    energy_J: float | None
    reason: str | None
    miss_m: float = 0.0
    drift_m: float = 0.0

    def to_json(self) -> dict:
        return {"dt": self.dt, "reached": self.reached, "travel_time_s": self.travel_time_s,
                "energy_J": self.energy_J, "reason": self.reason, "miss_m": self.miss_m,
                "drift_allowance_m": self.drift_m}


HOLD_LAST_S = 0.25   # s: the last control is held this much longer at the controller rate
DRIFT_PER_M = 0.005  # of the distance driven: how far the controller-rate replay of a plan,
                     # driven open loop, may miss the goal disc and still count as reaching
                     # it (a vehicle that closes the loop, sbmpc run, corrects such drift).
                     # A stall or a tip-over is never allowed.
PART_M = 0.05        # m: a plan's controller-rate replay has parted from the search's
PART_DEG = 2.0       # prediction once its pose differs by this much (dynamics.convergence)
MAX_REPAIRS = 6      # re-plans from a parted controller-rate state before a plan is given up
POLISH_GOAL_MARGIN = 0.1   # m (at most half the goal radius): the polish aims this far inside the goal disc
APPROACH_CONTROLS = 3   # a plan that only passes the goal within the drift allowance is
APPROACH_SLACK = 0.05   # re-planned from this many controls before its end (or from where
                        # it parted) and the result kept when it enters the goal disc at
                        # 1 kHz for at most 5 % more cost


def _cost(chk: "Check", cost: str) -> float:
    return chk.travel_time_s if cost == "time" else chk.energy_J


def _controller_rate(world: World, cost: str, controls, X0: np.ndarray) -> tuple:
    """The controls replayed at the controller period from X0, every step recorded.
    Returns (Check, trajectory dict, controls as driven: cut where the replay enters the
    goal disc or passes closest to it, the last one held up to HOLD_LAST_S longer)."""
    dt = 1.0 / world.vehicle.controller_rate
    traj, end, S, used = replay(world, cost, controls, every=1, start=X0, dt=dt, hold_last=HOLD_LAST_S)
    g = world.scenario.goal
    d = np.hypot(traj["x"] - g["x"], traj["y"] - g["y"]) - g["radius"]
    if end == SS.IN_GOAL:
        i, miss = len(d) - 1, 0.0
    else:
        i = int(np.argmin(d))
        miss = max(0.0, float(d[i]))
    drift = DRIFT_PER_M * float(np.sum(np.hypot(np.diff(traj["x"][:i + 1]), np.diff(traj["y"][:i + 1]))))
    t = float(traj["t"][i] - X0[K.S_T])
    e = float(traj["energy_J"][i] - X0[K.S_E])
    if end == SS.IN_GOAL or (end >= 0 and miss <= drift):
        # the controls as driven: cumulative ends, the one running at sample i cut there
        ends = np.cumsum([c[2] for c in controls])
        k = min(int(np.searchsorted(ends, t - 1e-9)), len(controls) - 1)
        done = float(ends[k - 1]) if k else 0.0
        kept = [tuple(c) for c in controls[:k]] + [(controls[k][0], controls[k][1], round(t - done, 9))]
        traj = {name: v[:i + 1] for name, v in traj.items()}
        return Check(dt, True, t, e, None, miss, drift), traj, kept
    tt = float(S[K.S_T] - X0[K.S_T])
    where = f"at ({S[K.S_X]:.2f}, {S[K.S_Y]:.2f}), t = {tt:.2f} s, control {used} of {len(controls)}"
    if end < 0:
        why = f"the vehicle {SS.CODES[-end - 1].split(' (')[0]} {where}"
    else:
        why = (f"the controls pass {miss:.2f} m outside the goal disc (allowed: {drift:.2f} m of "
               f"open-loop drift), ending {where}")
    return Check(dt, False, tt, float(S[K.S_E] - X0[K.S_E]), why, miss, drift), traj, list(controls)


def check(world: World, cost: str, controls, start: np.ndarray | None = None) -> Check:
    """Replay ``controls`` at the controller period from ``start`` (the check of every
    plan before it is reported). Reached when the vehicle enters the goal disc, holding
    the last control up to HOLD_LAST_S longer than planned (the planner cut it where its
    coarser step entered the goal), or when it passes within the open-loop drift
    allowance (DRIFT_PER_M of the distance driven) of the disc without stalling."""
    return _controller_rate(world, cost, controls, _start(world, start))[0]


def _parting(pred: np.ndarray, controls, fine: dict, rate: float) -> tuple:
    """(j, parted): j the first control whose start the controller-rate replay (``fine``,
    every step recorded) reaches with a pose PART_M / PART_DEG away from the search's
    prediction ``pred`` (poses (x, y, yaw) at the control boundaries), parted True; else
    j the control where the replay stopped (a stall or tip-over) or the number of
    controls, parted False."""
    n_f = np.cumsum([0] + [max(0, round(c[2] * rate)) for c in controls])
    last = min(len(controls), int(np.searchsorted(n_f, len(fine["t"]) - 1, "left")) - 1)
    for j in range(1, max(last, 0) + 1):
        b = n_f[j]
        dpos = math.hypot(pred[j, 0] - fine["x"][b], pred[j, 1] - fine["y"][b])
        dyaw = abs(math.remainder(pred[j, 2] - fine["yaw"][b], 2 * math.pi))
        if dpos > PART_M or dyaw > math.radians(PART_DEG):
            return j, True
    return max(last, 0), False


def _fine_state(world: World, cost: str, controls, X0: np.ndarray) -> np.ndarray:
    """The planner state after ``controls`` driven at the controller period from X0."""
    _, _, S, _ = replay(world, cost, controls, every=1 << 30, start=X0, dt=1.0 / world.vehicle.controller_rate)
    return S


def _predicted(world: World, cost: str, controls, X0: np.ndarray) -> np.ndarray:
    """Poses (len(controls) + 1, 3) [m, m, rad] at the control boundaries, replayed at the
    planner's step from X0 (for controls that did not come from a search)."""
    dt = world.scenario.planner.dt
    traj, *_ = replay(world, cost, controls, every=1, start=X0)
    b = np.cumsum([0] + [max(0, round(c[2] / dt)) for c in controls])
    b = np.minimum(b, len(traj["t"]) - 1)
    return np.column_stack([traj["x"][b], traj["y"][b], traj["yaw"][b]])


def _remedy(world: World, res: SearchResult, limit_note: str | None) -> str:
    """What to try after a failed search, from what it measured: the budget it used up,
    the share of edges that stalled (the vehicle's limits against the map's slopes), the
    vehicle's turning limit."""
    ps = world.scenario.planner
    out = []
    if "node budget" in (res.reason or ""):
        out.append(f"raise the node budget (planner.max_expansions or --max-expansions {2 * ps.max_expansions})")
    elif "time budget" in (res.reason or ""):
        out.append(f"raise the time budget (planner.time_budget_s or --time-budget {2 * ps.time_budget_s:g})")
    stalled = res.invalid.get(SS.CODES[SS.STALL - 1], 0)
    if res.edges and stalled > 0.3 * res.edges:
        from dynamics.limits import steepest_grade
        g = max(steepest_grade(world.vehicle, t) for t in world.terrains)
        steep = math.degrees(math.atan(_max_rise(world.emap.heights, world.emap.resolution, 1.0)))
        out.append(f"{100 * stalled / res.edges:.0f} % of the edges stalled: the {world.vehicle.name} holds at most "
                   f"{math.degrees(g):.1f} deg here and the map's slopes reach {steep:.1f} deg (a stronger vehicle, "
                   f"a gentler map, or a map without height steps)")
    if limit_note:
        out.append(limit_note)
    return ("; to try: " + "; ".join(out)) if out else ""


def _threads(ps):
    """Threads for the search's edges: the scenario's, or with 0 "auto" (every core numba
    uses, unless measurements during the search find the serial expander faster: cores
    busy with other work). On the GPU, 1: the edges run there, and measuring the serial
    CPU expander against it would hand it a dozen whole batches."""
    if on_gpu(ps):
        return 1
    if ps.threads:
        return ps.threads
    import numba
    return "auto" if numba.config.NUMBA_NUM_THREADS > 1 else 1


def _incumbent(world: World, cost: str, start: np.ndarray, controls) -> tuple | None:
    """(cost, controls) of a control sequence replayed from ``start`` when it ends in the
    goal (its last control cut where it enters the goal disc); else None."""
    if not controls:
        return None
    traj, end, S, used = replay(world, cost, controls, every=1 << 30, start=start)
    if end != SS.IN_GOAL:
        return None
    dt = world.scenario.planner.dt
    kept = [tuple(c) for c in controls[:used]]
    last = round(float(S[K.S_T] - start[K.S_T]) - sum(c[2] for c in kept[:-1]), 9)
    kept[-1] = (kept[-1][0], kept[-1][1], round(max(dt, last), 9))
    c = S[K.S_T] - start[K.S_T] if cost == "time" else S[K.S_E] - start[K.S_E]
    return float(c), kept


def plan(world: World, cost: str | None = None, progress=None, start: np.ndarray | None = None,
         incumbent: list | None = None, time_budget_s: float | None = None) -> Plan:
    """Plan the scenario of ``world`` for ``cost`` (default: the scenario's).

    ``start``: a planner state to plan from (default: the scenario's start; a receding-
    horizon run passes the measured state). ``incumbent``: controls [(wl, wr, duration_s)]
    of a known way to the goal (the rest of the previous plan): when their replay from
    ``start`` ends in the goal, its cost bounds the search (branch and bound: no node
    that cannot beat it by the search's weight w is opened: :meth:`Search.bound`) and
    it is the plan when the search finds nothing cheaper within its budgets
    (``found_by`` says so). ``time_budget_s`` overrides the
    scenario's."""
    cost = cost or world.scenario.cost
    ps = world.scenario.planner
    budget = ps.time_budget_s if time_budget_s is None else time_budget_s
    t0 = time.perf_counter()
    X0 = _start(world, start)
    why = unreachable_reason(world, (float(X0[K.S_X]), float(X0[K.S_Y])))
    fatal, limit_note = capability(world)
    why = why or fatal
    if why is not None:
        return Plan(world.scenario.name, cost, "no_path", why, planning_time_s=time.perf_counter() - t0)
    inc = _incumbent(world, cost, X0, incumbent) if incumbent else None
    prob = problem(world, cost, X0)
    search = Search(prob)
    if inc is not None:
        search.bound(inc[0] * (1.0 + 1e-9))
    res: SearchResult = search.run(ps.max_expansions, budget, progress=progress, batch=batch_size(ps),
                                   threads=_threads(ps))
    common = dict(nodes_expanded=res.iterations, edges_simulated=res.edges, nodes=res.nodes, invalid_edges=res.invalid)
    if res.status == "found":
        T = res.states[:, K.S_T]
        controls = [(float(prob.controls[c, 0]), float(prob.controls[c, 1]), round(float(T[i + 1] - T[i]), 9))
                    for i, c in enumerate(res.control_rows)]
        found_by = ""
    elif inc is not None:
        controls = inc[1]
        found_by = ("previous plan (warm start: the search found nothing cheaper than its remaining "
                    f"{inc[0]:.4g} {'s' if cost == 'time' else 'J'} within its budgets)")
    else:
        return Plan(world.scenario.name, cost, "no_path", res.reason + _remedy(world, res, limit_note),
                    planning_time_s=time.perf_counter() - t0, **common)
    traj, end, S, _ = replay(world, cost, controls, every=1 << 30, start=X0)
    if end < 0 or (res.status == "found" and not np.allclose(S[:K.NS], res.states[-1, :K.NS], rtol=0, atol=1e-9)):
        raise RuntimeError("internal error: the replayed plan does not reproduce the searched path")
    pred = res.states[:, [K.S_X, K.S_Y, K.S_YAW]] if res.status == "found" else _predicted(world, cost, controls, X0)
    pol, drive = None, None
    if res.status == "found" and ps.polishes(cost):
        pol, drive = _polished(world, cost, prob, X0, controls, t0 + budget)
        if pol is not None:
            controls = pol.controls
            pred = _predicted(world, cost, controls, X0)
    common["polish"] = pol
    controls, chk, fine, repairs = _checked(world, cost, controls, pred, X0, t0, budget, ps, drive)
    common["repairs"] = repairs
    if not chk.reached:
        return Plan(world.scenario.name, cost, "no_path",
                    f"the path the search found ({ps.dt * 1e3:g} ms steps) does not hold at the vehicle's "
                    f"controller rate ({world.vehicle.controller_rate:g} Hz)"
                    + (f", also after {repairs} re-plans from where it parted" if repairs else "")
                    + f": {chk.reason}",
                    planning_time_s=time.perf_counter() - t0, check=chk, **common)
    every = max(1, round(RECORD_EVERY * world.vehicle.controller_rate))
    rows = len(fine["t"])
    idx = np.unique(np.r_[np.arange(0, rows, every), rows - 1])
    traj = {name: v[idx].copy() for name, v in fine.items()}
    return Plan(world.scenario.name, cost, "found", None, controls, traj,
                planning_time_s=time.perf_counter() - t0, found_by=found_by, check=chk, **common)


def _polished(world: World, cost: str, prob: Problem, X0: np.ndarray, controls, deadline: float):
    """The polish of searched ``controls`` (:mod:`sbmpc.polish`) and its drive at the
    controller rate (:func:`_controller_rate`'s result, for :func:`_checked`); (None,
    None) when it gained nothing, or when its controls, driven at the controller rate, do
    not reach the goal (or only pass it where the searched ones entered it) or cost more
    there than the searched ones: the polish is judged where every plan is. The polish aims at the goal
    disc less POLISH_GOAL_MARGIN (or, where no trial reaches that, the disc): a cheapest
    path only grazes its target, and a plan that grazes the disc at the planner's step
    may pass just outside it at 1 kHz."""
    lo, hi = wheel_speed_range(world)
    params = prob.params.copy()
    r = world.scenario.goal["radius"]
    for margin in (min(POLISH_GOAL_MARGIN, 0.5 * r), 0.0):     # no margin: where none reaches it
        params[SS.Q_GR] = r - margin
        pol = polish(params, prob.data, X0, controls, lo, hi, deadline)
        if pol is not None:
            break
    if pol is None or pol.gain <= 0.0:
        return None, None
    drive = _controller_rate(world, cost, pol.controls, X0)
    new = drive[0]
    if not new.reached:
        return None, None
    old = _controller_rate(world, cost, controls, X0)[0]
    if new.miss_m > 0.0 and old.reached and old.miss_m == 0.0:
        return None, None
    if old.reached and _cost(old, cost) <= _cost(new, cost):
        return None, None
    return pol, drive


def _checked(world: World, cost: str, controls, pred: np.ndarray, X0: np.ndarray, t0: float,
             budget: float, ps, drive=None) -> tuple:
    """Check searched controls at the controller rate. Where the check fails, re-plan
    from the controller-rate state and splice, up to MAX_REPAIRS times within the time
    budget: from the first control where the replay parted from the search's prediction
    ``pred`` (poses at the control boundaries: the search's model drifted from the vehicle's there), or, where it never
    parted but an edge failed at 1 kHz that passed at the search's step, from that
    edge's start with the search's step halved (that edge was not converged). A replay
    that only passes within the drift allowance of the goal disc gets its last approach
    planned from where it passed closest, so that the plan enters the disc (a receding-
    horizon run executes exactly that); if that fails the allowance stands. Returns
    (controls as driven, Check, the controller-rate trajectory, re-plans made). ``drive``:
    the controls' drive at the controller rate when it is known already (the polish's)."""
    rate = world.vehicle.controller_rate
    chk, fine, kept = drive if drive is not None else _controller_rate(world, cost, controls, X0)
    repairs = 0
    dt = ps.dt
    while repairs < MAX_REPAIRS and not (chk.reached and chk.miss_m == 0.0):
        left = budget - (time.perf_counter() - t0)
        if left <= 0:
            break
        j, parted = _parting(pred, controls, fine, rate)
        if chk.reached:
            # the last approach: from where the replay parted, else a few controls back
            if not parted:
                j = max(0, len(kept) - APPROACH_CONTROLS)
        elif not parted:
            dt = max(dt / 2.0, 1.0 / rate)
        Sj = _fine_state(world, cost, controls[:j], X0)
        if Sj[K.S_STALLED] != 0.0 or unreachable_reason(world, (float(Sj[K.S_X]), float(Sj[K.S_Y]))) is not None:
            break
        prob = problem(world, cost, Sj, dt)
        res = Search(prob).run(ps.max_expansions, left, batch=batch_size(ps), threads=_threads(ps))
        repairs += 1
        if res.status != "found":
            break
        T = res.states[:, K.S_T]
        tail = [(float(prob.controls[c, 0]), float(prob.controls[c, 1]), round(float(T[i + 1] - T[i]), 9))
                for i, c in enumerate(res.control_rows)]
        new = [tuple(c) for c in controls[:j]] + tail
        chk2, fine2, kept2 = _controller_rate(world, cost, new, X0)
        if chk.reached and not (chk2.reached and chk2.miss_m < chk.miss_m
                                and _cost(chk2, cost) <= (1.0 + APPROACH_SLACK) * _cost(chk, cost)):
            break                              # the approach did not help: keep the allowance
        controls, pred = new, np.vstack([pred[:j], res.states[:, [K.S_X, K.S_Y, K.S_YAW]]])
        chk, fine, kept = chk2, fine2, kept2
    return kept, chk, fine, repairs


def plan_both(world: World, progress=None) -> dict:
    """The time- and the energy-optimal plan of a world, {"time": Plan, "energy": Plan}.

    The implicit grid merges states, so a search can lose a path that the other search
    kept: then the energy search's plan may cost more energy than the time search's,
    or one search may find nothing where the other found a way. Each plan is checked
    against the other on its own cost; the better one is kept, a search that found
    nothing takes the other's plan (its own reason is kept in ``found_by``), and
    ``found_by`` says which search produced it (reported by ``sbmpc compare``)."""
    plans = {c: plan(world, c, progress=progress(c) if progress else None) for c in ("time", "energy")}
    t, e = plans["time"], plans["energy"]
    if t.found and e.found:
        if e.travel_time_s < t.travel_time_s:      # (both the controller-rate replays')
            plans["time"] = _adopt(e, "time", t)
        if t.energy_J < e.energy_J:
            plans["energy"] = _adopt(t, "energy", e)
    elif t.found != e.found:
        own, other = (e, t) if t.found else (t, e)
        plans[own.cost] = _adopt(other, own.cost, own, why=f"its own search found no path: {own.reason}")
    return plans


def _adopt(other: Plan, cost: str, own: Plan, why: str | None = None) -> Plan:
    from dataclasses import replace as _replace
    note = why or f"better on {cost} than the {cost} search's own plan"
    return _replace(other, cost=cost, found_by=f"{other.cost} search ({note})",
                    planning_time_s=own.planning_time_s + other.planning_time_s)
