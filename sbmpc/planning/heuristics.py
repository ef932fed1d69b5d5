"""What the planner knows of the map before it searches: lower bounds of the cost to the
goal (the straight-line bounds' constants, the cost-to-go grid over the map) and the
reachability pre-check (cells where the vehicle tips over at every heading).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy import ndimage

from dynamics.params import G
from maps import ElevationMap
from maps.grid import pitch_roll_at

from ..problems import skidsteer as SS
from .world import World, wheel_speed_range


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


def copper_coefficient(world: World) -> float:
    """c [1/N] of :func:`least_step_energy`: R_a r s / (k^2 w_top), s the smaller of the
    wheels' radius scales (a side's rolled distance is r s int w dt) and w_top = V_max / k
    the no-load speed: while a motor drives (I w > 0) the voltage limit (eq. 27) keeps
    |w| below it, and only those intervals need to deliver the work."""
    v = world.vehicle
    w_top = v.v_max / v.torque_constant
    s = min(v.radius_scale_left, v.radius_scale_right)
    return v.armature_resistance * v.wheel_radius * s / (v.torque_constant ** 2 * w_top)


@njit(cache=True, error_model="numpy", nogil=True)
def _steps(f_roll, rise, d, c, energy, slope):
    """Over flat arrays: each step's bound (skidsteer.step_energy) into ``energy`` and
    its slope dE/dW = 1 + 2 c W / L at the minimum into ``slope`` (0 where the bound is
    0: nothing to climb against)."""
    for k in range(f_roll.shape[0]):
        energy[k] = SS.step_energy(f_roll[k], rise[k], d[k], c)
        if f_roll[k] * d[k] + rise[k] > 0.0:
            W, L = SS.step_work(f_roll[k], rise[k], d[k], c)
            slope[k] = 1.0 + 2.0 * c * W / max(L, 1e-12)
        else:
            slope[k] = 0.0


def _step_bounds(f_roll, rise, d, c) -> tuple:
    """(bounds, slopes) of :func:`_steps` over arrays that broadcast, in their shape."""
    f_roll, rise, d = np.broadcast_arrays(np.asarray(f_roll, float), np.asarray(rise, float), np.asarray(d, float))
    flat = [np.ascontiguousarray(x).ravel() for x in (f_roll, rise, d)]
    energy, slope = np.empty(flat[0].size), np.empty(flat[0].size)
    _steps(*flat, float(c), energy, slope)
    return energy.reshape(f_roll.shape), slope.reshape(f_roll.shape)


def least_step_energy(f_roll, rise, d, c):
    """Least battery energy [J] of a step over the ground of length d [m] that rises by
    ``rise`` = m g dz [J], against a rolling force f_roll [N] (arrays broadcast).

    Per side, the motor's electrical energy is its mechanical work W plus the copper loss
    R_a int I^2 dt (P = R_a I^2 + k w I, docs/model.md), and by Cauchy-Schwarz over the
    intervals where it drives (I w > 0, |w| <= w_top there) int I^2 dt >= (W / k)^2 /
    (w_top L / r), L the wheel's rolled distance, W >= f_roll L / 2 + its share of the
    climb (each side's rolling resistance is mu m g cos / 2 over what it rolls). So a
    side spends at least W + c W^2 / L, c = R_a r / (k^2 w_top) (:func:`copper_coefficient`).
    W^2 / L is jointly convex, so the two sides together spend at least twice the value
    at their mean W and mean L (the kinematics have no longitudinal slip: the mean rolled
    distance is at least the distance d travelled, though the inner wheel of a turn
    rolls less). Minimised over L >= d (a wheel that rolls farther for the same climb
    draws less current: the minimum is at L* = rise sqrt(c / (f_roll (2 + c f_roll)))
    when that exceeds d). With nothing to climb against (f_roll d + rise <= 0) the bound
    is 0 (no regeneration). The bound is convex and grows linearly with (rise, d)
    together, so splitting a step never lowers it: the grid's detour scaling and the
    way from a node to a pose stay valid.
    On a steady climb at the top command it is 0.3-5 % below the model's draw (the
    wheels slow on a grade, so the real copper loss per metre is larger); the copper
    term adds 4 % to rolling plus climb on the level and 20 % near the steepest grade
    the drive holds (packed dirt, tests/test_heuristics.py). One formula, compiled
    (``skidsteer.step_energy``), serves this grid and the heuristic's way to a pose."""
    return _step_bounds(f_roll, rise, d, c)[0]


def ke_factor(f_roll, rise, d, c) -> float:
    """The largest slope dE/dW = 1 + 2 c W / L of :func:`least_step_energy` over the given
    steps (at least 1): kinetic energy the vehicle carries and spends on a step saves at
    most this much of the step's bound (the bound is convex in W), so the heuristic
    credits a node's KE this many times."""
    slope = _step_bounds(f_roll, rise, d, c)[1]
    return float(max(1.0, slope.max())) if slope.size else 1.0


CARRY_S = 0.02     # s: the most a climb entered at the top speed can save against its steady
                   # top speed (the P3-AT sheds the speed it carries in within about 50 ms:
                   # 0.012 s entering 10 deg of grass at 0.955 m/s; tests/test_heuristics.py)
OVERSHOOT = 0.02   # of the commanded top wheel speed: the PID's overshoot downhill (1.5 % measured)
SPEED_GRADES = 64  # grades tabulated for the steady top speeds, 0 to the steepest sustainable


def step_speed_bounds(world: World, terrain: np.ndarray, grade: np.ndarray, vb: float) -> np.ndarray:
    """Upper bounds [m/s] of the speed over grid steps of the given ``grade`` [rad] (rise
    over run along the step; arrays broadcast) on ``terrain`` (indices into
    world.terrains): the steady top speed of straight driving at the top command up that
    grade (``dynamics.limits.top_speed``: the drive's voltage limit, eq. 27, against
    rolling, climb and viscous resistance; a turn only slows the vehicle), times the
    larger wheel radius scale, read from a table at the tabulated grade at or below the
    step's (the speed falls with the grade, so that reads high). On the level the
    drive is already at its voltage limit below the commanded top (0.924 m/s on
    asphalt against 0.955). Downhill the drive holds the commanded top wheel speed, its
    PID overshooting it by up to 1.5 % (OVERSHOOT: 2 %), as far down as it can brake at
    its continuous torque; steeper (0.99 m/s down 20 deg of asphalt), or beyond the
    steepest grade the terrain holds (a run-up: only momentum crosses it), ``vb``, the
    straight-line bound (the commanded top wheel speed with 5 % to spare).
    Speed carried into a climb from above its steady top is shed within a few tens of
    milliseconds (CARRY_S, which the heuristic subtracts)."""
    terrain, grade = np.broadcast_arrays(np.asarray(terrain), np.asarray(grade, float))
    out = np.full(grade.shape, vb)
    for k, (steep, held, nodes, table) in enumerate(_speed_tables(world, vb)):
        out[(terrain == k) & (grade < 0.0) & (grade >= steep)] = held
        if nodes.size:
            m = (terrain == k) & (grade >= 0.0) & (grade <= nodes[-1])
            i = np.clip(np.searchsorted(nodes, grade[m], side="right") - 1, 0, nodes.size - 1)
            out[m] = table[i]
    return out


@functools.lru_cache(maxsize=8)
def _speed_tables(world: World, vb: float) -> tuple:
    """Per terrain of ``world``, what :func:`step_speed_bounds` reads: (steepest descent
    [rad] the drive brakes to the command on, the speed bound there [m/s], the grades
    [rad] tabulated from 0 to the steepest sustainable one, their top speeds [m/s])."""
    from dynamics.limits import steepest_braked_grade, steepest_grade, top_speed
    v = world.vehicle
    scale = max(v.radius_scale_left, v.radius_scale_right)
    w_top = wheel_speed_range(world)[1]
    held = min(vb, (1.0 + OVERSHOOT) * scale * v.wheel_radius * w_top)
    out = []
    for t in world.terrains:
        steep = steepest_braked_grade(v, t, w_top)    # downhill, as far as the drive brakes to the command
        top = steepest_grade(v, t)
        nodes = np.linspace(0.0, top, SPEED_GRADES) if top > 0.0 else np.zeros(0)
        # (1 + 1e-9: the root finder's tolerance, so that the table reads high)
        table = np.array([min(vb, (1.0 + 1e-9) * scale * top_speed(v, t, g)) for g in nodes])
        out.append((steep, held, nodes, table))
    return tuple(out)


RUNUP_DEG = 3.0    # deg: how much steeper than its steepest sustainable grade a run-up may carry the vehicle


def climb_limit(world: World) -> float:
    """Steepest uphill grade [rad] the cost-to-go grid lets a step take: the steepest
    grade the vehicle holds at any speed on the best of the map's terrains
    (``dynamics.limits``) plus RUNUP_DEG for what momentum carries over a short ramp."""
    from dynamics.limits import steepest_grade
    grade = max(steepest_grade(world.vehicle, t) for t in world.terrains) + math.radians(RUNUP_DEG)
    return min(grade, math.radians(89.0))      # a vehicle whose drive holds any grade: tan stays finite


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
def off_limits(world: World) -> np.ndarray:
    """(ny, nx) grid nodes no way of the vehicle passes: where it tips over at every
    heading (:func:`blocked_cells`) and those closer to the map's edge than its
    footprint's half-diagonal (``World.margin``: an edge whose centre comes closer
    ends as "left the map"). The reachability checks avoid them
    (:func:`unreachable_reason`, :func:`steepest_climb_needed`); the cost-to-go grid
    avoids the first only (it stays a lower bound: excluding the band too changed no
    plan but by redrawing the weighted search's ties, docs/performance.md#unseen-maps)."""
    e = world.emap
    ny, nx = e.shape
    m = world.margin / e.resolution
    i, j = np.arange(nx), np.arange(ny)
    near_x = (i < m - 1e-9) | (i > nx - 1 - m + 1e-9)
    near_y = (j < m - 1e-9) | (j > ny - 1 - m + 1e-9)
    out = blocked_cells(world) | near_y[:, None] | near_x[None, :]
    out.setflags(write=False)
    return out


def _node(world: World, x: float, y: float) -> tuple:
    """(j, i): the grid node nearest (x, y) [m] outside the band along the map's edge
    that :func:`off_limits` keeps the vehicle's centre out of (a position the vehicle
    may take, at least ``World.margin`` inside, can round into it)."""
    e = world.emap
    ny, nx = e.shape
    k = min(int(math.ceil(world.margin / e.resolution - 1e-9)), (min(nx, ny) - 1) // 2)
    return (min(max(int(round((y - e.origin[1]) / e.resolution)), k), ny - 1 - k),
            min(max(int(round((x - e.origin[0]) / e.resolution)), k), nx - 1 - k))


CTG_MAX_CELLS = 1_000_000    # larger maps get a cost-to-go window around start and goal
OFF_CORRIDOR = 1e6           # s or J: what the grid adds off a corridor search's corridor (sbmpc.planning.corridor)


def ctg_window(world: World, max_cells: int = CTG_MAX_CELLS) -> tuple:
    """(j0, j1, i0, i1): the rows and columns the cost-to-go grid covers: the whole map
    when it has at most ``max_cells`` cells, else a box around the start and the goal
    (margin: half their distance, at least 10 m) cut to ``max_cells`` by shrinking the
    margin. The grid is then a lower bound through the box's edges (cost_to_go)."""
    e, scn = world.emap, world.scenario
    ny, nx = e.shape
    if nx * ny <= max_cells:
        return 0, ny, 0, nx
    ox, oy = e.origin
    s, g = scn.start, scn.goal
    margin = max(10.0, 0.5 * math.hypot(g["x"] - s["x"], g["y"] - s["y"]))
    while True:
        x0, x1 = min(s["x"], g["x"]) - margin, max(s["x"], g["x"]) + margin
        y0, y1 = min(s["y"], g["y"]) - margin, max(s["y"], g["y"]) + margin
        i0, i1 = max(0, int((x0 - ox) / e.resolution)), min(nx, int(math.ceil((x1 - ox) / e.resolution)) + 1)
        j0, j1 = max(0, int((y0 - oy) / e.resolution)), min(ny, int(math.ceil((y1 - oy) / e.resolution)) + 1)
        if (i1 - i0) * (j1 - j0) <= max_cells or margin < 2.0 * e.resolution:
            return j0, j1, i0, i1
        margin *= 0.7


def grid_steps(H: np.ndarray, blocked: np.ndarray, res: float, climb: float):
    """The 8-neighbour steps of the cost-to-go grid over heights H (ny, nx) [m] at
    resolution ``res`` [m], each direction taken both ways: yields (p, q, up, d), the
    flat indices of the cells a step leaves and reaches, its grade (rise over run) and
    length [m], for the steps that touch no ``blocked`` cell (flat, ny * nx) and climb
    no steeper than ``climb`` (a grade)."""
    ny, nx = H.shape
    Hr = H.ravel()
    idx = np.arange(nx * ny).reshape(ny, nx)
    for dj, di in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = idx[:ny - dj, max(0, -di):nx - max(0, di)].ravel()
        b = idx[dj:, max(0, di):nx - max(0, -di)].ravel()      # the cell (j + dj, i + di)
        d = res * math.hypot(di, dj)
        ok = ~(blocked[a] | blocked[b])
        a, b = a[ok], b[ok]
        for p, q in ((a, b), (b, a)):          # step from p to q
            up = (Hr[q] - Hr[p]) / d
            keep = up <= climb
            yield p[keep], q[keep], up[keep], d


def _cached_but_corridors(fn):
    """``fn(world, cost, max_cells)`` cached per (world, cost, max_cells) like
    functools.lru_cache(8), except for a corridor search's world (``World.keep_out``):
    its grid serves one search, and caching it would push out the grids that planning,
    replaying and a receding-horizon run's aims share."""
    cached = functools.lru_cache(maxsize=8)(fn)

    @functools.wraps(fn)
    def call(world: World, cost: str, max_cells: int = CTG_MAX_CELLS) -> tuple:
        return fn(world, cost, max_cells) if world.keep_out is not None else cached(world, cost, max_cells)
    call.cache_clear = cached.cache_clear
    return call


@dataclass(frozen=True)
class StepGraph:
    """The cost-to-go grid's graph over a window (j0, j1, i0, i1) of the map
    (:func:`ctg_window`): its heights ``H`` (ny, nx) [m] with origin (``ox``, ``oy``)
    [m] and spacing ``res`` [m], the ``blocked`` cells (flat), the per-cell lower bound
    of the rolling force ``froll_cell`` [N], the energy bound's copper coefficient and
    kinetic-energy factor (``kegrid``), and the 8-neighbour steps reversed (``src`` the
    cell a step reaches, ``dst`` the one it leaves: Dijkstra runs from where the way
    ends), each weighing its lower bound of time [s] or energy [J] over OCTILE."""

    window: tuple
    H: np.ndarray
    res: float
    ox: float
    oy: float
    blocked: np.ndarray
    froll_cell: np.ndarray
    copper: float
    kegrid: float
    src: np.ndarray
    dst: np.ndarray
    w: np.ndarray


def step_graph(world: World, cost: str, max_cells: int = CTG_MAX_CELLS) -> StepGraph:
    """The graph the cost-to-go grid is solved over (:class:`StepGraph`): a time step
    takes its length over :func:`step_speed_bounds`, an energy step
    :func:`least_step_energy`."""
    e, scn = world.emap, world.scenario
    j0, j1, i0, i1 = ctg_window(world, max_cells)
    Hfull = e.heights
    H = Hfull[j0:j1, i0:i1]
    ny, nx = H.shape
    res = e.resolution
    vb, _, mg = _bounds(world)
    ox, oy = e.origin[0] + i0 * res, e.origin[1] + j0 * res
    blocked = blocked_cells(world)[j0:j1, i0:i1].ravel()
    if e.terrain_layer is not None and len(world.terrains) > 1:
        terrain = e.terrain_layer[j0:j1, i0:i1].ravel()
    else:
        terrain = np.zeros(nx * ny, np.int64)
    mu = np.array([t.mu_roll for t in world.terrains])[terrain]
    gy, gx = np.gradient(H, res)
    # per cell: mu m g cos(steepest slope of the cell), a lower bound of the rolling force
    froll_cell = mu * mg * np.cos(np.minimum(np.arctan(np.hypot(gx, gy)), math.radians(scn.planner.tip_over_deg))).ravel()
    copper = copper_coefficient(world)
    src, dst, w = [], [], []
    kegrid = 1.0
    for p, q, up, d in grid_steps(H, blocked, res, math.tan(climb_limit(world))):
        if cost == "time":
            # the faster of the two cells' terrains: either may be under the vehicle
            grade = np.arctan(up)
            wt = d / np.maximum(step_speed_bounds(world, terrain[p], grade, vb),
                                step_speed_bounds(world, terrain[q], grade, vb))
        else:
            f = np.minimum(froll_cell[p], froll_cell[q])
            rise = mg * (H.ravel()[q] - H.ravel()[p])
            wt = least_step_energy(f, rise, d, copper)
            if p.size:
                kegrid = max(kegrid, ke_factor(f, rise, d, copper))
        # reversed edges: Dijkstra runs from where the way ends
        src.append(q)
        dst.append(p)
        w.append(wt / OCTILE + 1e-12)
    cat = (lambda parts, dt: np.concatenate(parts) if parts else np.zeros(0, dt))
    return StepGraph((j0, j1, i0, i1), H, res, ox, oy, blocked, froll_cell, copper, kegrid,
                     cat(src, np.int64), cat(dst, np.int64), cat(w, float))


@_cached_but_corridors
def cost_to_go(world: World, cost: str, max_cells: int = CTG_MAX_CELLS) -> tuple:
    """Lower bound of the cost [s or J] from every map node to the goal disc (Dijkstra
    over 8-neighbour steps, see :mod:`sbmpc.problems.skidsteer`; a time step takes its
    length over :func:`step_speed_bounds`, an energy step :func:`least_step_energy`), the largest rolling
    force [N] of the map's cells (for the heuristic's bound of the way from a node to a
    pose between the nodes, ``skidsteer._node_to_pose``), the factor
    its kinetic-energy credit takes (:func:`ke_factor` over the grid's steps; 1 for
    time) and the goal's gap [s or J] the heuristic subtracts (:func:`_goal_gap`). Unreachable
    nodes get a large finite cost. With ``world.keep_out`` (a corridor search,
    :mod:`sbmpc.planning.corridor`) a node in the corridor gets the least cost of the ways that
    stay in it, one off it (or with no way that stays in it) the whole map's value plus
    OFF_CORRIDOR: the search expands every node of the corridor it would open before
    any other, and goes on over the whole map, guided as without a corridor, where the
    corridor holds no way (the values are then no lower bounds: the corridor's plan is
    the best the weighted search finds along the coarse route). Cached per (world,
    cost): planning and replaying share it.

    On a map larger than ``max_cells`` the grid covers :func:`ctg_window` only (memory
    and time grow with the cells: a 5000 x 5000 map needed over 8 GB): every cell on the
    window's edge (not the map's) may also leave it, at the straight-line bound of the
    rest (divided by the grid's detour factor, as every step is), so the window's values
    stay lower bounds of the whole map's; outside the window the grid gives 0 and the
    straight-line bound of the heuristic applies."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    e, scn = world.emap, world.scenario
    graph = step_graph(world, cost, max_cells)
    j0, j1, i0, i1 = graph.window
    Hfull, H, res, ox, oy = e.heights, graph.H, graph.res, graph.ox, graph.oy
    ny, nx = H.shape
    vb, froll, mg = _bounds(world)
    blocked, froll_cell, copper, kegrid = graph.blocked, graph.froll_cell, graph.copper, graph.kegrid
    src, dst, w = [graph.src], [graph.dst], [graph.w]
    X, Y = np.meshgrid(ox + res * np.arange(nx), oy + res * np.arange(ny))
    g = scn.goal
    goal_nodes = np.flatnonzero((((X - g["x"]) ** 2 + (Y - g["y"]) ** 2) <= g["radius"] ** 2).ravel() & ~blocked)
    if goal_nodes.size == 0:
        return np.zeros(e.shape), 0.0, 1.0, 0.0
    # on a window, a source node (index nx * ny) joined to the goal at 0 and to every
    # cell of the window's inner edges at the straight-line bound from there
    S = nx * ny
    edge = np.zeros((ny, nx), bool)
    full_ny, full_nx = e.shape
    if j0 > 0:
        edge[0, :] = True
    if j1 < full_ny:
        edge[-1, :] = True
    if i0 > 0:
        edge[:, 0] = True
    if i1 < full_nx:
        edge[:, -1] = True
    exits = np.flatnonzero(edge.ravel() & ~blocked)
    @functools.cache
    def lowest_goal() -> float:
        """The goal disc's lowest height [m] (found when a bound first needs it)."""
        return _lowest_in_disc(e, g["x"], g["y"], g["radius"])

    def line_bound(x, y, z):
        """The straight-line bound [s or J] from points (x, y, z) [m] to the goal disc:
        what a cell on the window's edge takes to leave it, and (a corridor search) a
        node off both the window and the corridor."""
        dist = np.maximum(np.hypot(x - g["x"], y - g["y"]) - g["radius"], 0.0)
        if cost == "time":
            return dist / vb
        return np.maximum(0.0, froll * dist + mg * (lowest_goal() - z))
    if exits.size:
        src.append(np.full(exits.size, S))
        dst.append(exits)
        w.append(line_bound(X.ravel()[exits], Y.ravel()[exits], H.ravel()[exits]) / OCTILE + 1e-12)
        src.append(np.full(goal_nodes.size, S))
        dst.append(goal_nodes)
        w.append(np.zeros(goal_nodes.size))       # (explicit zeros are edges to csgraph)
    src, dst, w = np.concatenate(src), np.concatenate(dst), np.concatenate(w)

    def solve(keep, goals):
        """Dijkstra over the steps ``keep`` from the goal's nodes ``goals``."""
        G_ = coo_matrix((w[keep], (src[keep], dst[keep])), shape=(S + 1, S + 1)).tocsr()
        if exits.size:
            D = dijkstra(G_, indices=S)[:S]
        else:
            D = dijkstra(G_, indices=goals, min_only=True)[:S] if goals.size else np.full(S, np.inf)
        D[~np.isfinite(D)] = 1e12
        return D
    D = solve(np.ones(src.size, bool), goal_nodes)
    if world.keep_out is not None:
        # a corridor search (sbmpc.planning.corridor): inside the corridor the least cost of the ways
        # that stay in it; off it (or where none stays in it) the whole map's plus OFF_CORRIDOR
        off = np.r_[world.keep_out[j0:j1, i0:i1].ravel(), False]      # (the source node S is in)
        inside = solve(~(off[src] | off[dst]), goal_nodes[~off[goal_nodes]])
        D = np.where(inside < 1e12, inside, D + OFF_CORRIDOR)
    if (j0, j1, i0, i1) == (0, full_ny, 0, full_nx):
        out = D.reshape(ny, nx)
    else:
        out = np.zeros(e.shape)
        out[j0:j1, i0:i1] = D.reshape(ny, nx)
        if world.keep_out is not None:
            # off the window and off the corridor: the straight-line bound the heuristic
            # takes there (the window's exits' bound), plus OFF_CORRIDOR
            beyond = np.ones(e.shape, bool)
            beyond[j0:j1, i0:i1] = False
            jj, ii = np.nonzero(beyond & world.keep_out)
            out[jj, ii] = line_bound(e.origin[0] + res * ii, e.origin[1] + res * jj, Hfull[jj, ii]) + OFF_CORRIDOR
    out.setflags(write=False)        # cached and shared
    frmax = float(froll_cell.max())
    gap = _goal_gap(e, g, X.ravel()[goal_nodes], Y.ravel()[goal_nodes], H.ravel()[goal_nodes],
                    cost, vb, frmax, mg, copper)
    if cost == "time":
        gap += CARRY_S            # a climb entered faster than its steady top speed
    return out, frmax, kegrid, gap


def _goal_gap(e: ElevationMap, goal: dict, qx, qy, qz, cost, vb, frmax, mg, copper, n: int = 720) -> float:
    """The most the grid may charge beyond where a path ends [s or J]: a path ends where
    it first touches the goal disc, the grid where it reaches a node inside the disc
    (value 0), up to about a cell further. The largest, over points b of the disc's
    edge (``n`` samples, their spacing added to the distances), of the least bound of
    the way from b to one of the goal's nodes q (``qx, qy, qz``): distance / v_bound for
    time, the energy step bound at the map's largest rolling force for the climb from b
    to q. The heuristic subtracts it (for time with CARRY_S added by :func:`cost_to_go`):
    its constant shift of every value leaves the weighted search's order as it is."""
    if len(qx) == 0:
        return 0.0
    r = goal["radius"]
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    bx, by = goal["x"] + r * np.cos(a), goal["y"] + r * np.sin(a)
    bz = np.array([e.height(x, y) for x, y in zip(bx, by)])
    d = np.hypot(bx[:, None] - qx[None, :], by[:, None] - qy[None, :]) + np.pi * r / n
    if cost == "time":
        way = d / vb
    else:
        way = least_step_energy(frmax, mg * (qz[None, :] - bz[:, None]), d, copper)
    return float(way.min(axis=1).max())


def _max_rise(H, res, dist):
    """Largest height gain [m] within ``dist`` [m] on the map (from its steepest slope)."""
    gy, gx = np.gradient(H, res)
    return float(np.hypot(gx, gy).max() * dist)


# ---- reachability pre-check -----------------------------------------------------------
@njit(cache=True, error_model="numpy", nogil=True)
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


CLIMB_CHECK_MAX_CELLS = 250_000   # larger maps skip steepest_climb_needed (0.6 s at this size)


def steepest_climb_needed(world: World, xy: tuple | None = None, tol_deg: float = 0.05) -> float | None:
    """The least, over the ways from the start (or the position ``xy``) to the goal disc,
    of the steepest uphill grade [rad] a way climbs (a bottleneck path over the cost-to-go
    grid's 8-neighbour steps, :func:`grid_steps`, from the cell nearest the position,
    bisected to ``tol_deg``): every way climbs at least this steeply somewhere. None when
    not even the grid's steps (up to :func:`climb_limit`) reach the position, on maps
    over CLIMB_CHECK_MAX_CELLS cells (not checked) or when the goal disc holds no grid
    node. Computed on a failed search only (the grid's steps once, then about twelve
    breadth-first searches over those up to a grade: 0.03 s on a 120 x 120 map)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order
    e, scn = world.emap, world.scenario
    ny, nx = e.shape
    if nx * ny > CLIMB_CHECK_MAX_CELLS:
        return None
    sx, sy = xy if xy is not None else (scn.start["x"], scn.start["y"])
    ox, oy = e.origin
    res = e.resolution
    j, i = _node(world, sx, sy)
    start = j * nx + i
    X, Y = np.meshgrid(ox + res * np.arange(nx), oy + res * np.arange(ny))
    g = scn.goal
    blocked = off_limits(world).ravel()
    goal = np.flatnonzero((((X - g["x"]) ** 2 + (Y - g["y"]) ** 2) <= g["radius"] ** 2).ravel() & ~blocked)
    if goal.size == 0:
        return None

    lo, hi = 0.0, climb_limit(world)
    # every step up to the grid's climb limit, once; each test keeps those up to its grade
    steps = list(grid_steps(e.heights, blocked, res, math.tan(hi)))
    src = np.concatenate([np.full(goal.size, nx * ny)] + [q for _, q, _, _ in steps])   # reversed: from the goal
    dst = np.concatenate([goal] + [p for p, _, _, _ in steps])
    up = np.concatenate([np.full(goal.size, -np.inf)] + [u for _, _, u, _ in steps])  # (the source joins the goal)

    def reaches(grade: float) -> bool:
        k = up <= math.tan(grade)
        G = coo_matrix((np.ones(int(k.sum())), (src[k], dst[k])), shape=(nx * ny + 1, nx * ny + 1)).tocsr()
        return bool(np.isin(start, breadth_first_order(G, nx * ny, return_predecessors=False)))
    if not reaches(hi):
        return None
    if reaches(lo):
        return 0.0
    while hi - lo > math.radians(tol_deg):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if reaches(mid) else (mid, hi)
    return hi


def unreachable_reason(world: World, xy: tuple | None = None) -> str | None:
    """Why no path can exist, when the goal disc is cut off from the start (or from the
    position ``xy``) by cells where the vehicle tips over at every heading, or by those
    and the band along the map's edge its centre cannot enter (:func:`off_limits`;
    checked at cell centres); else None."""
    e, scn = world.emap, world.scenario
    sx, sy = xy if xy is not None else (scn.start["x"], scn.start["y"])
    ox, oy = e.origin
    labels, _ = ndimage.label(~off_limits(world), structure=np.ones((3, 3)))
    cell = functools.partial(_node, world)
    here = cell(sx, sy)
    s = labels[here]
    ny, nx = e.shape
    X, Y = np.meshgrid(ox + e.resolution * np.arange(nx), oy + e.resolution * np.arange(ny))
    g = scn.goal
    in_goal = (X - g["x"]) ** 2 + (Y - g["y"]) ** 2 <= max(g["radius"], 0.5 * e.resolution) ** 2
    in_goal[cell(g["x"], g["y"])] = True
    if s == 0:
        if not blocked_cells(world)[here]:
            return None       # in the band only (a map barely wider than the footprint): the search judges
        return f"the start stands on a slope beyond the tip-over limit of {scn.planner.tip_over_deg:g} deg at every heading"
    if not np.any(labels[in_goal] == s):
        tip, _ = ndimage.label(~blocked_cells(world), structure=np.ones((3, 3)))
        if tip[here] != 0 and np.any(tip[in_goal] == tip[here]):
            return (f"the only ways from the start to the goal between slopes beyond the tip-over limit of "
                    f"{scn.planner.tip_over_deg:g} deg run along the map's edge, closer to it than the vehicle's "
                    f"half-diagonal ({world.margin:.3f} m): no path can exist")
        return (f"the goal is cut off from the start by slopes beyond the tip-over limit of "
                f"{scn.planner.tip_over_deg:g} deg (no heading crosses them); no path can exist")
    return None
