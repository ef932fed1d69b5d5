"""Planning a scenario: resolve it into a world, build the search problem, search, replay.

``plan(world, cost)`` returns a :class:`Plan` whose controls, replayed through the
closed-loop model over the map (:func:`replay`), reproduce its trajectory and end in
the goal; the plan's trajectory *is* that replay.
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy import ndimage
from scipy.stats import qmc

from dynamics import ParameterError, kernels as K
from dynamics.params import G, Terrain, Vehicle, load_terrain, load_vehicle
from dynamics.resistance import friction_table
from dynamics.simulate import Model
from maps import ElevationMap
from maps.grid import pitch_roll_at
from maps.io import MapError, load_map

from . import skidsteer as SS
from .astar import Problem, Search, SearchResult
from .errors import InputError
from .scenario import Scenario, terrain_layer

RECORD_EVERY = 0.05   # s: trajectory samples in the plan JSON
SETTLE_DEPTH = 3      # edges from the start within which a child may stay in its parent's grid cell


@dataclass(frozen=True, eq=False)
class World:
    """A scenario resolved: the map (with its terrain layer), the vehicle, the terrains."""

    scenario: Scenario
    emap: ElevationMap
    vehicle: Vehicle
    terrains: tuple

    @property
    def half_length(self) -> float:
        """Half the wheelbase [m]: where the axles touch the ground ahead and behind."""
        v = self.vehicle
        return 0.25 * (v.patch_outer + v.patch_inner)

    @property
    def half_width(self) -> float:
        return 0.5 * self.vehicle.width

    @property
    def margin(self) -> float:
        """Half-diagonal of the footprint [m]: how close the centre may come to the map edge."""
        v = self.vehicle
        return math.hypot(0.5 * v.patch_outer, 0.5 * (v.width + v.patch_width))

    def terrain_at(self, x: float, y: float) -> Terrain:
        k = self.emap.terrain_index(x, y)
        return self.terrains[max(k, 0)]

    def model(self, x: float, y: float) -> Model:
        return Model(self.vehicle, self.terrain_at(x, y), self.scenario.planner.dt)


def resolve(scn: Scenario) -> World:
    """Load the map, vehicle and terrains of a scenario; InputError on any problem."""
    src = str(scn.path) if scn.path else scn.name
    try:
        emap = load_map(scn.map_spec, scn.base, "map")
    except MapError as exc:
        raise InputError(f"{src}: {exc}") from None
    try:
        vehicle = load_vehicle(scn.vehicle, scn.base)
    except ParameterError as exc:
        raise InputError(f"{src}: vehicle: {exc}") from None
    if isinstance(scn.terrain, str):
        names = [scn.terrain]
    else:
        names = [scn.terrain["default"]] + [r.terrain for r in scn.terrain["regions"]]
        names = list(dict.fromkeys(names))
    terrains = []
    for n in names:
        try:
            terrains.append(load_terrain(n, scn.base))
        except ParameterError as exc:
            raise InputError(f"{src}: terrain: {exc}") from None
    if not isinstance(scn.terrain, str):
        ny, nx = emap.shape
        ox, oy = emap.origin
        layer = terrain_layer(scn.terrain["regions"], 0, names, ox + emap.resolution * np.arange(nx),
                              oy + emap.resolution * np.arange(ny))
        emap = ElevationMap(emap.heights, emap.resolution, emap.origin, layer, tuple(names), emap.name)
    world = World(scn, emap, vehicle, tuple(terrains))
    problems = []
    x0, x1, y0, y1 = emap.extent
    m = world.margin
    for key, p in (("start", scn.start), ("goal", scn.goal)):
        if not emap.contains(p["x"], p["y"], m):
            problems.append(f"{key}: expected (x, y) at least {m:.2f} m inside the map "
                            f"[{x0:g}, {x1:g}] x [{y0:g}, {y1:g}], found ({p['x']:g}, {p['y']:g})")
    if scn.cost == "energy" and vehicle.regen:
        problems.append("cost: energy needs a vehicle without regeneration (regen: false), found regen: true")
    if problems:
        raise InputError(f"{src}: " + "; ".join(problems))
    return world


# ---- the search problem ------------------------------------------------------------
def wheel_speed_range(world: World) -> tuple:
    ws = world.scenario.planner.wheel_speeds
    if ws is not None:
        return ws
    w0 = world.vehicle.no_load_speed
    return -0.5 * w0, w0


FIXED_CONTROLS = ((1.0, 1.0), (1.0, 0.85), (0.85, 1.0))   # x the top of the range


def control_set(world: World) -> np.ndarray:
    """Desired wheel speeds (m, 2) [rad/s]: first the fixed rows (top speed straight and
    two gentle turns at top speed, tried at every expansion: a uniform sample of the
    square almost never has both wheels at full speed), then a scrambled Halton sequence
    over the sampled range (seeded: the same seed gives the same plan)."""
    ps = world.scenario.planner
    lo, hi = wheel_speed_range(world)
    nh = ps.branching - len(FIXED_CONTROLS)
    m = nh * (64 if ps.samples == "rotating" else 1)
    pts = qmc.Halton(d=2, scramble=True, seed=ps.seed).random(m)
    fixed = hi * np.array(FIXED_CONTROLS)
    return np.ascontiguousarray(np.vstack([fixed, lo + (hi - lo) * pts]))


def start_state(world: World) -> np.ndarray:
    """The model's state at the scenario's start: steady driving at the start speed."""
    s = world.scenario.start
    e = world.emap
    yaw = math.radians(s["yaw_deg"])
    pitch, _ = e.pitch_roll(s["x"], s["y"], yaw, world.half_length, world.half_width)
    w = s["v"] / world.vehicle.wheel_radius
    v = world.vehicle
    S = world.model(s["x"], s["y"]).state(w / v.radius_scale_left, w / v.radius_scale_right, pitch,
                                          s["x"], s["y"], yaw, e.height(s["x"], s["y"]))
    X = np.zeros(SS.NX)
    X[:K.NS] = S
    X[SS.X_YAWW] = math.atan2(math.sin(yaw), math.cos(yaw))
    X[SS.X_V] = s["v"]
    return X


def _start(world: World, start) -> np.ndarray:
    """The planner state to start from: ``start`` (contiguous float64) or the scenario's."""
    return start_state(world) if start is None else np.ascontiguousarray(start, float)


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


def _lowest_in_disc(e: ElevationMap, x, y, r) -> float:
    ang = np.linspace(0, 2 * np.pi, 33)
    pts = [(x, y)] + [(x + rr * np.cos(a), y + rr * np.sin(a)) for rr in (0.5 * r, r) for a in ang]
    # bilinear heights: the minimum over the disc lies on a grid node inside it or on the samples
    zs = [e.height(px, py) for px, py in pts]
    ny, nx = e.shape
    ox, oy = e.origin
    X, Y = np.meshgrid(ox + e.resolution * np.arange(nx), oy + e.resolution * np.arange(ny))
    inside = (X - x) ** 2 + (Y - y) ** 2 <= r * r
    if inside.any():
        zs.append(float(e.heights[inside].min()))
    return float(min(zs))


OCTILE = 1.0823922002923938   # largest ratio of an 8-neighbour grid path to the straight line


def _bounds(world: World):
    """(v_bound [m/s], F_roll [N], m g [N]) of the straight-line heuristics."""
    v = world.vehicle
    lo, hi = wheel_speed_range(world)
    vb = 1.05 * v.wheel_radius * max(abs(lo), abs(hi)) * max(v.radius_scale_left, v.radius_scale_right)
    # rolling resistance is mu m g cos(pitch): the pitch is at most the steepest slope
    # of the map (and the tip-over limit)
    steepest = min(math.radians(world.scenario.planner.tip_over_deg), math.atan(_max_rise(world.emap.heights, world.emap.resolution, 1.0)))
    froll = min(t.mu_roll for t in world.terrains) * v.mass * G * math.cos(steepest)
    return vb, froll, v.mass * G


RUNUP_DEG = 3.0    # deg: how much steeper than its steepest sustainable grade a run-up may carry the vehicle


def climb_limit(world: World) -> float:
    """Steepest uphill grade [rad] the cost-to-go grid lets a step take: the steepest
    grade the vehicle holds at any speed on the best of the map's terrains
    (``dynamics.limits``) plus RUNUP_DEG for what momentum carries over a short ramp."""
    from dynamics.limits import steepest_grade
    return max(steepest_grade(world.vehicle, t) for t in world.terrains) + math.radians(RUNUP_DEG)


@functools.lru_cache(maxsize=8)
def blocked_cells(world: World) -> np.ndarray:
    """(ny, nx) cells where the vehicle tips over at every heading (computed once per
    world: the reachability check and the cost-to-go grid share it)."""
    e = world.emap
    ox, oy = e.origin
    b = _blocked(e.heights, e.resolution, ox, oy, world.half_length, world.half_width,
                 math.radians(world.scenario.planner.tip_over_deg), 16)
    b.setflags(write=False)        # cached and shared
    return b


@functools.lru_cache(maxsize=8)
def cost_to_go(world: World, cost: str) -> tuple:
    """Lower bound of the cost [s or J] from every map node to the goal disc (Dijkstra
    over 8-neighbour steps, see :mod:`sbmpc.skidsteer`), and the slack [s or J] the
    heuristic subtracts for the way from a pose to its nearest node. Unreachable nodes
    get a large finite cost. Cached per (world, cost): planning and replaying share it."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    e, scn = world.emap, world.scenario
    H = e.heights
    ny, nx = H.shape
    res = e.resolution
    vb, froll, mg = _bounds(world)
    ox, oy = e.origin
    blocked = blocked_cells(world).ravel()
    if e.terrain_layer is not None and len(world.terrains) > 1:
        mu = np.array([t.mu_roll for t in world.terrains])[e.terrain_layer].ravel()
    else:
        mu = np.full(nx * ny, world.terrains[0].mu_roll)
    gy, gx = np.gradient(H, res)
    # per cell: mu m g cos(steepest slope of the cell), a lower bound of the rolling force
    froll_cell = mu * mg * np.cos(np.minimum(np.arctan(np.hypot(gx, gy)), math.radians(scn.planner.tip_over_deg))).ravel()
    idx = np.arange(nx * ny).reshape(ny, nx)
    climb = math.tan(climb_limit(world))
    src, dst, w = [], [], []
    for dj, di in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = idx[:ny - dj, max(0, -di):nx - max(0, di)].ravel()
        b = idx[dj:, max(0, di):nx - max(0, -di)].ravel()      # the cell (j + dj, i + di)
        d = res * math.hypot(di, dj)
        ok = ~(blocked[a] | blocked[b])
        a, b = a[ok], b[ok]
        for p, q in ((a, b), (b, a)):          # step from p to q
            up = (H.ravel()[q] - H.ravel()[p]) / d
            p, q = p[up <= climb], q[up <= climb]
            if cost == "time":
                wt = np.full(p.size, d / vb)
            else:
                f = np.minimum(froll_cell[p], froll_cell[q])
                wt = np.maximum(0.0, f * d + mg * (H.ravel()[q] - H.ravel()[p]))
            # reversed edges: Dijkstra runs from the goal
            src.append(q)
            dst.append(p)
            w.append(wt / OCTILE + 1e-12)
    G_ = coo_matrix((np.concatenate(w), (np.concatenate(src), np.concatenate(dst))), shape=(nx * ny, nx * ny)).tocsr()
    X, Y = np.meshgrid(ox + res * np.arange(nx), oy + res * np.arange(ny))
    g = scn.goal
    goal_nodes = np.flatnonzero((((X - g["x"]) ** 2 + (Y - g["y"]) ** 2) <= g["radius"] ** 2).ravel() & ~blocked)
    if goal_nodes.size == 0:
        return np.zeros((ny, nx)), 0.0
    D = dijkstra(G_, indices=goal_nodes, min_only=True)
    D[~np.isfinite(D)] = 1e12
    diag = res * math.sqrt(2.0)
    slack = diag / vb if cost == "time" else (froll_cell.max() * diag + mg * _max_rise(H, res, diag))
    D = D.reshape(ny, nx)
    D.setflags(write=False)        # cached and shared
    return D, float(slack)


def _max_rise(H, res, dist):
    """Largest height gain [m] within ``dist`` [m] on the map (from its steepest slope)."""
    gy, gx = np.gradient(H, res)
    return float(np.hypot(gx, gy).max() * dist)


def problem(world: World, cost: str, start: np.ndarray | None = None, dt: float | None = None) -> Problem:
    """The search problem of a world and cost, from ``start`` (a planner state, default
    the scenario's start state), its edges integrated at ``dt`` [s] (default the
    planner's step)."""
    ps = world.scenario.planner
    Q, data = pack_world(world, cost, dt)
    dims = np.array([K.S_X, K.S_Y, SS.X_YAWW, SS.X_V], np.int64)
    res = np.array([ps.cell_xy, ps.cell_xy, math.radians(ps.cell_yaw_deg), ps.cell_v])
    X0 = _start(world, start)
    return Problem(SS.expand, SS.heuristic, SS.is_goal, Q, data, X0, control_set(world),
                   dims, res, ps.branching, rotate=ps.samples == "rotating",
                   fixed_controls=len(FIXED_CONTROLS), snap=False, codes=SS.CODES, settle_depth=SETTLE_DEPTH,
                   weight=ps.weight(cost), refine=ps.refine)


# ---- reachability pre-check -----------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _blocked(H, res, ox, oy, hl, hw, tip, nheadings):
    """Cells where the vehicle would exceed the tip-over limit at every heading."""
    ny, nx = H.shape
    out = np.zeros((ny, nx), np.bool_)
    for j in range(ny):
        for i in range(nx):
            x = ox + i * res
            y = oy + j * res
            blocked = True
            for k in range(nheadings):
                p, r = pitch_roll_at(H, res, ox, oy, x, y, math.pi * k / nheadings, hl, hw)
                if abs(p) <= tip and abs(r) <= tip:
                    blocked = False
                    break
            out[j, i] = blocked
    return out


def unreachable_reason(world: World, xy: tuple | None = None) -> str | None:
    """Why no path can exist, when the goal disc is cut off from the start (or from the
    position ``xy``) by cells where the vehicle tips over at every heading (checked at
    cell centres); else None."""
    e, scn = world.emap, world.scenario
    sx, sy = xy if xy is not None else (scn.start["x"], scn.start["y"])
    ox, oy = e.origin
    labels, _ = ndimage.label(~blocked_cells(world), structure=np.ones((3, 3)))
    def cell(x, y):
        return (min(max(int(round((y - oy) / e.resolution)), 0), e.shape[0] - 1),
                min(max(int(round((x - ox) / e.resolution)), 0), e.shape[1] - 1))
    s = labels[cell(sx, sy)]
    ny, nx = e.shape
    X, Y = np.meshgrid(ox + e.resolution * np.arange(nx), oy + e.resolution * np.arange(ny))
    g = scn.goal
    in_goal = (X - g["x"]) ** 2 + (Y - g["y"]) ** 2 <= max(g["radius"], 0.5 * e.resolution) ** 2
    if s == 0:
        return f"the start stands on a slope beyond the tip-over limit of {scn.planner.tip_over_deg:g} deg at every heading"
    if not np.any(labels[in_goal] == s):
        return (f"the goal is cut off from the start by slopes beyond the tip-over limit of "
                f"{scn.planner.tip_over_deg:g} deg (no heading crosses them); no path can exist")
    return None


# ---- the plan ------------------------------------------------------------------------
TRAJECTORY_KEYS = ("t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r", "power_W",
                   "energy_J", "pitch", "i_l", "i_r")


def trajectory_json(traj: dict) -> dict:
    """The JSON ``trajectory`` object (CONTRACTS.md keys plus pitch and currents)."""
    return {k: [float(a) for a in traj[k]] for k in TRAJECTORY_KEYS if k in traj}

def trajectory_span(tr: dict, key: str) -> float | None:
    """Last minus first sample of channel ``key`` of a trajectory (None if it has none)."""
    return float(tr[key][-1] - tr[key][0]) if len(tr.get(key, ())) else None


def trajectory_length(tr: dict) -> float | None:
    """Length of a trajectory's xy path, m (None if it has no samples)."""
    return float(np.sum(np.hypot(np.diff(tr["x"]), np.diff(tr["y"])))) if len(tr.get("x", ())) else None


@dataclass
class Plan:
    """The result of planning one scenario for one cost (CONTRACTS.md plan JSON). The
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
    if why is not None:
        return Plan(world.scenario.name, cost, "no_path", why, planning_time_s=time.perf_counter() - t0)
    inc = _incumbent(world, cost, X0, incumbent) if incumbent else None
    prob = problem(world, cost, X0)
    search = Search(prob)
    if inc is not None:
        search.bound(inc[0] * (1.0 + 1e-9))
    res: SearchResult = search.run(ps.max_expansions, budget, progress=progress)
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
        return Plan(world.scenario.name, cost, "no_path", res.reason,
                    planning_time_s=time.perf_counter() - t0, **common)
    traj, end, S, _ = replay(world, cost, controls, every=1 << 30, start=X0)
    if end < 0 or (res.status == "found" and not np.allclose(S[:K.NS], res.states[-1, :K.NS], rtol=0, atol=1e-9)):
        raise RuntimeError("internal error: the replayed plan does not reproduce the searched path")
    pred = res.states[:, [K.S_X, K.S_Y, K.S_YAW]] if res.status == "found" else _predicted(world, cost, controls, X0)
    controls, chk, fine, repairs = _checked(world, cost, controls, pred, X0, t0, budget, ps)
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


def _checked(world: World, cost: str, controls, pred: np.ndarray, X0: np.ndarray, t0: float,
             budget: float, ps) -> tuple:
    """Check searched controls at the controller rate. Where the check fails, re-plan
    from the controller-rate state and splice, up to MAX_REPAIRS times within the time
    budget: from the first control where the replay parted from the search's prediction
    ``pred`` (poses at the control boundaries: the search's model drifted from the vehicle's there), or, where it never
    parted but an edge failed at 1 kHz that passed at the search's step, from that
    edge's start with the search's step halved (that edge was not converged). A replay
    that only passes within the drift allowance of the goal disc gets its last approach
    planned from where it passed closest, so that the plan enters the disc (a receding-
    horizon run executes exactly that); if that fails the allowance stands. Returns
    (controls as driven, Check, the controller-rate trajectory, re-plans made)."""
    rate = world.vehicle.controller_rate
    chk, fine, kept = _controller_rate(world, cost, controls, X0)
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
        res = Search(prob).run(ps.max_expansions, left)
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
    kept: then the energy search's plan may cost more energy than the time search's.
    Each plan is checked against the other on its own cost; the better one is kept and
    ``found_by`` says which search produced it (reported by ``sbmpc compare``)."""
    plans = {c: plan(world, c, progress=progress(c) if progress else None) for c in ("time", "energy")}
    t, e = plans["time"], plans["energy"]
    if t.found and e.found:
        if e.travel_time_s < t.travel_time_s:      # (both the controller-rate replays')
            plans["time"] = _adopt(e, "time", t)
        if t.energy_J < e.energy_J:
            plans["energy"] = _adopt(t, "energy", e)
    return plans


def _adopt(other: Plan, cost: str, own: Plan) -> Plan:
    from dataclasses import replace as _replace
    return _replace(other, cost=cost, found_by=f"{other.cost} search (better on {cost} than the {cost} search's own plan)",
                    planning_time_s=own.planning_time_s + other.planning_time_s)
