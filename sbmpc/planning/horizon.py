"""Receding-horizon SBMPC: a search that looks ``planner.horizon_s`` seconds ahead.

The whole-route search (:mod:`sbmpc.planning.plan`) ends in the goal disc; its answer costs the
whole route, and a robot waits for it. A horizon search is the same graph search over
the same closed-loop model and the same sampled wheel speeds, stopped at a horizon: a
node whose planner time reaches ``start time + horizon_s`` (or that enters the goal disc)
is terminal (:func:`sbmpc.problems.skidsteer.is_goal`). The open set is ordered by
f = g + w h, so the first terminal node taken out is the one of least cost over the
horizon plus the heuristic's cost to go from where it ends: the admissible cost-to-go
grid over the whole map (:func:`sbmpc.planning.heuristics.cost_to_go`, computed once per world
and cost and kept between plans) is the terminal cost. What the horizon cannot see the
grid does: a hill the vehicle cannot climb is a detour in the grid's values only where
its cells tip the vehicle over (the grid knows no drive limits); a run-up is found only
where it fits in the horizon.

Warm start: the previous horizon plan, less the period the vehicle drives while the next
plan is made, its last control held one period more, is driven from the new start with
the planner's model; where it holds, its cost plus the terminal cost bounds the search
(no node that cannot beat it is opened) and it is the plan when the search finds
nothing better within its budget (``found_by: previous``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from dynamics import kernels as K

from .problem import batch_size, from_inside, problem, search_threads
from ..problems import skidsteer as SS
from ..search.astar import Search
from .world import World, _start, start_state, wheel_speed_range


CHUNK = 8          # expansions between the search's budget checks
PROGRESS = 0.5     # a warm start is kept where its terminal cost falls by this share of its cost


@dataclass(frozen=True)
class HorizonPlan:
    """One horizon plan: ``controls`` [(wl, wr, duration_s)] from ``start`` to the horizon
    (or into the goal disc, ``goal``), ``cost`` their time [s] or energy [J], ``to_go``
    the terminal cost at their end (0 in the goal), ``found_by`` 'search' or 'previous'
    (the warm start kept), ``expansions`` and ``seconds`` the search's; ``controls`` empty
    (and ``reason`` set) when neither the search nor the warm start holds a way."""

    start: np.ndarray
    controls: list
    cost: float
    to_go: float
    goal: bool
    found_by: str
    expansions: int
    seconds: float
    reason: str | None = None

    @property
    def found(self) -> bool:
        return bool(self.controls)


def periods(controls, period_s: float) -> list:
    """A plan's controls [(wl, wr, duration_s)] as a run executes them: one planning
    period at a time, a control held over several periods (``planner.hold_periods``)
    split into periods of the same command (the drive is the same; the run measures
    and may re-plan after each period), the last piece the remainder."""
    out = []
    for wl, wr, d in controls:
        while d > period_s * (1.0 + 1e-9):
            out.append((float(wl), float(wr), period_s))
            d = round(d - period_s, 9)
        out.append((float(wl), float(wr), float(d)))
    return out


def _with_to_go(prob, grid: np.ndarray):
    """``prob`` with ``grid`` (the map's shape) as its cost-to-go grid and no value over
    position and heading: the terminal cost is the grid's (with the turn cost)."""
    params, data = prob.params.copy(), prob.data.copy()
    offd, n = int(params[SS.Q_OFFD]), int(params[SS.Q_NX]) * int(params[SS.Q_NY])
    if offd < 0 or n != grid.size:
        raise ValueError(f"to_go: expected a grid of the map's {n} nodes, found {grid.size}")
    data[offd:offd + n] = np.asarray(grid, float).ravel()
    params[SS.Q_OFFV] = -1
    return replace(prob, params=params, data=data)


class HorizonPlanner:
    """Plans of one world and cost over a horizon (module doc). What stays between plans
    (the packed problem with its cost-to-go grid, the control set) is made once.

    ``horizon_s``: look-ahead [s]; ``budget_s``: wall-clock budget of a plan [s];
    ``max_expansions``: node budget of a plan; ``to_go``: a cost-to-go grid over the map
    [s or J] (the map's shape) that replaces the world's and its value as the terminal
    cost (a tracker's: :mod:`sbmpc.planning.rejoin`)."""

    def __init__(self, world: World, cost: str, horizon_s: float, budget_s: float, max_expansions: int,
                 to_go: np.ndarray | None = None):
        self.world = world
        self.cost = cost
        self.horizon_s = float(horizon_s)
        self.budget_s = float(budget_s)
        self.max_expansions = int(max_expansions)
        ps = world.scenario.planner
        self.period_s = ps.period_s
        self.prob = replace(problem(world, cost, inside=False),
                            weight=ps.horizon_weight if cost == "time" else ps.horizon_energy_weight)
        self.tracks = None         # a tracker's (plan, kappa): the whole-route plan it leads along
        if to_go is not None:
            self.prob = _with_to_go(self.prob, to_go)
        self.col = K.S_T if cost == "time" else K.S_E
        # the value over position and heading knows the turns; the turn cost serves where
        # there is none (planner.value false, or a pose off its lattice)
        self.prob.params[SS.Q_TURNCOST] = self.turn_cost()
        self.batch = batch_size(ps)
        self.threads = search_threads(ps)

    @classmethod
    def of(cls, world: World, cost: str, to_go: np.ndarray | None = None) -> "HorizonPlanner":
        """The horizon planner of ``world`` and ``cost`` with its scenario's settings
        (``planner.horizon_s``, ``horizon_budget_s``, ``horizon_expansions``)."""
        ps = world.scenario.planner
        return cls(world, cost, ps.horizon_s, ps.horizon_budget_s, ps.horizon_expansions, to_go)

    def turn_cost(self) -> float:
        """The least cost [s/rad or J/rad] of a turn from rest at the start, by the nominal
        vehicle (no margin) over two periods: on the spot and about one wheel, at a
        quarter, half and all of the sampled wheel speeds. What the terminal cost charges
        per radian between the heading and the way on."""
        lo, hi = wheel_speed_range(self.world)
        top = min(abs(lo), abs(hi))
        params = self.prob.params.copy()
        params[SS.Q_OFFTW] = -1.0            # the nominal vehicle: no twin, reserve or tip margin
        params[SS.Q_RESERVE] = 0.0
        params[SS.Q_TIPM] = params[SS.Q_TIP]
        X0 = start_state(self.world)
        best = np.inf
        for share in (0.25, 0.5, 1.0):
            w = share * top
            for wl, wr in ((-w, w), (0.0, w)):
                c = self._value(params, X0, [(wl, wr, 2.0 * self.period_s)])
                if c is None:
                    continue
                turn = abs(c[4][K.S_YAW] - X0[K.S_YAW])
                if turn > 1e-3:
                    best = min(best, c[0] / turn)
        return float(best) if np.isfinite(best) else 0.0

    def to_go(self, state: np.ndarray) -> float:
        """The terminal cost at a planner state [s or J] (the heuristic with the turn)."""
        X0 = _start(self.world, state)
        return float(SS.heuristic(self._params(X0), self.prob.data, X0))

    def _params(self, X0: np.ndarray) -> np.ndarray:
        params = from_inside(self.prob.params, self.world, X0).copy()
        params[SS.Q_HORIZON] = X0[K.S_T] + self.horizon_s - 1e-9
        return params

    def _value(self, params: np.ndarray, X0: np.ndarray, controls) -> tuple | None:
        """(cost, terminal cost, in the goal, controls used) of ``controls`` driven from X0
        with the search's model, up to the horizon or into the goal; None where an edge
        fails."""
        if not controls:
            return None
        cl = np.array([c[0] for c in controls], float)
        cr = np.array([c[1] for c in controls], float)
        dt = params[SS.Q_DT]
        n = np.array([max(1, int(round(c[2] / dt))) for c in controls], np.int64)
        rows, S, end, early = SS.replay(params, self.prob.data, X0, cl, cr, n, np.empty((0, K.NR)))
        if end < 0:
            return None
        used = len(controls) if early < 0 else early + 1
        goal = end == SS.IN_GOAL
        h = 0.0 if goal else float(SS.heuristic(params, self.prob.data, S))
        return float(S[self.col] - X0[self.col]), max(h, 0.0), goal, used, S

    def plan(self, start: np.ndarray, previous: HorizonPlan | None = None,
             budget_s: float | None = None) -> HorizonPlan:
        """A horizon plan from the planner state ``start`` (a measured or predicted state),
        warm-started from ``previous`` (a plan from one period earlier: its first period
        is dropped); ``budget_s`` overrides the planner's budget (a first plan's)."""
        t0 = time.perf_counter()
        X0 = _start(self.world, start)
        params = self._params(X0)
        budget = self.budget_s if budget_s is None else budget_s
        warm = None
        if previous is not None and previous.found:
            steps = periods(previous.controls, self.period_s)[1:]
            if steps and not previous.goal:
                steps.append(steps[-1][:2] + (self.period_s,))
            v = self._value(params, X0, steps)
            # kept only where it makes way: its cost buys at least PROGRESS of its worth in
            # terminal cost (a plan that parks, little cost and no progress, must not
            # bound the search, which then finds nothing that beats it)
            if v is not None and self.to_go(X0) - v[1] >= PROGRESS * v[0]:
                warm = (v, steps[:v[3]])
        prob = replace(self.prob, params=params, start=X0)
        search = Search(prob, capacity=max(256, 4 * self.max_expansions))
        if warm is not None:
            # pruned: nodes whose g + h (unweighted: f = g + w h falls along a path when
            # w > 1, and would prune the start itself) cannot beat the warm plan's
            search.bound((warm[0][0] + warm[0][1]) * (1.0 + 1e-9), weight=1.0)
        # small chunks: the budget is checked between them (256 expansions took 0.1 s)
        res = search.run(self.max_expansions, max(budget - (time.perf_counter() - t0), 1e-3), chunk=CHUNK,
                         batch=self.batch, threads=self.threads)
        if res.status == "found":
            T = res.states[:, K.S_T]
            controls = [(float(prob.controls[c, 0]), float(prob.controls[c, 1]), round(float(T[i + 1] - T[i]), 9))
                        for i, c in enumerate(res.control_rows)]
            end = res.states[-1]
            goal = bool(SS.is_goal(self.prob.params, self.prob.data, end))
            h = 0.0 if goal else max(float(SS.heuristic(params, self.prob.data, end)), 0.0)
            return HorizonPlan(X0, controls, float(end[self.col] - X0[self.col]), h, goal, "search",
                               res.iterations, time.perf_counter() - t0)
        if warm is not None:
            (c, h, goal, _, _), steps = warm
            return HorizonPlan(X0, steps, c, h, goal, "previous", res.iterations, time.perf_counter() - t0)
        return HorizonPlan(X0, [], np.inf, np.inf, False, "", res.iterations, time.perf_counter() - t0,
                           reason=res.reason)


__all__ = ["HorizonPlan", "HorizonPlanner", "periods"]
