"""Receding-horizon SBMPC (``planner.horizon_s``, :mod:`sbmpc.planning.horizon`, ``sbmpc run
--horizon``): searches that look a few seconds ahead with the cost-to-go grid and a
turn cost as terminal cost, re-planned every period from the predicted state."""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from dynamics import kernels as K
from sbmpc.planning import horizon as HZ
from sbmpc import execution as EX
from sbmpc import receding as R
from sbmpc import scenario as SC
from sbmpc import schemas
from sbmpc.planning import world as WO
from sbmpc.commands.cli import main
from sbmpc.problems import skidsteer as SS

SCN = Path(__file__).resolve().parents[1] / "scenarios"


def _world(name="flat", **planner):
    scn = SC.load(SCN / f"{name}.yaml")
    return WO.resolve(replace(scn, planner=replace(scn.planner, **planner)))


@pytest.fixture(scope="module")
def flat():
    return _world(horizon_s=10.0)


@pytest.mark.parametrize("cost", ["time", "energy"])
def test_a_horizon_plan_reaches_its_horizon_and_replays_to_its_cost(flat, cost):
    """From rest at flat's start (15.7 m from the goal), a 5 s plan ends at the horizon
    (a control held over two periods may pass it by one), not in the goal; its controls, driven through the search's model at the planner's
    step, end where the plan says and cost what it says."""
    hp = HZ.HorizonPlanner(flat, cost, 5.0, 5.0, 2000)
    X0 = WO.start_state(flat)
    h = hp.plan(X0)
    assert h.found and h.found_by == "search" and not h.goal
    ps = flat.scenario.planner
    assert 5.0 - 1e-6 <= sum(c[2] for c in h.controls) <= 5.0 + (ps.hold_periods - 1) * ps.period_s + 1e-6
    c, togo, goal, used, S = hp._value(hp._params(X0), X0, h.controls)
    assert used == len(h.controls) and not goal
    assert c == pytest.approx(h.cost, rel=1e-9) and togo == pytest.approx(h.to_go, rel=1e-9)
    # it made way: the terminal cost fell by more than half of what the plan cost
    assert hp.to_go(X0) - h.to_go > 0.5 * h.cost


def _facing_and_away(hp, world):
    """The start state (left heading away from the goal), the heading towards the goal
    [rad], and the terminal cost at the start facing the goal and facing away."""
    X = WO.start_state(world)
    g = world.scenario.goal
    toward = math.atan2(g["y"] - X[K.S_Y], g["x"] - X[K.S_X])
    X[K.S_YAW] = toward
    facing = hp.to_go(X)
    X[K.S_YAW] = toward + math.pi
    return X, toward, facing, hp.to_go(X)


def test_the_terminal_cost_charges_the_heading_error_at_the_measured_turn_cost():
    """Without the value (``planner.value`` false) the grid knows no heading: the
    horizon's terminal cost adds the turn cost per radian between the heading and the
    way on. Facing away from the goal costs pi radians more than facing it; a turn on
    the spot cannot be faster than both wheels at the top sampled speed in opposite
    senses allow (yaw rate 2 r w / B, the kinematics' bound without slip)."""
    flat = _world(horizon_s=10.0, value=False)
    hp = HZ.HorizonPlanner(flat, "time", 10.0, 1.0, 2000)
    k = hp.prob.params[SS.Q_TURNCOST]
    lo, hi = WO.wheel_speed_range(flat)
    v = flat.vehicle
    assert k >= v.width / (2.0 * v.wheel_radius * min(abs(lo), abs(hi))) - 1e-9
    X, toward, facing, away = _facing_and_away(hp, flat)
    # (the grid's slope at the start may point a few degrees off the straight line)
    assert away - facing == pytest.approx(k * math.pi, rel=0.1)
    # the whole-route search's heuristic is untouched: no horizon, no heading term
    p = hp.prob.params.copy()
    assert p[SS.Q_HORIZON] == 0.0
    assert SS.heuristic(p, hp.prob.data, X) == pytest.approx(
        SS.heuristic(p, hp.prob.data, np.r_[X[:K.S_YAW], toward, X[K.S_YAW + 1:]]))


def test_with_the_value_the_terminal_cost_knows_the_heading(flat):
    """With the value over position and heading (the default) the terminal cost is the
    value where it exceeds the grid, no turn term (the turn cost serves only where the
    value is infinite, off its lattice): facing away from the goal it costs
    more than facing it by at least what a half turn takes at the tables' best steady
    turn rate on the level, and the whole-route heuristic reads the same value (clamped
    by the grid)."""
    from sbmpc.planning import motions as MO, value as VA
    hp = HZ.HorizonPlanner(flat, "time", 10.0, 1.0, 2000)
    assert hp.prob.params[SS.Q_TURNCOST] > 0.0 and hp.prob.params[SS.Q_OFFV] >= 0   # (where V is inf)
    X, toward, facing, away = _facing_and_away(hp, flat)
    tb = MO.tables(flat)
    lvl = int(np.argmin(np.abs(tb["grades"])))
    turning = (tb["kinds"] == MO.ARC) | (tb["kinds"] == MO.PIVOT)
    best_rate = np.abs(tb["w"][0, lvl, turning & tb["ok"][0, lvl]]).max()
    assert away - facing >= 0.9 * math.pi / best_rate
    val = VA.value(flat, "time")
    assert away + hp.prob.params[SS.Q_GOALGAP] == pytest.approx(val.at(X[K.S_X], X[K.S_Y], X[K.S_YAW]), rel=1e-9)


def test_a_previous_plan_that_makes_way_bounds_the_search_and_one_that_parks_does_not(flat):
    """The warm start: the previous plan less its first period is kept where the search
    finds nothing better; a plan that creeps (little cost, no way made) is not offered."""
    hp = HZ.HorizonPlanner(flat, "time", 5.0, 5.0, 2000)
    X0 = WO.start_state(flat)
    first = hp.plan(X0)
    model = R._Executor(flat, "time")
    _, _, P = model.step(X0, HZ.periods(first.controls, 1.0)[0], record=False)
    nxt = hp.plan(P, previous=first)
    assert nxt.found and nxt.to_go < first.to_go
    park = replace(first, controls=[(0.05, 0.05, 1.0)] * 5, found_by="search")
    none = replace(first, controls=[], found_by="")
    a, b = hp.plan(P, previous=park), hp.plan(P, previous=none)
    # the parked plan changed nothing: the search ran as without a previous plan
    assert a.found_by == b.found_by == "search" and a.controls == b.controls


@pytest.mark.parametrize("cost", ["time", "energy"])
def test_a_horizon_run_on_flat_reaches_the_goal_close_to_the_whole_route_run(flat, cost):
    """flat, the truth the planning model: the horizon run reaches the goal without a
    stall or a whole-route fallback, one horizon plan per period driven; its executed
    travel time is within 5 % of the whole-route run's (measured 0.6 %, bench/
    bench_horizon.py), and its energy within 15 % (measured 13 %: the horizon does not
    see the whole route's speed profile). Its JSON says so and matches the schema."""
    res = R.run(flat, cost)
    d = res.to_json()
    jsonschema.validate(d, schemas.run())
    hz = d["horizon"]
    assert res.status == "reached" and res.stalls == 0 and hz["fallbacks"] == 0
    assert hz["plans"] == len(res.plans) == res.periods
    whole = R.run(_world(horizon_s=0.0), cost)
    assert whole.status == "reached" and "horizon" not in whole.to_json()
    key = "travel_time_s" if cost == "time" else "energy_J"
    assert d[key] <= (1.05 if cost == "time" else 1.15) * whole.to_json()[key]


def test_where_the_horizon_sees_no_way_on_the_run_follows_a_whole_route_plan(flat, monkeypatch):
    """A horizon plan that finds nothing hands the run to whole-route plans from the
    measured state, counted and timed in the JSON; the run still reaches the goal."""
    real = HZ.HorizonPlanner.plan
    calls = []

    def blind(self, start, previous=None, budget_s=None):
        calls.append(1)
        h = real(self, start, previous, budget_s)
        return h if len(calls) <= 3 else replace(h, controls=[], found_by="", reason="blind (test)")
    monkeypatch.setattr(HZ.HorizonPlanner, "plan", blind)
    res = R.run(flat, "time")
    hz = res.to_json()["horizon"]
    assert res.status == "reached" and hz["fallbacks"] >= 1 and len(hz["fallback_s"]) == hz["fallbacks"]
    assert any("whole-route" in r.why for r in res.plans)


def test_an_energy_runs_whole_route_fallback_is_checked_against_the_time_plan(flat, monkeypatch):
    """Where the horizon sees no way on in an energy run, its whole-route plan is the one
    ``sbmpc plan --cost energy`` makes: the energy search's, or the time search's where
    that one finds nothing (planner.energy_vs_time). Here every energy search finds
    nothing (as narrow_pass's, with the margin, found nothing in 60 s from near its start,
    two of eight seeds' runs failing there): the run follows the time plan and reaches
    the goal; with the energy search's own plan as its fallback it failed."""
    from sbmpc.planning import plan as PL
    real_plan, real_search = HZ.HorizonPlanner.plan, PL.search_plan
    calls = []

    def blind(self, start, previous=None, budget_s=None):
        calls.append(1)
        h = real_plan(self, start, previous, budget_s)
        return h if len(calls) <= 3 else replace(h, controls=[], found_by="", reason="blind (test)")

    def no_energy(world, cost=None, *a, **k):
        if cost == "energy":
            return PL.Plan(world.scenario.name, "energy", "no_path", "no energy plan (test)", failure="exhausted")
        return real_search(world, cost, *a, **k)

    monkeypatch.setattr(HZ.HorizonPlanner, "plan", blind)
    monkeypatch.setattr(PL, "search_plan", no_energy)
    res = R.run(flat, "energy")
    assert res.status == "reached", res.reason
    fallbacks = [r for r in res.plans if "whole-route" in r.why]
    assert fallbacks and fallbacks[0].plan.found and fallbacks[0].plan.found_by.startswith("time search")


def test_cli_run_horizon(tmp_path, capsys):
    out = tmp_path / "run.json"
    assert main(["run", str(SCN / "flat.yaml"), "--horizon", "8", "--cost", "time", "--json", str(out),
                 "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "horizon plans (8 s ahead)" in text and "95th percentile" in text
    assert json.loads(out.read_text())["horizon"]["horizon_s"] == 8.0
    assert main(["run", str(SCN / "flat.yaml"), "--horizon", "-1"]) == 2
    assert "--horizon: expected seconds in [0, 3600], found -1" in capsys.readouterr().err


def test_horizon_settings_are_validated(tmp_path):
    for key in ("horizon_weight", "horizon_energy_weight"):
        text = (SCN / "flat.yaml").read_text().replace("planner:", f"planner:\n  {key}: 0.5", 1)
        p = tmp_path / "bad.yaml"
        p.write_text(text)
        with pytest.raises(Exception, match=key):
            SC.load(p)


def test_each_cost_searches_the_horizon_with_its_own_weight():
    """The energy horizon searches weigh their terminal cost by horizon_energy_weight,
    the time ones by horizon_weight (measured with the grid as terminal cost: at 1.3 the
    energy runs drove too fast; with the value, which is no lower bound, 1 for both)."""
    from dataclasses import replace
    scn = SC.load(SCN / "flat.yaml")
    w = WO.resolve(replace(scn, planner=replace(scn.planner, horizon_s=5.0, horizon_weight=1.7,
                                                horizon_energy_weight=1.2)))
    ps = w.scenario.planner
    weights = {c: HZ.HorizonPlanner(w, c, 5.0, ps.horizon_budget_s, ps.horizon_expansions).prob.weight
               for c in ("time", "energy")}
    assert weights == {"time": 1.7, "energy": 1.2}
    assert SC.PlannerSettings().horizon_energy_weight == 1.0 and SC.PlannerSettings().horizon_weight == 1.0


def test_plan_and_compare_with_a_horizon_report_the_drive(tmp_path, capsys):
    """``plan --horizon``: the receding-horizon run by the planning vehicle, reported as a
    plan whose controls, driven again at the controller rate from the start, are its
    trajectory; ``compare --horizon`` does so for both costs."""
    out = tmp_path / "plan.json"
    assert main(["plan", str(SCN / "flat.yaml"), "--horizon", "8", "--cost", "time", "--json", str(out),
                 "--quiet"]) == 0
    assert "receding horizon:" in capsys.readouterr().out
    d = json.loads(out.read_text())
    jsonschema.validate(d, schemas.plan())
    assert d["status"] == "found" and d["found_by"].startswith("receding horizon: ")
    ctrl = [(c["wl"], c["wr"], c["duration_s"]) for c in d["controls"]]
    ex = R._Executor(_world(), "time")
    X = WO.start_state(_world())
    for c in ctrl:
        _, end, X = ex.step(X, c, record=False)
    assert end == SS.IN_GOAL
    assert X[K.S_T] == pytest.approx(d["travel_time_s"], abs=1e-6)
    assert main(["compare", str(SCN / "flat.yaml"), "--horizon", "8", "--out", str(tmp_path / "cmp"), "--quiet"]) == 0
    plans = json.loads((tmp_path / "cmp" / "compare.json").read_text())["plans"]
    assert all(p["found_by"].startswith("receding horizon") for p in plans.values())


class _Predicts:
    """A run's guard (receding._guards) whose 1 kHz predictions all end with ``end``."""

    world = None                     # (no map: the guard takes no floor)

    def __init__(self, end):
        self.end = end

    def step(self, X, control, record=False, tilt_error=0.0, floor=0.0):
        return None, self.end, X


def test_a_horizon_run_never_drives_a_period_the_guard_holds_back(flat, monkeypatch):
    """The tip-over guard of whole-route runs guards horizon runs too (their narrow_pass
    runs with a 10 % heavier or less grippy truth tipped over without it,
    bench/results/horizon_truths.json): a period whose prediction comes within half the
    tip-over margin is not driven; the vehicle waits for a horizon plan from where it
    stands, then for a whole-route plan, and where that one's first period is held back
    too, the run stops rather than tip over, without driving a step."""
    monkeypatch.setattr(EX, "guards", lambda world, cost: [_Predicts(0), _Predicts(-SS.MARGIN)])
    res = R.run(flat, "time")
    assert res.status == "failed" and "the run stops rather than tip over" in res.reason
    assert res.periods == 0 and res.guarded == 3
    assert res.horizon.fallbacks == 1 and res.horizon.from_measured == 1
    assert [r.why.split(" at (")[0] for r in res.plans[1:]] == [R.HELD, R.HELD]
    # a guard that holds nothing back changes nothing
    monkeypatch.setattr(EX, "guards", lambda world, cost: [_Predicts(0), _Predicts(0)])
    free = R.run(flat, "time")
    assert free.status == "reached" and free.guarded == 0 and free.horizon.fallbacks == 0


class _HoldsAfter:
    """A guard whose predictions pass ``n`` periods, then come within half the tip-over
    margin; braking to rest after a period passes."""
    world = None

    def __init__(self, n):
        self.n = n

    def step(self, X, control, record=False, tilt_error=0.0, floor=0.0):
        if control[0] == 0.0 and control[1] == 0.0:
            return None, 0, X
        self.n -= 1
        return None, (0 if self.n >= 0 else -SS.MARGIN), X


def test_a_horizon_run_brakes_through_a_held_period_and_stops_only_at_rest(flat, monkeypatch):
    """Three periods driven, then every period held back: the moving vehicle cannot wait
    for the plans from where it stands, so it brakes through a period (driven, status
    held) and the run stops from rest (before, it stopped with the wheels turning)."""
    monkeypatch.setattr(EX, "guards", lambda world, cost: [_Predicts(0), _HoldsAfter(3)])
    res = R.run(flat, "time")
    assert res.status == "failed" and "the run stops rather than tip over" in res.reason
    assert res.periods == 3 + 1
    assert max(abs(res.trajectory["wl"][-1]), abs(res.trajectory["wr"][-1])) < EX.MOVING


class _HoldsForwardAfter(_HoldsAfter):
    """As _HoldsAfter, but periods driven backwards pass too."""

    def step(self, X, control, record=False, tilt_error=0.0, floor=0.0):
        if control[0] + control[1] < 0.0:
            return None, 0, X
        return super().step(X, control, record, tilt_error, floor)


def test_where_the_whole_route_plans_first_period_is_held_too_the_run_backs_off_before_it_stops(flat, monkeypatch):
    """Three periods driven, then every period forward held back (backing passes): after
    the brake, the horizon plan's and the whole-route plan's first periods held, the
    vehicle drives back along the way it came (a stop, then its last two periods
    reversed, each guarded) and plans again from there; held there too, with too few
    periods left to retrace, it stops, at rest. Before, it stopped where the whole-route
    plan's first period was held (a map-family `hills_field` horizon truth stopped so on
    a 25 deg flank, and reaches the goal backing off, 2026-12-07)."""
    monkeypatch.setattr(EX, "guards", lambda world, cost: [_Predicts(0), _HoldsForwardAfter(3)])
    res = R.run(flat, "time")
    assert res.status == "failed" and "the run stops rather than tip over" in res.reason
    assert [r.why for r in res.plans if r.why.startswith("backed off")]
    back = [c for c in res.driven if c[0] + c[1] < 0.0]
    assert len(back) == 2 and res.periods >= 3 + 1 + 3
    assert max(abs(res.trajectory["wl"][-1]), abs(res.trajectory["wr"][-1])) < EX.MOVING


class _HoldsLong(_Predicts):
    """A guard that holds back every period longer than half a second (braking passes)."""

    def __init__(self):
        super().__init__(0)

    def step(self, X, control, record=False, tilt_error=0.0, floor=0.0):
        moving = control[0] != 0.0 or control[1] != 0.0
        return None, (-SS.MARGIN if moving and control[2] > 0.5 + 1e-9 else 0), X


def test_a_horizon_run_drives_the_part_of_a_held_period_the_guard_lets_through(flat, monkeypatch):
    """Every 1 s period held back, its first half let through: from rest the run drives
    that half, planned again from where it ended; moving, a held period is braked
    through (a part driven at speed adds speed), and from rest again the next half is
    driven: the run creeps to the goal in half periods, never a whole one, without a
    whole-route plan."""
    monkeypatch.setattr(EX, "guards", lambda world, cost: [_Predicts(0), _HoldsLong()])
    res = R.run(flat, "time")
    assert res.status == "reached", res.reason
    assert res.horizon.fallbacks == 0 and res.guarded > 0 and res.horizon.shortened > 0
    assert res.to_json()["horizon"]["shortened"] == res.horizon.shortened
    moving = [c for c in res.driven if c[0] != 0.0 or c[1] != 0.0]
    assert moving and max(c[2] for c in moving) <= 0.5 + 1e-9


# A pivot braked on a slope of hills_field: the vehicle at 0.25 m/s, full speed for a
# second, then the left wheel stopped and the right one reversed. It stops on a 5 deg
# slope with its right drive saturated and its stall timer running, short of a stall
# (found by a horizon run, energy, seed 4, that then failed at t = 50 s).
TRAP_START = {"x": 33.0, "y": 24.0, "yaw_deg": -16.0, "v": 0.25}
TRAP = [(8.68, 7.4, 1.0), (0.1, -2.5, 1.0)]


@pytest.fixture(scope="module")
def trap():
    # budgets of 0.5 s (0.09 s by default): the run's path does not hang on a slow machine's
    scn = SC.load(SCN / "hills_field.yaml")
    return WO.resolve(replace(scn, start=dict(scn.start, **TRAP_START),
                              planner=replace(scn.planner, horizon_s=10.0, horizon_budget_s=0.5,
                                              horizon_first_budget_s=1.0)))


@pytest.mark.parametrize("cost", ["time", "energy"])
def test_a_saturated_drive_has_no_way_on_until_its_wheels_are_held_at_rest(trap, cost):
    """At the controller rate, the braked pivot stops the vehicle (wheels below 0.05 rad/s)
    with the stall timer running and no stall; from there every edge of the horizon
    search stalls (the rate-limited references keep the drive saturated whatever is
    commanded), within any budget; one period with the wheels commanded to rest clears
    the timer, and the same search then finds a way on."""
    ps = trap.scenario.planner
    X = WO.start_state(trap)
    for c in TRAP:
        _, end, X = R._Executor(trap, cost).step(X, c)
        assert end == 0
    assert X[K.S_STALLT] > 0.05 and X[K.S_STALLED] == 0.0 and R._settles(X)
    assert abs(X[K.S_WL]) < 0.05 and abs(X[K.S_WR]) < 0.05
    hp = HZ.HorizonPlanner(trap, cost, ps.horizon_s, ps.horizon_budget_s, ps.horizon_expansions)
    stuck = hp.plan(X, budget_s=5.0)
    assert not stuck.found and stuck.expansions <= 2 and "stalled" in stuck.reason
    _, end, rested = R._Executor(trap, cost).step(X, (0.0, 0.0, ps.period_s))
    assert end == 0 and rested[K.S_STALLT] == 0.0 and not R._settles(rested)
    assert hp.plan(rested, budget_s=5.0).found


def test_a_horizon_run_holds_a_saturated_drive_at_rest_before_it_falls_back(trap, monkeypatch):
    """A horizon run whose plans drive the braked pivot (scripted here for the first two
    periods) finds no way on from where the vehicle stops: it holds the wheels at rest for
    one period, the next plan made meanwhile, and drives on to the goal (horizon JSON
    ``settled``). Without that (``_settles`` never true) its whole-route fallback finds no
    way on either: the run failed there, and since 2026-12-07 backs off along the way it
    came and plans from there instead, the detour the settle spares it."""
    real = HZ.HorizonPlanner.plan
    calls = []

    def scripted(self, start, previous=None, budget_s=None):
        calls.append(1)
        if len(calls) <= 2:
            return HZ.HorizonPlan(start, list(TRAP[len(calls) - 1:]), 0.0, 0.0, False, "search", 0, 0.0)
        return real(self, start, previous, budget_s)

    monkeypatch.setattr(HZ.HorizonPlanner, "plan", scripted)
    res = R.run(trap, "time")
    assert res.status == "reached", res.reason
    assert res.horizon.settled == 1 and res.to_json()["horizon"]["settled"] == 1
    assert res.driven[:3] == [TRAP[0], TRAP[1], (0.0, 0.0, trap.scenario.planner.period_s)]
    assert [r.why for r in res.plans].count(R.SETTLED) == 1
    assert not any(r.why.startswith("backed off") for r in res.plans)
    from sbmpc.commands.run import summary
    assert "wheels held at rest 1 period to unload a saturated drive" in summary(res)
    jsonschema.validate(res.to_json(), schemas.run())
    calls.clear()
    monkeypatch.setattr(EX, "settles", lambda X: False)
    res = R.run(trap, "time")
    assert res.horizon.settled == 0 and res.stalls == 0
    backed = [r for r in res.plans if r.why.startswith("backed off: no way on from")]
    assert backed, [(r.why, r.plan.reason) for r in res.plans]
