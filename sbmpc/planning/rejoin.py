"""The way onto a whole-route plan made beside the horizon: the controller's hand-over
without waiting (:class:`sbmpc.robot.Controller`).

A receding-horizon run hands over to a whole-route plan where its horizon plans find no
way on or make no progress. A whole-route plan made at that moment from where the vehicle
stands is waited for (2.9-15 s in ``bench_controller``); one made beside the horizon from
the start is ready, but the vehicle has driven the horizon's plans since and is rarely on
it (0.03-1.98 m off at four measured hand-overs: docs/research-log.md). So the hand-over
does not drive that plan's controls: it goes on with horizon plans whose terminal cost
leads onto the plan's path and along it (:func:`tube_to_go`), a receding-horizon tracker
of the plan (:func:`tracker`) that the controller's warm start, guard and stall handling
serve as before.

The tracker's cost-to-go is a Dijkstra over the cost-to-go grid's steps
(:func:`sbmpc.planning.heuristics.step_graph`) from every node the plan's path crosses,
each starting at the plan's remaining cost from there (its controller-rate replay), every
step weighed ``kappa`` times its lower bound. With ``kappa`` 1 the cheapest way on would
always be the grid's straight lower bound to the path's end (the lower bound through
any path node is never dearer than its remaining cost), so the path would guide nothing:
``kappa`` is the least factor that makes the path the cheapest way on from its own nodes
(the largest ratio of remaining cost to the grid's lower bound along it, 5 % more,
within [KAPPA_MIN, KAPPA_MAX]). Off the path a node's value is the priced way to the path
plus the rest of the plan: the horizon search then ends its plans on or towards the path,
and drives along it where it can.
"""
from __future__ import annotations

import numpy as np

from dynamics import kernels as K

from ..problems import skidsteer as SS
from . import heuristics as HE
from . import plan as PL
from .horizon import HorizonPlanner, periods
from .world import World

KAPPA_MIN = 1.05    # the least a step off the plan's path is charged over its lower bound
KAPPA_MAX = 4.0     # ... and the most (a plan around a hill the grid sees as crossable)
FAR = 1e12          # s or J: a node with no way to the path (or off the grid's window)


def tube_to_go(world: World, cost: str, trajectory: dict) -> tuple:
    """(grid, kappa): the cost-to-go [s or J] from every map node (an array of the map's
    shape, as :func:`sbmpc.planning.heuristics.cost_to_go`'s) onto the path of a plan's
    ``trajectory`` (channels x, y [m] and t [s] or energy_J [J], its controller-rate
    replay) and along it to its end, and the factor ``kappa`` its steps off the path
    are weighed by (module doc). Nodes with no way to the path get FAR."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra
    graph = HE.step_graph(world, cost)
    j0, j1, i0, i1 = graph.window
    ny, nx = graph.H.shape
    c = np.asarray(trajectory["t" if cost == "time" else "energy_J"], float)
    rest = c[-1] - c
    i = np.rint((np.asarray(trajectory["x"], float) - graph.ox) / graph.res).astype(np.int64)
    j = np.rint((np.asarray(trajectory["y"], float) - graph.oy) / graph.res).astype(np.int64)
    inside = (i >= 0) & (i < nx) & (j >= 0) & (j < ny)
    node = j[inside] * nx + i[inside]
    rest = rest[inside]
    free = ~graph.blocked[node]
    best = np.full(nx * ny, np.inf)
    np.minimum.at(best, node[free], rest[free])
    seeds = np.flatnonzero(np.isfinite(best))
    out = np.full(world.emap.shape, FAR)
    if seeds.size == 0:
        return out, KAPPA_MAX
    lower = HE.cost_to_go(world, cost)[0][j0:j1, i0:i1].ravel()[seeds]
    r = best[seeds]
    ok = (lower > 0.05 * lower.max()) & (lower < FAR)
    kappa = float(np.clip(1.05 * np.max(r[ok] / lower[ok]), KAPPA_MIN, KAPPA_MAX)) if ok.any() else KAPPA_MAX
    S = nx * ny
    src = np.concatenate([graph.src, np.full(seeds.size, S)])
    dst = np.concatenate([graph.dst, seeds])
    w = np.concatenate([kappa * graph.w, r + 1e-12])          # (explicit zeros are edges to csgraph)
    G = coo_matrix((w, (src, dst)), shape=(S + 1, S + 1)).tocsr()
    D = dijkstra(G, indices=S)[:S]
    D[~np.isfinite(D)] = FAR
    out[j0:j1, i0:i1] = D.reshape(ny, nx)
    return out, kappa


def tracker(world: World, cost: str, plan: PL.Plan) -> HorizonPlanner:
    """A horizon planner of ``world`` and ``cost`` whose terminal cost is
    :func:`tube_to_go` of ``plan`` (a found whole-route plan): its plans lead onto the
    plan's path and along it (module doc)."""
    grid, kappa = tube_to_go(world, cost, plan.trajectory)
    hp = HorizonPlanner.of(world, cost, grid)
    hp.tracks = (plan, kappa)
    return hp


def path_distances(plan: PL.Plan, X: np.ndarray) -> np.ndarray:
    """How far [m] the planner state X is from each sample of ``plan``'s trajectory
    (its controller-rate replay), in the plane."""
    tr = plan.trajectory
    return np.hypot(np.asarray(tr["x"]) - X[K.S_X], np.asarray(tr["y"]) - X[K.S_Y])


def join(plan: PL.Plan, X: np.ndarray, period_s: float, tick_s: float, tol_xy: float, tol_yaw: float,
         tol_v: float) -> list | None:
    """The rest of ``plan``'s controls [(wl, wr, duration_s)] in periods of ``period_s``
    (:func:`sbmpc.planning.horizon.periods`) from the sample of its trajectory where
    the planner state X joins it, or None where none does: the samples on the
    ``tick_s`` grid of the plan's time (a robot's loop commands whole control periods)
    within ``tol_xy`` [m], ``tol_yaw`` [rad] and ``tol_v`` [m/s] of X (a run's re-plan
    tolerances: a vehicle there would not have re-planned), the nearest in position
    taken (the later of equals). The first piece is what is left of the period the
    sample falls in."""
    tr = plan.trajectory
    t = np.asarray(tr["t"], float) - tr["t"][0]
    on_tick = np.abs(t / tick_s - np.rint(t / tick_s)) < 1e-6
    d = path_distances(plan, X)
    dyaw = np.abs(np.remainder(np.asarray(tr["yaw"]) - X[K.S_YAW] + np.pi, 2.0 * np.pi) - np.pi)
    ok = on_tick & (d <= tol_xy) & (dyaw <= tol_yaw) & (np.abs(np.asarray(tr["v"]) - X[SS.X_V]) <= tol_v)
    ok[-1] = False                       # (the end: nothing left to drive)
    if not ok.any():
        return None
    k = np.flatnonzero(ok)
    k = k[d[k] <= d[k].min() + 1e-9][-1]
    tau, out, start = float(t[k]), [], 0.0
    for wl, wr, dur in periods(plan.controls, period_s):
        end = start + dur
        if end > tau + 1e-9:
            out.append((wl, wr, round(end - max(start, tau), 9)))
        start = end
    return out or None


class Cancelled(Exception):
    """A plan made beside was called off (:func:`beside`'s ``cancel`` set)."""


def _calls_off(cancel):
    """A search's progress callback that raises :class:`Cancelled` once ``cancel`` (a
    threading.Event) is set: the search stops at its next budget check."""
    def progress(*_):
        if cancel.is_set():
            raise Cancelled("the plan made beside was called off")
    return progress


def beside(world: World, cost: str, start: np.ndarray, cancel=None) -> tuple:
    """(plan, tracker or None): a whole-route plan of ``world`` for ``cost`` from the
    planner state ``start`` (:func:`sbmpc.planning.plan.plan`, its own budget) and, where
    it found one, the horizon planner that tracks it (:func:`tracker`). What the
    controller's third worker makes beside the horizon.
    ``cancel``: a threading.Event that calls it off (:class:`Cancelled` raised at the
    search's next budget check)."""
    progress = None if cancel is None else _calls_off(cancel)
    p = PL.plan(world, cost, progress=progress, start=start, time_progress=progress)
    if cancel is not None and cancel.is_set():
        raise Cancelled("the plan made beside was called off")
    return p, (tracker(world, cost, p) if p.found else None)


__all__ = ["KAPPA_MAX", "KAPPA_MIN", "Cancelled", "beside", "join", "path_distances", "tracker", "tube_to_go"]
