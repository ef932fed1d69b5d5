"""Coarse to fine: a quick search on coarse cells finds a route, and the planner's own
search then looks along it first (``planner.corridor_energy``, ``corridor_time``: the
corridor's half-width [m]; 0 searches the whole map as before).

The coarse search is the same search with every cell twice as large (position cells up
to COARSE_CELL_XY, heading, speed), half the controls per expansion (at least
COARSE_BRANCHING), a weight of at least COARSE_WEIGHT and at most COARSE_MAX_EXPANSIONS
expansions: it finds some way to the goal in a fraction of the fine search's expansions,
dearer than the fine plan. The fine search's cost-to-go grid then holds, for the nodes within the half-width of that route's
path, the least cost of the ways that stay in the corridor, and for every other node the
whole map's value plus ``heuristics.OFF_CORRIDOR`` (:func:`narrowed`,
``heuristics.cost_to_go``): the grid rises where the route bends round hills the
straight line would cross, the search opens the corridor's nodes before any other and
ends in fewer expansions; where the corridor holds no way to the goal it goes on over
the whole map, guided as without a corridor. Where the coarse search finds no route
within its budgets, the fine search runs on the whole map as without it. The coarse
search's time comes out of the plan's time budget (it takes at most COARSE_TIME_SHARE of
it); its expansions are counted in the plan's but not charged to the search's node
budget. A corridor world's grid is not cached (``heuristics.cost_to_go``). Measured in
docs/performance.md#coarse-to-fine.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from dynamics import kernels as K

from .check import replay
from .problem import problem
from ..search.astar import Search
from .world import World

COARSE_WEIGHT = 1.3            # the coarse search's least weight of h
COARSE_CELL_XY = 1.0           # m: its position cells are twice the search's, up to this (or the search's own):
                               # 2 m cells on hills_field merged the states that pass between hills
COARSE_BRANCHING = 8           # its controls per expansion: half the search's, at least this (or the search's own)
COARSE_MAX_EXPANSIONS = 20_000  # the coarse search's node budget (at most the planner's own; its
                                # expansions are counted in the plan's, not charged to the search's budget)
COARSE_TIME_SHARE = 0.25       # ... and at most this share of the plan's time budget


@dataclass(frozen=True)
class Coarse:
    """What the coarse search did (plan JSON ``coarse``): its status ('found': the fine
    search looked along its route first; 'no_path': the fine search ran on the whole
    map), expansions, edges simulated, seconds, its route's cost at the planner's step
    (None without a route) and the corridor's half-width [m]."""

    status: str
    expansions: int
    edges: int
    seconds: float
    cost: float | None
    half_width_m: float

    def to_json(self) -> dict:
        return {"status": self.status, "expansions": self.expansions, "edges_simulated": self.edges,
                "seconds": self.seconds, "cost": self.cost, "half_width_m": self.half_width_m}


def coarse_world(world: World, cost: str) -> World:
    """The world of the coarse search: cells twice as large (position cells up to
    COARSE_CELL_XY), half the controls (at least COARSE_BRANCHING), a weight of at least
    COARSE_WEIGHT, its node budget capped, no polish, no check against the other cost."""
    ps = world.scenario.planner
    w = max(ps.weight(cost), COARSE_WEIGHT)
    coarse = replace(ps, cell_xy=max(ps.cell_xy, min(2.0 * ps.cell_xy, COARSE_CELL_XY)),
                     cell_yaw_deg=min(2.0 * ps.cell_yaw_deg, 180.0), cell_v=2.0 * ps.cell_v,
                     branching=min(ps.branching, max(COARSE_BRANCHING, ps.branching // 2)),
                     max_expansions=min(ps.max_expansions, COARSE_MAX_EXPANSIONS), refine=0.0,
                     time_weight=w if cost == "time" else ps.time_weight,
                     energy_weight=w if cost == "energy" else ps.energy_weight,
                     polish_time=False, polish_energy=False, energy_vs_time=False)
    return replace(world, scenario=replace(world.scenario, planner=coarse), keep_out=None)


def corridor_mask(world: World, xy: np.ndarray, half_width: float) -> np.ndarray:
    """(ny, nx) True at the grid nodes farther than ``half_width`` [m] from every point of
    the path ``xy`` (n, 2) [m] (points on the map, one cell or closer apart)."""
    e = world.emap
    ny, nx = e.shape
    near = np.zeros((ny, nx), bool)
    i = np.clip(np.round((xy[:, 0] - e.origin[0]) / e.resolution).astype(int), 0, nx - 1)
    j = np.clip(np.round((xy[:, 1] - e.origin[1]) / e.resolution).astype(int), 0, ny - 1)
    near[j, i] = True
    # (the path's own nodes are up to half a cell's diagonal from its points)
    return ndimage.distance_transform_edt(~near) * e.resolution > half_width + 0.5 * math.sqrt(2) * e.resolution


def narrowed(world: World, cost: str, X0: np.ndarray, half_width: float, deadline: float) -> tuple:
    """(world, coarse): ``world`` with the nodes off the coarse route's corridor marked
    (``World.keep_out``, for its cost-to-go grid), or ``world`` itself where the coarse
    search found no route; and the :class:`Coarse` record. The coarse search runs on one
    thread for at most COARSE_TIME_SHARE of the time to ``deadline``."""
    cw = coarse_world(world, cost)
    ps = cw.scenario.planner
    t0 = time.perf_counter()
    prob = problem(cw, cost, X0)
    res = Search(prob).run(ps.max_expansions, max(0.0, COARSE_TIME_SHARE * (deadline - t0)), threads=1)
    seconds = time.perf_counter() - t0
    if res.status != "found":
        return world, Coarse("no_path", res.iterations, res.edges_simulated, seconds, None, half_width)
    T = res.states[:, K.S_T]
    controls = [(float(prob.controls[c, 0]), float(prob.controls[c, 1]), round(float(T[k + 1] - T[k]), 9))
                for k, c in enumerate(res.control_rows)]
    traj, *_ = replay(cw, cost, controls, every=1, start=X0)
    xy = np.column_stack([traj["x"], traj["y"]])
    keep_out = corridor_mask(world, xy, half_width)
    keep_out.setflags(write=False)
    return (replace(world, keep_out=keep_out),
            Coarse("found", res.iterations, res.edges_simulated, time.perf_counter() - t0, float(res.cost), half_width))
