"""The controller a robot calls (:class:`sbmpc.robot.Controller`): driven against the
simulated truth at 0.1 s and 1 s periods, fed measurements with missing channels and bad
timestamps, a slow planner stubbed in; its estimator and its cmd_vel conversion."""
from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from dynamics import kernels as K
from dynamics.params import load_vehicle
from sbmpc import execution as EX
from sbmpc import receding as R
from sbmpc import scenario as SC
from sbmpc.errors import InputError
from sbmpc.planning import horizon as HZ
from sbmpc.planning import world as WO
from sbmpc.problems import skidsteer as SS
from sbmpc.robot import Controller, Estimator, Measurement, to_twist, to_wheels

SCN = Path(__file__).resolve().parents[1] / "scenarios"


def _world(name="flat", **planner):
    scn = SC.load(SCN / f"{name}.yaml")
    return WO.resolve(replace(scn, planner=replace(scn.planner, **planner)))


@pytest.fixture(scope="module")
def flat():
    return _world(horizon_s=10.0)


def _drive(world, ctrl, cost="time", truth=None, t_max=120.0):
    """The controller against the simulated truth (as ``sbmpc run`` does): returns the
    commands, the end code and the truth's last state."""
    twin = world if truth is None else replace(world, vehicle=truth)
    real = R._Executor(twin, cost)
    X = WO.start_state(twin)
    cmds, stalled = [], False
    while X[K.S_T] < t_max:
        cmd = ctrl.step(float(X[K.S_T]), R.measured(X, twin.vehicle, stalled))
        cmds.append(cmd)
        if cmd.done:
            return cmds, None, X
        _, end, X = real.step(X, (cmd.wl, cmd.wr, ctrl.period_s), record=False)
        stalled = end == -SS.STALL
        if stalled:
            R._protected(X, real)
        elif end != 0:
            return cmds, end, X
    return cmds, "timeout", X


@pytest.mark.parametrize("period", [0.1, 1.0])
def test_the_controller_drives_the_truth_into_the_goal_within_the_drives_limits(flat, period):
    """At a 0.1 s and a 1 s control period, on flat: the truth ends in the goal disc, every
    command within the sampled wheel-speed range, its twist the wheel speeds' by the
    vehicle's track, and at 0.1 s the wheel speeds change only at the planner's periods
    (1 s: a command held for ten steps)."""
    ctrl = Controller(flat, "time", period_s=period, lockstep=True)
    cmds, end, X = _drive(flat, ctrl)
    ctrl.close()
    assert end == SS.IN_GOAL, (end, ctrl.status, ctrl.reason)
    lo, hi = WO.wheel_speed_range(flat)
    w = np.array([(c.wl, c.wr) for c in cmds])
    assert np.all(w >= lo - 1e-9) and np.all(w <= hi + 1e-9)
    v = flat.vehicle
    for c in cmds:
        assert c.v == pytest.approx(0.5 * v.wheel_radius * (c.wl + c.wr))
        assert c.omega == pytest.approx(v.wheel_radius * (c.wr - c.wl) / v.width)
    assert ctrl.plans and ctrl.periods >= 10
    if period == 0.1:
        changes = np.flatnonzero(np.any(np.diff(w, axis=0) != 0.0, axis=1)) + 1
        assert len(changes) <= ctrl.periods + 1 and len(cmds) >= 8 * ctrl.periods
    # against the horizon run at 1 s: the same drive within 2 % of its time
    assert X[K.S_T] == pytest.approx(17.7, rel=0.05)


def test_sbmpc_runs_horizon_mode_through_the_controller_at_its_period(flat):
    """``sbmpc run`` with a horizon is the controller against the truth: at 0.1 s and 1 s
    (run.control_period_s) both reach the goal with the same plans' drive, within 2 %."""
    runs = {}
    for p in (0.1, 1.0):
        w = replace(flat, scenario=replace(flat.scenario, run=replace(flat.scenario.run, control_period_s=p)))
        runs[p] = R.run(w, "time")
        assert runs[p].status == "reached", runs[p].reason
        assert runs[p].horizon is not None and runs[p].horizon.seconds
    assert runs[0.1].travel_time_s == pytest.approx(runs[1.0].travel_time_s, rel=0.02)
    assert runs[0.1].energy_J == pytest.approx(runs[1.0].energy_J, rel=0.02)


def test_step_never_waits_on_a_slow_planner_and_holds_the_wheels_at_rest_meanwhile(flat, monkeypatch):
    """A planner stubbed to take 0.6 s a plan: without lockstep (a robot), every step
    returns within the 0.1 s period (the planning runs in the worker thread), the wheels
    held at rest ('planning') until the first plan is ready; then it drives."""
    real = HZ.HorizonPlanner.plan

    def slow(self, *a, **k):
        time.sleep(0.6)
        return real(self, *a, **k)
    monkeypatch.setattr(HZ.HorizonPlanner, "plan", slow)
    ctrl = Controller(flat, "time", period_s=0.1)
    X = WO.start_state(flat)
    real_ex = R._Executor(flat, "time")
    seen, took = [], []
    t = 0.0
    try:
        for _ in range(30):
            t0 = time.perf_counter()
            cmd = ctrl.step(t, R.measured(X, flat.vehicle))
            took.append(time.perf_counter() - t0)
            seen.append(cmd)
            _, _, X = real_ex.step(X, (cmd.wl, cmd.wr, 0.1), record=False)
            t += 0.1
            time.sleep(max(0.0, 0.1 - took[-1]))
    finally:
        ctrl.close()
    assert max(took) < 0.1, max(took)
    assert seen[0].status == "planning" and (seen[0].wl, seen[0].wr) == (0.0, 0.0)
    first = next(i for i, c in enumerate(seen) if c.status == "horizon")
    assert 4 <= first <= 12                     # the 0.6 s plan arrived, and it drives
    assert all((c.wl, c.wr) == (0.0, 0.0) for c in seen[:first])
    assert any(c.wl != 0.0 or c.wr != 0.0 for c in seen[first:])


def test_measurements_with_missing_channels_or_bad_times_get_a_clear_error_or_a_hold(flat):
    """Pose alone is enough (wheel speeds and currents then come from the model driven by
    the commands issued); a repeated time gets the last command again; a time that goes
    back, a missing pose, a NaN, one side of a pair or a pose off the map is an
    InputError naming it, and the controller goes on at the next good measurement."""
    s = flat.scenario.start
    ctrl = Controller(flat, "time", period_s=0.1, lockstep=True)
    try:
        m = Measurement(s["x"], s["y"], math.radians(s["yaw_deg"]))
        a = ctrl.step(0.0, m)
        assert ctrl.step(0.0, m) is a
        b = ctrl.step(0.1, m)
        assert b.status == "horizon" and np.isfinite([b.wl, b.wr, b.v, b.omega]).all()
        bad = [(0.05, m, "expected times that never go back"),
               (0.2, Measurement(s["x"], None, 0.0), "field 'y': expected the pose"),
               (0.2, Measurement(s["x"], s["y"], float("nan")), "field 'yaw': expected a finite number"),
               (0.2, Measurement(s["x"], s["y"], 0.0, wl=1.0), "expected both sides or neither"),
               (0.2, Measurement(500.0, s["y"], 0.0), "expected a position on the map"),
               (float("inf"), m, "t: expected a finite time")]
        for t, mm, msg in bad:
            with pytest.raises(InputError, match=msg):
                ctrl.step(t, mm)
        c = ctrl.step(0.2, m)
        assert np.isfinite([c.wl, c.wr]).all() and not c.done
    finally:
        ctrl.close()
    with pytest.raises(InputError, match="period_s: expected a control period in"):
        Controller(flat, "time", period_s=2.0)


def test_the_estimate_of_the_truth_is_the_truth_where_the_model_is_right(flat):
    """The truth driven by the planning vehicle's own model: from pose, wheel speeds and
    currents every 0.1 s, the estimate's loop states (references, integrals, currents,
    speeds) equal the truth's to 1e-9 after 3 s of accelerating and turning; from the
    pose alone, its wheel speeds follow the commands (the model's, within 1e-9 too)."""
    est_full, est_pose = Estimator(flat, "time"), Estimator(flat, "time")
    real = R._Executor(flat, "time")
    X = WO.start_state(flat)
    cmds = [(6.0, 8.0)] * 20 + [(8.0, 4.0)] * 10
    issued = []
    for c in cmds:
        m = R.measured(X, flat.vehicle)
        est_full.update(X[K.S_T], m, issued)
        est_pose.update(X[K.S_T], Measurement(m.x, m.y, m.yaw), issued)
        _, _, X = real.step(X, (*c, 0.1), record=False)
        issued = [(*c, 0.1)]
    m = R.measured(X, flat.vehicle)
    full = est_full.update(X[K.S_T], m, issued)
    pose = est_pose.update(X[K.S_T], Measurement(m.x, m.y, m.yaw), issued)
    for i in (K.S_WL, K.S_WR, K.S_REFL, K.S_REFR, K.S_INTL, K.S_INTR, K.S_IL, K.S_IR, K.S_X, K.S_YAW):
        assert full[i] == pytest.approx(X[i], abs=1e-9), K
        assert pose[i] == pytest.approx(X[i], abs=1e-6), i


def test_a_heavier_truths_currents_correct_the_integrals_the_model_got_wrong(flat):
    """A truth 30 % heavier, driven up to 4 rad/s and into a turn: from its measured
    currents and speeds the inner side's PID integral lands on the truth's (within 1 %), where
    the pose-only estimate keeps the planning model's, 5 % off or more."""
    heavy = replace(flat, vehicle=WO.heavier(flat.vehicle, 1.3))
    est_full, est_pose = Estimator(flat, "time"), Estimator(flat, "time")
    real = R._Executor(heavy, "time")
    X = WO.start_state(heavy)
    issued = []
    for k in range(40):
        m = R.measured(X, heavy.vehicle)
        est_full.update(X[K.S_T], m, issued)
        est_pose.update(X[K.S_T], Measurement(m.x, m.y, m.yaw), issued)
        c = (4.0, 4.0) if k < 20 else (4.0, 6.0)
        _, _, X = real.step(X, (*c, 0.1), record=False)
        issued = [(*c, 0.1)]
    m = R.measured(X, heavy.vehicle)
    full = est_full.update(X[K.S_T], m, issued)
    pose = est_pose.update(X[K.S_T], Measurement(m.x, m.y, m.yaw), issued)
    assert full[K.S_INTL] == pytest.approx(X[K.S_INTL], rel=0.01)
    assert abs(pose[K.S_INTL] - X[K.S_INTL]) > 0.05 * abs(X[K.S_INTL])
    # the outer side is at its current limit: its integral is not observable, and the
    # estimate keeps the prediction's (the measured current is the limit)
    assert X[K.S_IR] == pytest.approx(heavy.vehicle.current_limit) and full[K.S_IR] == X[K.S_IR]


@settings(max_examples=60, deadline=None)
@given(st.floats(-15, 15), st.floats(-15, 15))
def test_cmd_vel_and_wheel_speeds_convert_both_ways_with_the_drivers_track(wl, wr):
    """to_twist and to_wheels are each other's inverse, for the P3-AT (track = width) and
    the Husky (its driver's track, 0.555 m x 1.875)."""
    for name in ("p3at", "husky"):
        v = load_vehicle(name)
        a, b = to_wheels(*to_twist(wl, wr, v), v)
        assert a == pytest.approx(wl, abs=1e-9) and b == pytest.approx(wr, abs=1e-9)


def test_the_husky_is_clearpaths():
    """The shipped Husky against Clearpath's description (clearpath_common a200
    control.yaml, husky_description URDF): wheel radius 0.1651 m, wheel separation 0.555 m,
    and its driver turns cmd_vel into wheel speeds with 0.555 m x 1.875 = 1.04 m: an
    on-the-spot turn at 1 rad/s is +-3.15 rad/s per side, not the 1.68 of the bare track."""
    v = load_vehicle("husky")
    assert v.wheel_radius == pytest.approx(0.1651) and v.width == pytest.approx(0.555)
    assert v.command_track == pytest.approx(0.555 * 1.875, abs=1e-3)
    wl, wr = to_wheels(0.0, 1.0, v)
    assert wr == pytest.approx(-wl) and wr == pytest.approx(0.5 * 1.0406 / 0.1651, rel=1e-4)
    assert load_vehicle("p3at").command_track == load_vehicle("p3at").width


def test_a_planner_that_fails_stops_the_controller_with_the_reason_and_never_a_wrong_command(flat, monkeypatch):
    """A plan that raises in the worker (a bug, a corrupt map): the controller stops for
    good, says why, and every later step holds the wheels at rest; after close(), a step
    holds them at rest too. Numbers of NumPy's types are measurements like any other."""
    def broken(self, *a, **k):
        raise RuntimeError("the planner broke (test)")
    monkeypatch.setattr(HZ.HorizonPlanner, "plan", broken)
    s = flat.scenario.start
    ctrl = Controller(flat, "time", period_s=0.1, lockstep=True)
    m = Measurement(np.float64(s["x"]), np.float32(s["y"]), np.float64(0.0), wl=np.float32(0.0), wr=0)
    a = ctrl.step(0.0, m)
    assert a.done and a.status == "stopped" and "the planner broke (test)" in a.reason
    b = ctrl.step(0.1, m)
    assert b.done and (b.wl, b.wr) == (0.0, 0.0)
    ctrl.close()
    monkeypatch.undo()
    fresh = Controller(flat, "time", period_s=0.1, lockstep=True)
    fresh.close()
    c = fresh.step(0.0, m)
    assert c.done and c.status == "stopped" and (c.wl, c.wr) == (0.0, 0.0) and "closed" in c.reason


def test_the_estimate_keeps_a_command_delay_in_its_prediction(flat):
    """A vehicle whose commands reach the drive 0.15 s late (a diagnosed or calibrated
    `delay`), driven through a speed step and a turn: from the pose alone, the estimate's
    wheel speeds follow the truth's to 1e-6 (the prediction holds the commands in the same
    pipe), where a prediction without the delay is off by the first 0.15 s of each step."""
    slow = replace(flat, vehicle=flat.vehicle.replace(delay=0.15))
    est = Estimator(slow, "time")
    real = R._Executor(slow, "time", slow.vehicle.delay)
    X = WO.start_state(slow)
    issued = []
    for c in [(6.0, 6.0)] * 12 + [(8.0, 4.0)] * 12:
        m = R.measured(X, slow.vehicle)
        E = est.update(X[K.S_T], Measurement(m.x, m.y, m.yaw), issued)
        assert E[K.S_WL] == pytest.approx(X[K.S_WL], abs=1e-6) and E[K.S_WR] == pytest.approx(X[K.S_WR], abs=1e-6)
        _, _, X = real.step(X, (*c, 0.1), record=False)
        issued = [(*c, 0.1)]


@pytest.mark.slow
def test_after_a_stall_the_controller_plans_as_the_margins_twin_and_reaches():
    """steep_hill with a P3-AT whose drive gives 17 % less current (3.0 A for 3.62): the
    horizon plans made for the file's vehicle drove it into the flank, where it stalled four
    times and the run failed. From the first stall on, the controller plans for the
    margin's pessimistic twin (as whole-route runs do) of the vehicle as the periods before
    the stall measured it: the fit from the robot's 0.1 s measurements (wheel speeds,
    currents) finds the current limit 0.83 times the file's within 3 %, and says the
    stall was a weaker drive's. The run reaches the goal with at most two stalls, and says
    from when and as what it planned."""
    world = _world("steep_hill", horizon_s=10.0)
    weak = world.vehicle.replace(name="p3at_weak", current_limit=3.0)
    out = R.run(world, "time", truth=weak)
    assert out.status == "reached", out.reason
    assert 1 <= out.stalls <= 2
    first = out.inferred[0]
    assert first["inferred"] == "weaker" and first["fit"]["current_limit"] == pytest.approx(3.0 / 3.62, rel=0.03)
    assert out.planned_as.startswith("p3at as measured (") and "current_limit x0.8" in out.planned_as
    assert out.weaker_from is not None and out.weaker_from > 0.0
    assert any("planning as the margin's twin of p3at as measured" in p.why for p in out.plans)


def test_one_stall_reported_twice_counts_once_and_a_later_one_counts_again(flat):
    """A stall is reported twice where the estimate's model flags it a few ms before the
    drive's own protection trips (or after): on hills_field four of six runs that failed on
    four stalls had one counted twice, 0.01-0.23 s apart, and the second count marked
    flat ground ahead a wall. A restarted drive cannot fail the stall test again within
    STALL_TIME: the report 0.1 s later at the same place is the same stall (and is planned
    from, as a drive restarted); one 2 s on, metres away, is a new one."""
    ctrl = Controller(flat, "time", period_s=0.1, lockstep=True)
    real = R._Executor(flat, "time")
    X = WO.start_state(flat)
    flags = {30: True, 31: True, 50: True}       # control periods (0.1 s) whose measurement says stalled
    for k in range(60):
        cmd = ctrl.step(float(X[K.S_T]), R.measured(X, flat.vehicle, flags.get(k, False)))
        assert not cmd.done, ctrl.reason
        _, end, X = real.step(X, (cmd.wl, cmd.wr, ctrl.period_s), record=False)
        if flags.get(k + 1):
            R._protected(X, real)
    ctrl.close()
    assert ctrl.stalls == 2, ctrl.stall_at
    (x0, y0), (x1, y1) = ctrl.stall_at
    assert math.hypot(x1 - x0, y1 - y0) > 0.5
    assert not ctrl._marks          # no second stall near the first: nothing marked a wall


@pytest.mark.parametrize("currents, wall", [((3.0, -3.0), False), ((3.0, 3.0), True)])
def test_a_second_stall_near_the_first_marks_a_wall_ahead_unless_it_was_in_a_turn(flat, currents, wall):
    """A second stall within MARK_NEAR of the first makes the slope ahead a wall in the
    plans' map; not where the two sides' currents pulled against each other at the
    drive's limit, a turn the vehicle could not make (on hills_field about half the drawn
    vehicles' stalls, on gentle ground): the ground ahead is not what held it."""
    ctrl = Controller(flat, "time", period_s=0.1, lockstep=True)
    real = R._Executor(flat, "time")
    X = WO.start_state(flat)
    stalls = (20, 32)                # control periods whose measurement says stalled, in a turn
    for k in range(45):
        m = R.measured(X, flat.vehicle, k in stalls)
        if k in stalls:
            m = replace(m, il=currents[0], ir=currents[1])
        cmd = ctrl.step(float(X[K.S_T]), m)
        assert not cmd.done, ctrl.reason
        _, end, X = real.step(X, (cmd.wl, cmd.wr, ctrl.period_s), record=False)
        if k + 1 in stalls:
            R._protected(X, real)
    ctrl.close()
    assert ctrl.stalls == 2
    (x0, y0), (x1, y1) = ctrl.stall_at
    assert math.hypot(x1 - x0, y1 - y0) < EX.MARK_NEAR
    assert bool(ctrl._marks) is wall
    assert any("slope(s) kept off" in p.why for p in ctrl.plans) is wall


def test_a_turning_stall_is_read_from_the_currents_at_the_stall_while_a_robot_waits_for_the_fit(flat, monkeypatch):
    """On a robot (lockstep=False) the fit a stall asks for is made in the worker while
    step keeps being called, each call with the currents of a drive held at rest: the
    turn is judged on the currents of the call that reported the stall, so a second
    turning stall near the first still marks no wall."""
    from sbmpc.robot import controller as CT
    slow = CT._fit

    def fit(*a, **k):
        time.sleep(0.3)
        return slow(*a, **k)
    monkeypatch.setattr(CT, "_fit", fit)
    ctrl = Controller(flat, "time", period_s=0.1, lockstep=False)
    real = R._Executor(flat, "time")
    X = WO.start_state(flat)
    first, driving, k = None, 0, 0
    while X[K.S_T] < 30.0 and ctrl.stalls < 2:
        # the first stall 2 periods in, the second 0.4 s after it drives again (past STALL_TIME: a new one)
        flag = (first is None and ctrl.periods >= 2) or (first is not None and driving == 4)
        m = R.measured(X, flat.vehicle, flag)
        if flag:
            m = replace(m, il=3.0, ir=-3.0)
        before = ctrl.stalls
        cmd = ctrl.step(float(X[K.S_T]), m)
        assert not cmd.done, ctrl.reason
        if ctrl.stalls > before:
            first = ctrl.periods
            R._protected(X, real)
        elif first is not None and cmd.status == "horizon":
            driving += 1
        _, _, X = real.step(X, (cmd.wl, cmd.wr, ctrl.period_s), record=False)
        time.sleep(0.01)
        k += 1
    deadline = time.time() + 10.0
    while ctrl.status in ("planning", "waiting") and time.time() < deadline:
        ctrl.step(float(X[K.S_T]) + 0.1 * (k := k + 1), R.measured(X, flat.vehicle))
        time.sleep(0.05)
    ctrl.close()
    assert ctrl.stalls == 2
    (x0, y0), (x1, y1) = ctrl.stall_at
    assert math.hypot(x1 - x0, y1 - y0) < EX.MARK_NEAR
    assert not ctrl._marks


def test_a_second_back_off_goes_further_back_along_the_way_never_forward_again(flat):
    """execution.back_along: the first back-off retraces the way's last 2 periods (a stop,
    then each negated, latest first) and takes them off the way; the second the 4 before
    them, not the periods just driven back; with fewer periods left than a retrace needs,
    none. The controller keeps the periods it drives back out of its way (they are in its
    record, ``driven``)."""
    way = [(float(k), float(k), 1.0) for k in range(1, 8)]
    back, tried = EX.back_along([], None, way, 0)
    assert tried == 1 and back == [(0.0, 0.0, 1.0), (-7.0, -7.0, 1.0), (-6.0, -6.0, 1.0)] and len(way) == 5
    back, tried = EX.back_along([], None, way, tried)
    assert tried == 2 and back[1:] == [(-k, -k, 1.0) for k in (5.0, 4.0, 3.0, 2.0)] and way == [(1.0, 1.0, 1.0)]
    assert EX.back_along([], None, way, 0) == (None, 2)
    ctrl = Controller(flat, "time", lockstep=True)
    try:
        X = WO.start_state(flat)
        for status in ("horizon", "backing"):
            ctrl._last_t = 0.0
            g = ctrl._drive((1.0, 1.0, 1.0), status)
            next(g)
            ctrl._last_t = 1.0
            with pytest.raises(StopIteration):
                g.send((X, False))
        assert len(ctrl.driven) == 2 and ctrl._way == ctrl.driven[:1]
    finally:
        ctrl.close()


def test_the_controller_adapts_to_the_vehicle_its_measurements_show(flat):
    """A P3-AT with 20 % less battery voltage on the floor, driven by the controller at
    0.1 s with run.adapt_periods 3: the fit from the robot's own measurements (wheel
    speeds and currents every 0.1 s, made in the worker while it drives) pins v_max at
    0.80 of the file's and the others within 3 %, and the horizon plans are made for that
    vehicle from then on: a plan then still holds one period later (the warm start kept)
    far more often than without adaptation (14 of 24 plans against 4 of 25 measured), where the
    plans of the file's vehicle, too fast by a fifth, were replaced by the search every
    period; the run reaches the goal."""
    slow = flat.vehicle.replace(v_max=0.8 * flat.vehicle.v_max)
    plain = R.run(flat, "time", slow)
    res = R.run(flat, "time", slow, replace(flat.scenario.run, adapt_periods=3))
    assert plain.end == res.end == "reached"
    assert len(res.adapted) >= 1 and not plain.adapted
    f = res.adapted[0]["fit"]
    assert f["v_max"] == pytest.approx(0.8, abs=0.02)
    assert all(abs(f[k] - 1.0) < 0.03 for k in ("mass", "current_limit", "grip", "mu_roll")), f
    assert res.planned_as.startswith("p3at as measured (v_max x0.8")
    assert res.horizon.kept_previous > plain.horizon.kept_previous + 3, (res.horizon.kept_previous,
                                                                         plain.horizon.kept_previous)


def test_a_vehicle_with_no_way_on_and_no_stall_backs_off_and_plans_from_lower_down(flat, monkeypatch):
    """A vehicle that lost its run-up part way up a ramp it cannot hold has no plan from
    there (every control stalls) though it has not stalled yet: the horizon plans
    stubbed to find no way on from t = 5 s to 8 s, and the whole-route plan from there
    too. The controller settles, hands over, finds no whole-route plan, and backs off
    along the way it came, as after a stall (before, it stopped there: 4 of 20
    runup_ramp horizon runs ended 3 m short on the ramp, 2026-12-07); the horizon plans
    from lower down lead on and the run reaches the goal, with no stall."""
    from sbmpc.planning import plan as PL
    real = HZ.HorizonPlanner.plan

    def blind(self, start, previous=None, budget_s=None):
        if 5.0 < start[K.S_T] < 8.0:
            return HZ.HorizonPlan(start, [], np.inf, np.inf, False, "", 0, 0.0, reason="stubbed: no way on")
        return real(self, start, previous, budget_s)
    monkeypatch.setattr(HZ.HorizonPlanner, "plan", blind)
    route = PL.plan

    def no_route(world, cost, *args, start=None, **kw):
        p = route(world, cost, *args, start=start, **kw)
        if start is not None and start[K.S_T] > 4.0:
            return replace(p, status="no_path", reason="no way (the test's)")
        return p
    monkeypatch.setattr(PL, "plan", no_route)
    res = R.run(flat, "time")
    assert res.end == "reached", res.reason
    assert res.stalls == 0
    assert any(p.why.startswith("backed off: no way on from") for p in res.plans), [p.why for p in res.plans]
