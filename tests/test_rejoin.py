"""The hand-over without waiting (:mod:`sbmpc.planning.rejoin`): the cost-to-go that
leads onto a whole-route plan's path and along it, the join onto that plan within the
run's tolerances, and the controller that hands over to the plan made beside it."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from dynamics import kernels as K
from sbmpc import receding as R
from sbmpc import scenario as SC
from sbmpc.planning import heuristics as HE
from sbmpc.planning import horizon as HZ
from sbmpc.planning import plan as PL
from sbmpc.planning import rejoin as RJ
from sbmpc.planning import world as WO
from sbmpc.problems import skidsteer as SS

SCN = Path(__file__).resolve().parents[1] / "scenarios"
SPEED = 0.8      # m/s along the path drawn by hand


@pytest.fixture(scope="module")
def flat():
    scn = SC.load(SCN / "flat.yaml")
    return WO.resolve(replace(scn, planner=replace(scn.planner, horizon_s=10.0)))


def _l_path(dt=0.05):
    """A path around two sides of flat's map: east along y = 2 from the start (2, 2) to
    (16, 2), then north to the goal (16, 9), at SPEED; its trajectory channels."""
    a = np.arange(0.0, 14.0, SPEED * dt)
    b = np.arange(0.0, 7.0 + 1e-9, SPEED * dt)
    x = np.r_[2.0 + a, np.full(b.size, 16.0)]
    y = np.r_[np.full(a.size, 2.0), 2.0 + b]
    yaw = np.r_[np.zeros(a.size), np.full(b.size, math.pi / 2)]
    t = np.arange(x.size) * dt
    return {"t": t, "x": x, "y": y, "yaw": yaw, "v": np.full(x.size, SPEED), "energy_J": 20.0 * SPEED * t}


def _node(world, x, y):
    e = world.emap
    return int(round((y - e.origin[1]) / e.resolution)), int(round((x - e.origin[0]) / e.resolution))


def test_the_tube_values_the_path_at_its_remaining_cost_and_leads_along_it_not_to_the_goal(flat):
    """On every node the path crosses the value is the path's remaining time (within a
    cell's travel: the node keeps the last sample in it): no shortcut undercuts the path
    from its own nodes, which with steps priced at their lower bound (kappa 1) the way
    straight to the goal would (the grid's lower bound there is a third less). Off the
    path the value is higher, and it falls along the path (east on the first leg), not
    towards the goal (north-east)."""
    tr = _l_path()
    grid, kappa = RJ.tube_to_go(flat, "time", tr)
    assert RJ.KAPPA_MIN <= kappa <= RJ.KAPPA_MAX
    lower = HE.cost_to_go(flat, "time")[0]
    rest = tr["t"][-1] - tr["t"]
    cell_s = flat.emap.resolution / SPEED
    for k in range(0, tr["t"].size - 1, 25):
        j, i = _node(flat, tr["x"][k], tr["y"][k])
        assert grid[j, i] == pytest.approx(rest[k], abs=cell_s + 1e-9)
    j, i = _node(flat, 4.0, 2.0)
    assert lower[j, i] < 0.75 * grid[j, i]          # the lower bound would cut the corner
    # off the first leg, 1 m north of it: dearer than the path beside it, and downhill east
    j, i = _node(flat, 8.0, 3.0)
    jp, ip = _node(flat, 8.0, 2.0)
    assert grid[j, i] > grid[jp, ip]
    gy, gx = np.gradient(grid[j - 2:j + 3, i - 2:i + 3])
    sx, sy = -gx[2, 2], -gy[2, 2]
    assert abs(math.degrees(math.atan2(sy, sx))) < 30.0, (sx, sy)


def test_a_tracker_plan_from_beside_the_path_ends_on_it_where_the_plain_horizon_heads_for_the_goal(flat):
    """From 1.5 m north of the L path's first leg, facing east: the tracker's horizon plan
    ends within 0.5 m of the path; the plain horizon's (terminal cost: the map's own) ends
    metres off it, on the way straight to the goal."""
    tr = _l_path()
    tracker = RJ.tracker(flat, "time", SimpleNamespace(trajectory=tr))
    ps = flat.scenario.planner
    plain = HZ.HorizonPlanner(flat, "time", ps.horizon_s, ps.horizon_budget_s, ps.horizon_expansions)
    X = WO.start_state(flat)
    X[K.S_X], X[K.S_Y] = 5.0, 3.5
    ends = {}
    for name, planner in (("tracker", tracker), ("plain", plain)):
        h = planner.plan(X, None, 2.0)
        assert h.found, (name, h.reason)
        ex = R._Executor(flat, "time")
        S = X
        for c in h.controls:
            _, _, S = ex.step(S, c, record=False)
        ends[name] = float(np.min(np.hypot(tr["x"] - S[K.S_X], tr["y"] - S[K.S_Y])))
    assert ends["tracker"] < 0.5 and ends["plain"] > 1.5, ends


@pytest.fixture(scope="module")
def route(flat):
    return PL.plan(flat, "time")


def _at(world, tr, k):
    X = WO.start_state(world)
    X[K.S_T], X[K.S_X], X[K.S_Y], X[K.S_YAW] = tr["t"][k], tr["x"][k], tr["y"][k], tr["yaw"][k]
    X[SS.X_V] = tr["v"][k]
    return X


def test_a_vehicle_on_the_plan_joins_it_where_it_is_and_one_off_it_does_not(flat, route):
    """A state on the plan's trajectory at t = 5 s joins it there: the rest of its
    controls, in periods, driving the 1 kHz replay's remaining time; 1 m off it, turned
    about, or 0.3 m/s slower than the plan there (the run's tolerances: 0.5 m, 15 deg,
    0.2 m/s), it does not."""
    assert route.found
    tr = route.trajectory
    ps, rs = flat.scenario.planner, flat.scenario.run
    k = int(np.flatnonzero(np.isclose(tr["t"] - tr["t"][0], 5.0))[0])
    args = (ps.period_s, 0.1, rs.tol_xy, math.radians(rs.tol_yaw_deg), rs.tol_v)
    rest = RJ.join(route, _at(flat, tr, k), *args)
    assert rest is not None
    assert sum(d for _, _, d in rest) == pytest.approx(tr["t"][-1] - tr["t"][k], abs=0.06)
    whole = HZ.periods(route.controls, ps.period_s)
    assert rest[-3:] == whole[-3:]
    X = _at(flat, tr, k)
    X[K.S_Y] += 1.0
    assert RJ.join(route, X, *args) is None
    X = _at(flat, tr, k)
    X[K.S_YAW] += math.pi
    assert RJ.join(route, X, *args) is None
    X = _at(flat, tr, k)
    X[SS.X_V] -= 0.3
    assert RJ.join(route, X, *args) is None


def _blind_after(flat, monkeypatch, t_blind: float):
    """``sbmpc run`` of flat with ``run.beside``, the plain horizon plans stubbed to find
    no way on from t_blind [s] on (a tracker's plans are left alone)."""
    real = HZ.HorizonPlanner.plan

    def blind(self, start, previous=None, budget_s=None):
        if self.tracks is None and start[K.S_T] > t_blind:
            return HZ.HorizonPlan(start, [], np.inf, np.inf, False, "", 0, 0.0, reason="stubbed: no way on")
        return real(self, start, previous, budget_s)
    monkeypatch.setattr(HZ.HorizonPlanner, "plan", blind)
    world = replace(flat, scenario=replace(flat.scenario, run=replace(flat.scenario.run, beside=True)))
    return R.run(world, "time")


def test_the_controller_hands_over_to_the_plan_made_beside_without_waiting_for_a_new_one(flat, monkeypatch):
    """Horizon plans stubbed to find no way on after t = 3 s: the controller hands over
    to a whole-route plan it made beside (horizon plans led onto its path and along it),
    plans no whole-route plan from where the vehicle stands, and reaches the goal
    (``run.beside``)."""
    out = _blind_after(flat, monkeypatch, 3.0)
    assert out.status == "reached", out.reason
    assert out.horizon.rejoined == 1 and out.horizon.fallbacks == 0
    assert any("made beside" in p.why for p in out.plans)


def test_a_hand_over_takes_a_plan_made_beside_from_ahead_of_the_vehicle_not_the_one_from_the_start(flat, monkeypatch):
    """The plans made beside are kept fresh: each from where the horizon plan predicts
    the vehicle a little later than the last took to make. With the horizon plans
    stubbed blind after t = 8 s, the hand-over takes one made from beyond t = 2 s
    (the first, from the start at t = 0, is 8 s stale by then), with no whole-route plan
    from where the vehicle stood, and the vehicle reaches the goal."""
    out = _blind_after(flat, monkeypatch, 8.0)
    assert out.status == "reached", out.reason
    assert out.horizon.rejoined >= 1 and out.horizon.fallbacks == 0
    assert len(out.horizon.beside_s) >= 2
    made = [p for p in out.plans if "made beside" in p.why]
    assert made and made[0].t > 2.0, [(p.t, p.why) for p in made]


def test_in_a_lockstep_run_a_plan_made_beside_is_ready_when_a_robots_would_be(flat, monkeypatch):
    """The run clock: a plan made beside that takes W s of wall time counts as ready in a
    lockstep run (``sbmpc run``, whose simulated clock runs faster than the wall's) W s
    of robot time after it was asked for, at the first period's end after that, never
    earlier (a run whose first horizon plan took longer would see it at t = 0) and not
    much later (the run waits for it as a robot would, instead of meeting it many
    seconds of driving later). Each next one is asked for from where the horizon plan
    predicts the vehicle a period beyond that wall time ahead."""
    import time as _time
    from sbmpc.robot import controller as CT
    W = 0.6
    asks = []       # periods ahead of the vehicle each plan made beside starts

    def slow(world, cost, X, cancel, ahead=()):
        asks.append(len(ahead))
        _time.sleep(W)
        return None, None, X, _time.perf_counter()
    monkeypatch.setattr(CT, "_beside", slow)
    real = HZ.HorizonPlanner.plan

    def slow_first(self, start, previous=None, budget_s=None):
        if start[K.S_T] == 0.0:
            _time.sleep(2 * W)      # the simulated clock stands still: the plan beside is done at t = 0
        return real(self, start, previous, budget_s)
    monkeypatch.setattr(HZ.HorizonPlanner, "plan", slow_first)
    ctrl = CT.Controller(flat, "time", period_s=0.1, lockstep=True, beside=True)
    from test_controller import _drive      # (tests/ is on the path: no package)
    try:
        _drive(flat, ctrl, t_max=5.0)
    finally:
        ctrl.close()
    lag = ctrl.horizon.beside_s
    assert len(lag) >= 2, lag
    period = flat.scenario.planner.period_s
    assert all(W - 1e-6 <= x <= W + period + 0.3 for x in lag), lag
    # the first from where the vehicle stands, each later one a period beyond the last
    # one's wall time ahead along the horizon plan (0.6 s: two periods of 1 s)
    assert asks[0] == 0 and asks[1:] and all(a == 2 for a in asks[1:]), asks


def test_a_tracker_is_offered_only_where_its_horizon_plans_can_reach_the_path(flat):
    """At a hand-over with no plan made beside that the vehicle joins, the newest whose
    path passes within half the look-ahead at top speed is tracked; one further away (made
    where the vehicle no longer is) is not: the tracker would lead it back (a plan from
    the start, 2-20 m behind, cost 32-59 % more on hills_field)."""
    from sbmpc.robot import controller as CT
    tr = _l_path()
    plan = SimpleNamespace(trajectory=tr, cost="time", controls=[], found=True)
    ctrl = CT.Controller(flat, "time", period_s=0.1, beside=True)
    try:
        ctrl._last_t = 0.0
        ps = flat.scenario.planner
        reach = 0.5 * ps.horizon_s * WO.wheel_speed_range(flat)[1] * flat.vehicle.wheel_radius
        X = WO.start_state(flat)
        X[K.S_X], X[K.S_Y], X[K.S_YAW] = 8.0, 2.0 + reach + 0.5, math.pi   # beyond reach, facing away
        ctrl._offers = [(plan, "tracker", X.copy())]
        assert ctrl._rejoin(X, "test") is None
        X[K.S_Y] = 2.0 + reach - 0.5
        got = ctrl._rejoin(X, "test")
        assert got is not None and got[1] == "tracker"
        assert ctrl._offers == []           # used once
    finally:
        ctrl.close()


def test_offers_made_for_a_model_an_adaptation_replaced_are_dropped(flat, monkeypatch):
    """A P3-AT with 20 % less battery voltage, refitted every 3 periods with run.beside:
    once the plans are made for the vehicle as measured, no plan made beside for the
    file's vehicle is offered any more (the offers are cleared where the planning model
    is rebuilt, and the next are made for the new one). The plans made beside are stubbed
    to return at once, tagged with the world they were asked for."""
    import time as _time
    from sbmpc.robot import controller as CT

    def tagged(world, cost, X, cancel, ahead=()):
        return SimpleNamespace(world=world), "tracker", X, _time.perf_counter()
    monkeypatch.setattr(CT, "_beside", tagged)
    monkeypatch.setattr(CT.Controller, "_rejoin", lambda self, X, why, tracked=None: None)   # (never taken up)
    seen = []            # (offer's world is the planning world, planning world is the file's) at every poll
    real = CT.Controller._poll_beside

    def poll(self, t):
        real(self, t)
        seen.extend((o[0].world is self.plan_world, self.plan_world is self.world) for o in self._offers)
    monkeypatch.setattr(CT.Controller, "_poll_beside", poll)
    slow = flat.vehicle.replace(v_max=0.8 * flat.vehicle.v_max)
    world = replace(flat, scenario=replace(flat.scenario, run=replace(flat.scenario.run, beside=True)))
    res = R.run(world, "time", slow, replace(world.scenario.run, adapt_periods=3))
    assert res.adapted and res.planned_as.startswith("p3at as measured")
    assert any(own and not files for own, files in seen)     # offers for the vehicle as measured were made ...
    assert all(own for own, _ in seen)                       # ... and none for a model replaced was kept
