"""Planning a scenario: search the problem of a world (:mod:`sbmpc.planning.problem`), polish
energy plans (:mod:`sbmpc.planning.polish`), check the plan at the controller rate
(:mod:`sbmpc.planning.check`) and repair it (:mod:`sbmpc.planning.repair`), check an energy plan against
the time plan, say why where nothing is found, and report the drive at the controller
rate.

``plan(world, cost)`` returns a :class:`Plan` whose controls, replayed through the
closed-loop model over the map (:func:`sbmpc.planning.check.replay`), reproduce its trajectory
and end in the goal; the plan's trajectory *is* that replay.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from dynamics import kernels as K

from .check import HOLD_LAST_S, Check, controller_rate, predicted, replay
from .corridor import Coarse, narrowed
from .heuristics import _max_rise, steepest_climb_needed, unreachable_reason
from . import polish as PO
from .polish import Polished
from .problem import batch_size, problem, search_threads
from ..problems import skidsteer as SS
from .repair import better, checked, polished, polished_standing
from ..search.astar import Search, SearchResult
from ..search.counters import budget_text
from ..trajectory import RECORD_EVERY, trajectory_json, trajectory_length, trajectory_span
from . import world as WO
from .margin import report
from .world import World, _start, capability

FAILURES = {
    "unreachable": ("no path can exist, found from the map and the vehicle before any search: slopes beyond "
                    "the tip-over limit cut the goal off, the start stands on one, or the vehicle cannot hold a "
                    "speed on the map's terrain"),
    "exhausted": "the search explored every state it could reach",
    "node_budget": "the search used up its node budget (planner.max_expansions)",
    "time_budget": "the search used up its time budget (planner.time_budget_s)",
    "controller_rate": "the path the search found does not hold at the controller rate",
}   # Plan.failure: kind -> what it means (docs/formats.md)


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
    polish: Polished | None = None     # the local search over the found controls (sbmpc.planning.polish)
    rival: dict | None = None     # the time plan an energy plan was checked against (plan())
    failure: str | None = None    # for no_path, the kind of failure: one of FAILURES
    coarse: Coarse | None = None  # the coarse search whose corridor the search looked in (sbmpc.planning.corridor)
    margin: dict | None = None    # how close the plan runs to the limits (sbmpc.planning.margin.report), "kept", "note"
    # status "searched" (search_plan(lazy=True), inside plan() only): the searched controls' travel
    # time and energy at the planner's step, and the call that checks them at the controller rate
    searched: dict | None = None
    pending: object = field(default=None, repr=False, compare=False)

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
            "rival": self.rival,
            "failure": self.failure,
            "coarse": self.coarse.to_json() if self.coarse else None,
            "margin": self.margin,
        }


def _closest(world: World, search: Search, res: SearchResult) -> str:
    """Where a failed search came closest to the goal: the expanded state nearest the
    goal disc, how far from it, and the ground between (the height to climb and the
    steepest slope along the straight line to the goal's centre, from the map), so a
    user sees whether the goal stands on ground the vehicle cannot drive. Empty when
    nothing was expanded."""
    n = int(res.nodes)
    if res.iterations <= 0 or n <= 0:
        return ""
    closed = search.CLO[:n].astype(bool)
    X = search.X[:n][closed]
    if not len(X):
        return ""
    g = world.scenario.goal
    d = np.hypot(X[:, K.S_X] - g["x"], X[:, K.S_Y] - g["y"])
    k = int(np.argmin(d))
    x, y = float(X[k, K.S_X]), float(X[k, K.S_Y])
    e = world.emap
    t = np.linspace(0.0, 1.0, max(2, int(d[k] / (0.5 * e.resolution)) + 1))
    xs, ys = x + t * (g["x"] - x), y + t * (g["y"] - y)
    z = np.array([e.height(a, b) for a, b in zip(xs, ys)])
    step = max(d[k] / (len(t) - 1), 1e-9)
    rises = np.diff(z) if len(z) > 1 else np.zeros(1)
    steepest = math.degrees(math.atan(max(float(rises.max()), 0.0) / step))
    out = f"; closest approach {max(d[k] - g['radius'], 0.0):.1f} m from the goal disc, at ({x:.1f}, {y:.1f})"
    if z.max() - z[0] > 0.05 and steepest > 1.0:
        out += (f", from where the straight line to the goal climbs {z.max() - z[0]:.1f} m on grades up to "
                f"{steepest:.0f} deg")
    return out


def _remedy(world: World, res: SearchResult, limit_note: str | None, start: np.ndarray | None = None) -> str:
    """What to try after a failed search, from what it measured: the budget it used up,
    a ``start`` (the planner state searched from) at rest facing uphill a grade steeper
    than the vehicle holds, a way that needs a run-up (every way from there climbs
    steeper than the vehicle holds somewhere: ``heuristics.steepest_climb_needed``),
    the share of edges that stalled (the vehicle's limits against the map's slopes),
    the vehicle's turning limit."""
    ps = world.scenario.planner
    out = []
    if res.ended == "node_budget":
        out.append(f"raise the node budget (planner.max_expansions or --max-expansions {2 * ps.max_expansions})")
    elif res.ended == "time_budget":
        out.append(f"raise the time budget (planner.time_budget_s or --time-budget {2 * ps.time_budget_s:g})")
    from dynamics.limits import steepest_grade
    held = max(steepest_grade(world.vehicle, t) for t in world.terrains)
    xy = None if start is None else (float(start[K.S_X]), float(start[K.S_Y]))
    if start is not None and abs(start[SS.X_V]) < 0.05:                  # at rest (a re-plan may carry speed)
        pitch, _ = world.emap.pitch_roll(*xy, float(start[K.S_YAW]), world.half_length, world.half_width)
        slope = math.atan(math.hypot(*world.emap.gradient(*xy)))
        here = steepest_grade(world.vehicle, world.terrain_at(*xy))
        if pitch > here:                                                      # uphill, nose up
            out.append(f"the start faces a grade of {math.degrees(pitch):.1f} deg along its heading (the ground "
                       f"there slopes {math.degrees(slope):.1f} deg), steeper than the {world.vehicle.name} holds "
                       f"({math.degrees(here):.1f} deg): a start heading across the slope is gentler")
    if res.ended in ("node_budget", "time_budget"):
        need = steepest_climb_needed(world, xy)
        if need is not None and need > held:
            out.append(f"every way to the goal climbs {math.degrees(need):.1f} deg or more somewhere, steeper than "
                       f"the {world.vehicle.name} holds ({math.degrees(held):.1f} deg): only speed carried into "
                       f"that ramp crosses it (a run-up), and few of the ways searched carry enough")
    stalled = res.invalid.get(SS.CODES[SS.STALL - 1], 0)
    if res.edges and stalled > 0.3 * res.edges:
        steep = math.degrees(math.atan(_max_rise(world.emap.heights, world.emap.resolution, 1.0)))
        out.append(f"{100 * stalled / res.edges:.0f} % of the edges stalled: the {world.vehicle.name} holds at most "
                   f"{math.degrees(held):.1f} deg here and the map's slopes reach {steep:.1f} deg (a stronger vehicle, "
                   f"a gentler map, or a map without height steps)")
    if limit_note:
        out.append(limit_note)
    return ("; to try: " + "; ".join(out)) if out else ""


def _incumbent(world: World, cost: str, start: np.ndarray, controls) -> tuple | None:
    """(cost, controls) of a control sequence replayed from ``start`` when it ends in the
    goal (its last control cut where it enters the goal disc; held HOLD_LAST_S longer
    first, as the controller-rate check holds it: the rest of a plan whose last control
    was cut where its 1 kHz drive entered the disc may end a step short of it at the
    planner's step); else None."""
    if not controls:
        return None
    traj, end, S, used = replay(world, cost, controls, every=1 << 30, start=start, hold_last=HOLD_LAST_S)
    if end != SS.IN_GOAL:
        return None
    dt = world.scenario.planner.dt
    kept = [tuple(c) for c in controls[:used]]
    last = round(float(S[K.S_T] - start[K.S_T]) - sum(c[2] for c in kept[:-1]), 9)
    kept[-1] = (kept[-1][0], kept[-1][1], round(max(dt, last), 9))
    c = S[K.S_T] - start[K.S_T] if cost == "time" else S[K.S_E] - start[K.S_E]
    return float(c), kept


def _checked_inputs(world: World, start, incumbent) -> tuple:
    """(start, incumbent) checked: a planner state of SS.NX finite numbers or None, controls
    of three finite numbers or None (InputErrors naming them)."""
    if start is not None:
        start = WO._start(world, start)
    if incumbent is not None:
        incumbent = WO.checked_controls(incumbent, "incumbent")
    return start, incumbent


def plan(world: World, cost: str | None = None, progress=None, start: np.ndarray | None = None,
         incumbent: list | None = None, time_budget_s: float | None = None, time_progress=None) -> Plan:
    """Plan the scenario of ``world`` for ``cost`` (default: the scenario's): the plan
    of :func:`search_plan`, except that an energy plan (without ``incumbent``) is checked
    against the time plan when ``planner.energy_vs_time`` is on (the default): the time
    search runs first (``time_progress`` reports it), and where its plan, driven at the
    controller rate, uses less energy than the energy search's own, or the energy search
    finds nothing, or only it keeps the planner's margin (:func:`cross_checked`), the time
    plan is the energy plan (``found_by`` says so). The time plan is checked at the
    controller rate only where it could be the energy plan (:func:`_stands`: not where the
    energy plan uses TIME_CHECK_SLACK less than its search predicts; ``rival.checked``). The search
    for the cheapest energy merges states on its grid and samples its own wheel speeds,
    so it can lose a way the time search kept; a user who asks for the least energy
    never gets a plan dearer than the fastest one (unless only the dearer one keeps the
    planner's margin; where the time plan stands unchecked, as far as its search's
    prediction tells, which lay within 4 % of its 1 kHz drive on nine route maps). The
    searches share the time budget (the energy search gets what the time search left; a
    time plan checked after the energy search gets the budget its check would have had
    at once, so the whole may run past the budget by that check); ``planning_time_s``
    counts both; ``rival`` holds the time plan's figures."""
    cost = WO.checked_cost(world, cost)
    start, incumbent = _checked_inputs(world, start, incumbent)
    time_budget_s = WO.checked_budget(time_budget_s)
    ps = world.scenario.planner
    if cost != "energy" or incumbent is not None or not ps.energy_vs_time:
        return search_plan(world, cost, progress, start, incumbent, time_budget_s)
    budget = ps.time_budget_s if time_budget_s is None else time_budget_s
    fast = search_plan(world, "time", time_progress, start, None, budget, lazy=True)
    searched_s = fast.planning_time_s           # the time search's share of the budget (its check may come later)
    left = max(budget - searched_s, 0.0)
    found = fast.found or fast.status == "searched"
    # where the time plan keeps the margin, an energy plan without it would not be taken
    # (cross_checked): the energy search does not search again without it
    margin_free = not (found and keeps_margin(fast))
    own = search_plan(world, "energy", progress, start, None, left, without_margin=margin_free)
    if fast.status == "searched":
        if _stands(own, fast):
            return replace(counting(own, fast), rival=_rival(fast))
        fast = fast.pending()
    if not own.found and not margin_free and not fast.found:
        # the time plan kept the margin at the search's step but not at the controller
        # rate: the energy search's plan without it is the one left (search_plan's retry)
        own = margined(world, "energy", own, progress, start, None, left)
    if not own.found and fast.found and keeps_margin(fast) and own.invalid_edges.get(SS.CODES[SS.MARGIN - 1], 0):
        head = (own.reason or "").split(";")[0]
        own = replace(own, reason=f"no plan it found keeps the planner's margin ({head}); the time plan keeps it")
    elif not own.found:
        own = _shared_budget(own, fast, budget, left, searched_s)
    return checked_against_time(own, fast)


TIME_CHECK_SLACK = 0.1   # an energy plan this share below the time search's prediction stands unchecked against it


def _stands(own: Plan, fast: Plan) -> bool:
    """Whether the energy plan ``own`` (checked at the controller rate) is the plan whatever
    the time plan ``fast`` (searched, not yet checked: status "searched") does at 1 kHz: it
    keeps the margin where the time plan does not, or, both keeping it or neither, it uses
    TIME_CHECK_SLACK less energy than the time search predicts for its plan. The time
    plan's 1 kHz drive, its repairs included, used 0.96-1.04x its search's prediction on
    nine route maps of 70-340 m (docs/performance.md#route-length); its check and repairs
    took most of its planning time there (about 4 s of 4.5 s on map 8's 340 m route)."""
    if not own.found:
        return False
    if keeps_margin(own) != keeps_margin(fast):
        return keeps_margin(own)
    return own.energy_J <= (1.0 - TIME_CHECK_SLACK) * fast.searched["energy_J"]


def checked_against_time(own: Plan, fast: Plan) -> Plan:
    """The energy plan :func:`plan` reports from the energy search's own plan and the
    time plan ``fast``: :func:`cross_checked`, both searches' work counted, and
    ``rival`` the time plan's figures."""
    out = cross_checked(own, fast)
    return replace(out if out is not own else counting(own, fast), rival=_rival(fast))


def counting(p: Plan, other: Plan) -> Plan:
    """``p`` with the planning time, nodes expanded and edges simulated of ``other``'s
    search added: every search that went into a reported plan counts."""
    return replace(p, planning_time_s=p.planning_time_s + other.planning_time_s,
                   nodes_expanded=p.nodes_expanded + other.nodes_expanded,
                   edges_simulated=p.edges_simulated + other.edges_simulated)


def _shared_budget(own: Plan, fast: Plan, budget: float, left: float, fast_s: float) -> Plan:
    """The energy search's failed plan ``own`` where the time search it is checked against
    ran first: a time budget used up is the whole one, shared (:func:`plan`), and where
    the time search found nothing either, say so, and how to give the energy search all
    of the budget. Any other failure (a node budget, no path at all) stands as it is.
    ``fast_s``: the time search's share of the budget (its 1 kHz check may come after the
    energy search, :func:`_stands`)."""
    if own.failure != "time_budget":
        return own
    head = f"time budget of {budget_text(left)} s used up"
    rest = own.reason[len(head):] if (own.reason or "").startswith(head) else "; " + (own.reason or "")
    if fast_s < budget:
        used = (f"{fast_s:.2f} s of it by the time search the energy plan is checked against, "
                f"planner.energy_vs_time; {left:.2f} s left to the energy search")
    else:       # the budget cuts a search, not its fixed costs (the cost-to-go grid, the 1 kHz check)
        used = (f"all of it by the time search the energy plan is checked against, planner.energy_vs_time, which "
                f"took {fast_s:.2f} s: a search's grid and its 1 kHz check are not cut by the budget; "
                "nothing was left to the energy search")
    reason = f"time budget of {budget_text(budget)} s used up ({used})" + rest
    if not fast.found:
        reason += ("; the time search found no path either; planner.energy_vs_time: false leaves the whole "
                   "budget to the energy search")
    return replace(own, reason=reason)


def _rival(p: Plan) -> dict:
    """The figures of the plan an energy plan was checked against (plan JSON ``rival``): as
    driven at the controller rate (``checked``), or, a time plan that could not be the
    energy plan (:func:`_stands`), its search's at the planner's step."""
    if p.status == "searched":
        return {"cost": p.cost, "status": "found", "travel_time_s": p.searched["travel_time_s"],
                "energy_J": p.searched["energy_J"], "planning_time_s": p.planning_time_s, "checked": False,
                "kept_margin": keeps_margin(p)}
    return {"cost": p.cost, "status": p.status, "travel_time_s": p.travel_time_s, "energy_J": p.energy_J,
            "planning_time_s": p.planning_time_s, "checked": True}


def keeps_margin(p: Plan) -> bool:
    """Whether a found plan keeps the planner's margin (``margin.kept``; False without one)."""
    return bool((p.margin or {}).get("kept", False))


def cross_checked(own: Plan, other: Plan) -> Plan:
    """``own`` checked against ``other`` (planned for the other cost) on own's cost, both
    as driven at the controller rate: the other plan (adopted, :func:`_adopt`) where it
    does better, or where own's search found nothing and the other's did; else own.
    Keeping the planner's margin ranks before the cost: where only one of the two keeps
    it (the other search found no plan that does and fell back to one at the nominal
    vehicle's limit, :func:`search_plan`), that one is the plan, whatever the two cost."""
    cost = own.cost
    if own.found and other.found:
        if keeps_margin(own) != keeps_margin(other):
            if keeps_margin(own):
                return own
            mine = f"{own.energy_J:.1f} J" if cost == "energy" else f"{own.travel_time_s:.2f} s"
            return _adopt(other, cost, own, why=f"it keeps the planner's margin; the {cost} search's own plan "
                                                f"({mine} at the controller rate) does not")
        better = (other.energy_J < own.energy_J if cost == "energy"
                  else other.travel_time_s < own.travel_time_s)
        return _adopt(other, cost, own) if better else own
    if other.found and not own.found:
        return _adopt(other, cost, own, why=f"the {cost} search found no path: {own.reason}")
    return own


def search_plan(world: World, cost: str | None = None, progress=None, start: np.ndarray | None = None,
                incumbent: list | None = None, time_budget_s: float | None = None,
                without_margin: bool = True, lazy: bool = False) -> Plan:
    """Plan the scenario of ``world`` for ``cost`` (default: the scenario's) by its own
    search (:func:`_search_plan`), keeping the planner's margin (``planner.margin``,
    :mod:`sbmpc.planning.margin`). Where no plan keeps it (the search found nothing and edges
    failed on the margin), the search runs again without it in what is left of the time
    budget (unless ``without_margin`` is False): a plan at the nominal vehicle's limit,
    which says so (``margin.kept`` false, ``margin.note``); a vehicle stalled on a slope
    needs every bit of its drive to get away. The plan's ``margin`` reports how close it
    runs to each limit.

    ``lazy``: a found plan comes back searched but not yet checked at the controller rate
    (status "searched", its figures at the planner's step in ``searched``, ``margin.kept``
    set); ``pending()`` then makes the plan (:func:`plan` checks the time plan only where it
    could be the energy plan)."""
    cost = WO.checked_cost(world, cost)
    time_budget_s = WO.checked_budget(time_budget_s)
    p = _search_plan(world, cost, progress, start, incumbent, time_budget_s, lazy)
    return margined(world, cost, p, progress, start, incumbent, time_budget_s, lazy, retry=without_margin)


def margined(world: World, cost: str, p: Plan, progress=None, start: np.ndarray | None = None,
             incumbent: list | None = None, time_budget_s: float | None = None, lazy: bool = False,
             retry: bool = True) -> Plan:
    """:func:`search_plan`'s plan from its search's result ``p`` (:func:`_search_plan`'s, with
    the planner's margin): where no plan kept the margin (the search found nothing and
    edges failed on it), and ``retry``, the search again without it in what is left of the
    time budget, its plan saying so (``margin.kept`` false, ``margin.note``, the edges that
    failed on the margin); the plan reported (:func:`_reported`). ``lazy``: search_plan's."""
    ps = world.scenario.planner
    kept = True
    note = None
    failed = None
    if (retry and not p.found and margin_on(ps) and p.failure in ("exhausted", "node_budget")
            and p.invalid_edges.get(SS.CODES[SS.MARGIN - 1], 0) > 0):
        budget = ps.time_budget_s if time_budget_s is None else time_budget_s
        left = budget - p.planning_time_s
        if left > 0.0:
            bare = WO.without_margin(world)
            q = _search_plan(bare, cost, progress, start, incumbent, left, lazy)
            if q.found or q.status == "searched":
                note = (f"no plan keeps the margin ({p.reason.split(';')[0]}); this plan rides the nominal "
                        f"vehicle's limits (planner.margin 0)")
                failed = p.invalid_edges
                if q.status == "searched":
                    def bare_checked(miss=p, check=q.pending):
                        # checked at 1 kHz, the plan without the margin counts the failed search's
                        # work too; where it does not hold there, the failed search's reason stands
                        r = check()
                        return counting(r, miss) if r.found else miss
                    q = replace(q, pending=bare_checked)
                p, kept = counting(q, p), False
    kept = kept and margin_on(ps)
    if p.status == "searched":
        return replace(p, margin={"kept": kept},
                       pending=lambda check=p.pending: _reported(world, check(), kept, note, failed))
    return _reported(world, p, kept, note, failed)


def _reported(world: World, p: Plan, kept: bool, note: str | None, failed: dict | None) -> Plan:
    """A found plan with its ``margin`` (:func:`sbmpc.planning.margin.report`, ``kept``, ``note``,
    the edges that failed on the margin where none kept it); any other plan as it is."""
    if not p.found:
        return p
    rep = report(world, p.trajectory) or {}
    return replace(p, margin=dict(rep, kept=kept, note=note,
                                  **({"invalid_edges_with_margin": failed} if failed else {})))


def margin_on(ps) -> bool:
    """Whether planner settings ``ps`` keep a margin (a drive reserve and twin, or a tip margin)."""
    return ps.margin > 0.0 or ps.margin_turn > 0.0 or ps.margin_tip_deg > 0.0


def _search_plan(world: World, cost: str | None = None, progress=None, start: np.ndarray | None = None,
                 incumbent: list | None = None, time_budget_s: float | None = None, lazy: bool = False) -> Plan:
    """Plan the scenario of ``world`` for ``cost`` (default: the scenario's) by its own
    search: search, polish, check at the controller rate and repair (a plan of more than
    polish.EXACT_UP_TO controls: search, check and repair, then polish what the repairs
    leave standing, repair.polished_standing).

    ``start``: a planner state to plan from (default: the scenario's start; a receding-
    horizon run passes the measured state). ``incumbent``: controls [(wl, wr, duration_s)]
    of a known way to the goal (the rest of the previous plan): when their replay from
    ``start`` ends in the goal, its cost bounds the search (branch and bound: no node
    that cannot beat it by the search's weight w is opened: :meth:`Search.bound`) and
    it is the plan when the search finds nothing cheaper within its budgets
    (``found_by`` says so). ``time_budget_s`` overrides the
    scenario's. ``lazy``: :func:`search_plan`'s (the check, the polish and the repairs made by
    ``pending()``, with the budget they would have had at once)."""
    cost = WO.checked_cost(world, cost)
    start, incumbent = _checked_inputs(world, start, incumbent)
    time_budget_s = WO.checked_budget(time_budget_s)
    ps = world.scenario.planner
    budget = ps.time_budget_s if time_budget_s is None else time_budget_s
    t0 = time.perf_counter()
    X0 = _start(world, start)
    why = unreachable_reason(world, (float(X0[K.S_X]), float(X0[K.S_Y])))
    fatal, limit_note = capability(world)
    why = why or fatal
    if why is not None:
        return Plan(world.scenario.name, cost, "no_path", why, planning_time_s=time.perf_counter() - t0,
                    failure="unreachable")
    inc = _incumbent(world, cost, X0, incumbent) if incumbent else None
    coarse = None
    sworld = world
    if ps.corridor(cost) > 0.0 and inc is None:
        # coarse to fine: the search looks along a coarse search's route (sbmpc.planning.corridor)
        sworld, coarse = narrowed(world, cost, X0, ps.corridor(cost), t0 + budget)
    prob = problem(sworld, cost, X0)
    search = Search(prob)
    if inc is not None:
        search.bound(inc[0] * (1.0 + 1e-9))
    # the coarse search's time comes out of the search's budget; its expansions are counted,
    # not charged to the search's node budget (a small budget would starve the search)
    spent = (coarse.expansions, coarse.edges) if coarse else (0, 0)
    res: SearchResult = search.run(ps.max_expansions, budget - (coarse.seconds if coarse else 0.0),
                                   progress=progress, batch=batch_size(ps), threads=search_threads(ps))
    common = dict(nodes_expanded=res.iterations + spent[0], edges_simulated=res.edges_simulated + spent[1],
                  nodes=res.nodes, invalid_edges=res.invalid, coarse=coarse)
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
        return Plan(world.scenario.name, cost, "no_path",
                    res.reason + _closest(world, search, res)
                    + _remedy(world, res, limit_note, X0),
                    planning_time_s=time.perf_counter() - t0, failure=res.ended, **common)
    traj, end, S, _ = replay(world, cost, controls, every=1 << 30, start=X0)
    if end < 0 or (res.status == "found" and not np.allclose(S[:K.NS], res.states[-1, :K.NS], rtol=0, atol=1e-9)):
        raise RuntimeError("internal error: the replayed plan does not reproduce the searched path")
    if lazy:
        searched = time.perf_counter() - t0
        return Plan(world.scenario.name, cost, "searched", None, controls, {}, planning_time_s=searched,
                    found_by=found_by, searched={"travel_time_s": float(S[K.S_T] - X0[K.S_T]),
                                                 "energy_J": float(S[K.S_E] - X0[K.S_E])},
                    pending=lambda: _checked_plan(world, cost, prob, res, X0, controls, inc, found_by, common,
                                                  time.perf_counter() - searched, budget), **common)
    return _checked_plan(world, cost, prob, res, X0, controls, inc, found_by, common, t0, budget)


def _checked_plan(world: World, cost: str, prob, res: SearchResult, X0: np.ndarray, controls: list, inc,
                  found_by: str, common: dict, t0: float, budget: float) -> Plan:
    """The rest of :func:`_search_plan` after its search: the polish, the check at the
    controller rate and its repairs, the incumbent judged at the controller rate, and the
    Plan (its planning time counted from ``t0``, its deadlines ``t0 + budget``)."""
    ps = world.scenario.planner
    common = dict(common)
    pred = res.states[:, [K.S_X, K.S_Y, K.S_YAW]] if res.status == "found" else predicted(world, cost, controls, X0)
    pol, drive, missed = None, None, None
    threads = 1 if res.threads_chosen == "serial" else None
    polishing = res.status == "found" and ps.polishes(cost)
    long = polishing and len(controls) > PO.EXACT_UP_TO      # polished after the check (repair.polished_standing)
    if polishing and not long:
        pol, drive, missed = polished(world, cost, prob, X0, controls, t0 + budget, threads)
        if pol is not None:
            controls = pol.controls
            pred = predicted(world, cost, controls, X0)
    common["polish"] = pol
    memo = {}       # the re-plans of the searched plan's repair, reused by its polish's (repair.checked)
    done = checked(world, cost, controls, pred, X0, t0, budget, ps, drive, memo)
    if missed is not None and time.perf_counter() - t0 < budget:
        # the polished line misses the goal at 1 kHz: repaired like a searched one, it
        # is the plan when it then does better than the searched one (repair.better)
        mpol, mdrive = missed
        other = checked(world, cost, mpol.controls, predicted(world, cost, mpol.controls, X0),
                        X0, t0, budget, ps, mdrive, memo)
        if better(other[1], done[1], cost):
            done = other
            common["polish"] = mpol
    if long:
        done, common["polish"] = polished_standing(world, cost, prob, X0, done, t0 + budget, t0, budget, ps,
                                                   threads, memo)
    controls, chk, fine, repairs, _ = done
    if inc is not None and res.status == "found":
        # the search beat the incumbent at its own step; at the controller rate the new
        # plan may still cost more (a perfect-model run would then do worse than its
        # first plan): the two are judged where every plan is
        ichk, ifine, ikept = controller_rate(world, cost, inc[1], X0)
        if ichk.reached and not better(chk, ichk, cost):
            controls, chk, fine, repairs = ikept, ichk, ifine, 0
            common["polish"] = None
            found_by = ("previous plan (warm start: the search's new plan, cheaper at the planner's step, "
                        "was not at the controller rate)")
    common["repairs"] = repairs
    if not chk.reached:
        return Plan(world.scenario.name, cost, "no_path",
                    f"the path the search found ({ps.dt * 1e3:g} ms steps) does not hold at the vehicle's "
                    f"controller rate ({world.vehicle.controller_rate:g} Hz)"
                    + (f", also after {repairs} re-plans from where it parted" if repairs else "")
                    + f": {chk.reason}",
                    planning_time_s=time.perf_counter() - t0, check=chk, failure="controller_rate", **common)
    every = max(1, round(RECORD_EVERY * world.vehicle.controller_rate))
    rows = len(fine["t"])
    idx = np.unique(np.r_[np.arange(0, rows, every), rows - 1])
    traj = {name: v[idx].copy() for name, v in fine.items()}
    return Plan(world.scenario.name, cost, "found", None, controls, traj,
                planning_time_s=time.perf_counter() - t0, found_by=found_by, check=chk, **common)


def plan_both(world: World, progress=None) -> dict:
    """The time- and the energy-optimal plan of a world, {"time": Plan, "energy": Plan}.

    The implicit grid merges states, so a search can lose a path that the other search
    kept: then the energy search's plan may cost more energy than the time search's,
    or one search may find nothing where the other found a way. Each plan is checked
    against the other on its own cost (a plan that keeps the planner's margin before one
    that does not, :func:`cross_checked`); the better one is kept, a search that found
    nothing takes the other's plan (its own reason is kept in ``found_by``), and
    ``found_by`` says which search produced it (reported by ``sbmpc compare``)."""
    WO.checked_cost(world, "energy")       # before the time search: a regenerating vehicle is refused
    t, e = (search_plan(world, c, progress=progress(c) if progress else None) for c in ("time", "energy"))
    return {"time": cross_checked(t, e), "energy": cross_checked(e, t)}


def _adopt(other: Plan, cost: str, own: Plan, why: str | None = None) -> Plan:
    mine = (f"{own.energy_J:.1f} J" if cost == "energy" else f"{own.travel_time_s:.2f} s") if own.found else ""
    note = why or f"better on {cost} than the {cost} search's own plan, {mine} at the controller rate"
    return counting(replace(other, cost=cost, found_by=f"{other.cost} search ({note})", rival=None,
                            coarse=own.coarse), own)
