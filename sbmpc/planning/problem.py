"""The search problem of a world: the skid-steer's packed parameters and data
(:mod:`sbmpc.problems.skidsteer`), its control set, grid and weight, and the backend
its edges run on (the CPU's cores or a GPU)."""
from __future__ import annotations

import functools
import math

import numpy as np

from dynamics import kernels as K
from dynamics.resistance import friction_table
from maps.grid import aside_tilts, steepest_near

from .heuristics import _bounds, _lowest_in_disc, copper_coefficient, cost_to_go
from .value import value
from ..problems import skidsteer as SS
from ..search.astar import Problem
from .world import FIXED_CONTROLS, World, _start, control_set, hold_mode, pessimistic

SETTLE_DEPTH = 3      # edges from the start within which a child may stay in its parent's grid cell


def standing_tilt(world: World, X: np.ndarray, aside: float = 0.0) -> float:
    """The larger of the pitch's and the roll's magnitudes [rad] of a vehicle at the
    planner state X on the world's map, as the edges judge the tip-over limit and its
    margin (:func:`maps.grid.pitch_roll_at`; 0 off the map); with ``aside`` [m] the
    largest also over the vehicle moved that far to its left and right, as the edges
    judge the margin (``planner.margin_aside_m``, :func:`maps.grid.aside_tilts`)."""
    e = world.emap
    x, y, yaw = float(X[K.S_X]), float(X[K.S_Y]), float(X[K.S_YAW])
    if not e.contains(x, y):
        return 0.0
    p, r = e.pitch_roll(x, y, yaw, world.half_length, world.half_width)
    tilt = max(abs(p), abs(r))
    if aside > 0.0:
        tilt = max(tilt, math.atan(aside_tilts(e.heights, e.resolution, e.origin[0], e.origin[1], x, y, yaw,
                                               world.half_length, world.half_width, aside)))
    return tilt


def from_inside(Q: np.ndarray, world: World, X: np.ndarray) -> np.ndarray:
    """The params Q for a search from X where X already stands inside the tip-over margin
    (steeper than ``tip_over_deg - margin_tip_deg`` on the map, a vehicle that drifted
    onto a flank): its margin's limit raised to where X stands, so that the search's
    edges may lead out of it and none steeper (every edge from there failed on the margin
    at its first step, and the fallback without the margin rode the tip-over limit
    itself); Q itself elsewhere (a copy where changed). Where X stands outside the margin
    but nearer the band than the allowance aside (``planner.margin_aside_m``: a vehicle
    that drifted towards a wall), the allowance is shrunk to the clearance X has
    (:func:`_clearance`), not the limit raised: the edges may then come no nearer the
    wall than X stands (raising the limit to the tilt a full allowance aside, past the
    tip-over limit beside `narrow_pass`'s wall, let the plans drive along the wall's foot
    and the guard held every period there, 2026-12-07)."""
    aside = Q[SS.Q_ASIDE]
    if aside > 0.0 and standing_tilt(world, X, aside) > Q[SS.Q_TIPM]:
        Q = Q.copy()
        Q[SS.Q_ASIDE] = _clearance(world, X, aside, Q[SS.Q_TIPM])
    tilt = standing_tilt(world, X, Q[SS.Q_ASIDE])
    if tilt <= Q[SS.Q_TIPM] or Q[SS.Q_TIPM] >= Q[SS.Q_TIP]:
        return Q
    Q = Q.copy()
    Q[SS.Q_TIPM] = min(tilt + 1e-9, Q[SS.Q_TIP])
    return Q


def _clearance(world: World, X: np.ndarray, aside: float, limit: float) -> float:
    """The largest allowance aside [m], at most ``aside``, with which X's tilt stays
    within ``limit`` [rad] (0 where X itself is beyond it): bisection to a millimetre."""
    if standing_tilt(world, X) > limit:
        return 0.0
    lo, hi = 0.0, aside
    while hi - lo > 1e-3:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if standing_tilt(world, X, mid) <= limit else (lo, mid)
    return lo


@functools.lru_cache(maxsize=8)
def slope_layer(world: World) -> np.ndarray:
    """The map's steepest slope near each cell (:func:`maps.grid.steepest_near`, flat),
    within the vehicle's footprint and its allowance aside (``planner.margin_aside_m``):
    made once per world (every re-plan and repair packs the world again; on a 360 m
    field at 0.25 m it takes about 0.1 s)."""
    ps = world.scenario.planner
    layer = steepest_near(world.emap.heights, world.emap.resolution,
                          math.hypot(world.half_length, world.half_width + ps.margin_aside_m)).ravel()
    layer.setflags(write=False)        # cached and shared
    return layer


def pack_world(world: World, cost: str, dt: float | None = None, margin: bool = False,
               grid: bool = True) -> tuple:
    """(params, data) flat arrays of :mod:`sbmpc.problems.skidsteer` for a world and cost, with
    the edges integrated at ``dt`` [s] (default the planner's step). ``margin``: edges
    must also keep the planner's margin (``planner.margin``, ``margin_tip_deg``: the
    search's and the polish's edges); without it an edge fails only where the vehicle
    does (the checks, the runs' drives); with it and ``planner.value`` the value over
    position and heading (:mod:`sbmpc.planning.value`) is packed too. ``grid`` False: no cost-to-go grid (a drive
    that only replays controls, ``skidsteer.replay``, never reads it; its slot holds
    one infinite value and the heuristic's constants 0)."""
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
    offs = -1
    if margin and ps.margin_aside_m > 0.0 and nx > 1 and ny > 1:
        # the steepest slope near each cell within the footprint and its allowance aside:
        # the edges skip the allowance's check where no slope there passes the limit
        offs = sum(p.size for p in parts)
        parts.append(slope_layer(world))
    offt = sum(p.size for p in parts)
    ctg, frmax, kegrid, gap = cost_to_go(world, cost) if grid else (np.full((1, 1), np.inf), 0.0, 0.0, 0.0)
    twins = []
    if margin and ps.margin > 0.0:
        # the margin's pessimistic twin (skidsteer.edge): heavier, more grip, by the margin
        tw = pessimistic(world)
        twins = [np.concatenate([K.pack(tw.vehicle, tt), friction_table(tw.vehicle, tt)]) for tt in tw.terrains]
    offw = offt + sum(b.size for b in blocks)
    offd = offw + sum(b.size for b in twins)
    val = value(world, cost) if grid and margin and ps.value else None
    offv = offd + ctg.size
    data = np.ascontiguousarray(np.concatenate(parts + blocks + twins + [ctg.ravel()]
                                               + ([val.V.ravel()] if val is not None else [])))
    Q = np.zeros(SS.NQ)
    Q[SS.Q_DT] = dt
    Q[SS.Q_NSTEP] = max(1, round(ps.period_s / dt))
    Q[SS.Q_GX], Q[SS.Q_GY], Q[SS.Q_GR] = scn.goal["x"], scn.goal["y"], scn.goal["radius"]
    Q[SS.Q_HL], Q[SS.Q_HW] = world.half_length, world.half_width
    tip = math.radians(ps.tip_over_deg)
    Q[SS.Q_TIP] = tip
    Q[SS.Q_TIPM] = tip - math.radians(ps.margin_tip_deg) if margin else tip
    Q[SS.Q_RESERVE] = ps.margin_turn if margin else 0.0
    Q[SS.Q_OFFTW] = offw if twins else -1
    Q[SS.Q_TWHEAD] = math.radians(ps.margin_heading_deg)
    Q[SS.Q_TWGRADE] = math.radians(ps.margin_grade_deg)
    Q[SS.Q_ASIDE] = ps.margin_aside_m if margin else 0.0     # searches only: a drive judges the pose itself
    Q[SS.Q_OFFS] = offs
    Q[SS.Q_TWLAG] = scn.run.tol_xy     # the most the twin falls behind: a run re-plans beyond it
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
    Q[SS.Q_FRMAX] = frmax       # the largest rolling force of the map's cells (the way from a node to a pose)
    Q[SS.Q_KEGRID] = kegrid        # the step bounds' largest slope dE/dW (heuristics.ke_factor)
    Q[SS.Q_COPPER] = copper_coefficient(world)
    Q[SS.Q_GOALGAP] = gap          # the grid's reach past a path's end in the disc (heuristics._goal_gap)
    Q[SS.Q_OFFV] = offv if val is not None else -1    # the value over position and heading (planning.value)
    if val is not None:
        Q[SS.Q_VNY], Q[SS.Q_VNX] = val.V.shape[:2]
        Q[SS.Q_VCELL], Q[SS.Q_VOX], Q[SS.Q_VOY] = val.cell, val.ox, val.oy
        Q[SS.Q_VW2] = ps.value_w2 if cost == "time" else ps.value_energy_w2
    return Q, data


def problem(world: World, cost: str, start: np.ndarray | None = None, dt: float | None = None,
            inside: bool = True) -> Problem:
    """The search problem of a world and cost, from ``start`` (a planner state, default
    the scenario's start state), its edges integrated at ``dt`` [s] (default the
    planner's step). ``inside``: a start inside the tip-over margin raises its limit
    (:func:`from_inside`); False for a template whose searches start elsewhere (the
    horizon planner's: each of its plans does so from its own start)."""
    ps = world.scenario.planner
    Q, data = pack_world(world, cost, dt, margin=True)
    dims = np.array([K.S_X, K.S_Y, SS.X_YAWW, SS.X_V], np.int64)
    res = np.array([ps.cell_xy, ps.cell_xy, math.radians(ps.cell_yaw_deg), ps.cell_v])
    X0 = _start(world, start)
    if inside:
        Q = from_inside(Q, world, X0)
    if on_gpu(ps):
        from ..problems.skidsteer_cuda import CudaEdges
        batch = CudaEdges(Q, data)
    else:
        batch = SS.expand_batch
    return Problem(SS.expand, SS.heuristic, SS.is_goal, Q, data, X0, control_set(world),
                   dims, res, ps.branching, rotate=ps.samples == "rotating", hold=hold_mode(ps),
                   fixed_controls=len(FIXED_CONTROLS), snap=False, codes=SS.CODES, settle_depth=SETTLE_DEPTH,
                   weight=ps.weight(cost), refine=ps.refine, expand_batch=batch)


GPU_BATCH = 64     # nodes per batch on a GPU (batch 0: auto): 1024 edges at branching 16
CPU_BATCH = 16     # nodes per batch on several CPU threads (batch 0: auto; one thread: 1)


def device_note(ps) -> str | None:
    """One line when the scenario asks for the GPU and it cannot be used (the CPU plans
    instead), else None."""
    if ps.device != "cuda":
        return None
    from ..problems.skidsteer_cuda import unavailable
    why = unavailable()
    return None if why is None else f"device cuda: {why}; planning on the CPU"


def on_gpu(ps) -> bool:
    """Whether the edges of this planner's searches run on the GPU."""
    return ps.device == "cuda" and device_note(ps) is None


def batch_size(ps) -> int:
    """Nodes whose edges are simulated together: the scenario's, or with 0 (auto)
    GPU_BATCH on a GPU, CPU_BATCH on several CPU threads and 1 on one. The plan is the
    serial search's either way; a batch pays in edges simulated for nodes the search
    then does not expand (bench/results/planner.json, docs/performance.md#planner)."""
    if ps.batch:
        return ps.batch
    if on_gpu(ps):
        return GPU_BATCH
    return CPU_BATCH if search_threads(ps) != 1 else 1


def search_threads(ps):
    """Threads for the search's edges: the scenario's, or with 0 "auto" (every core numba
    uses, unless measurements during the search find the serial expander faster: cores
    busy with other work). On the GPU, None: the edges run there (measuring the serial
    CPU expander against it would hand it a dozen whole batches), and numba's thread
    count is left alone for the CPU work around the search (the polish, the checks)."""
    if on_gpu(ps):
        return None
    if ps.threads:
        return ps.threads
    import numba
    return "auto" if numba.config.NUMBA_NUM_THREADS > 1 else 1

