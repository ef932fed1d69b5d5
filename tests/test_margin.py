"""Plans with margin (planner.margin, margin_turn, margin_tip_deg; sbmpc.planning.margin): the
drive's share, the turn reserve, the pessimistic twin against the heavier vehicle's own
drive at 1 kHz, the tip-over margin, the fallback, the report and the run's guard."""
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, strategies as st

from dynamics import kernels as K
from dynamics.drive import current_window, window_share
from sbmpc import api
from sbmpc import execution as EX
from sbmpc.planning import check as CK
from sbmpc.planning import plan as PL
from sbmpc.planning import problem as PB
from sbmpc.planning import world as WO
from sbmpc.planning.margin import report, robustness
from sbmpc.problems import skidsteer as SS

ROOT = Path(__file__).resolve().parents[1]
P3AT = dict(v_max=12.0, k=1.3825, ra=0.706, imax=3.62)


def _plane(grade_deg=0.0, roll_deg=0.0, size=(40.0, 12.0), res=0.5, **planner):
    """A world on a tilted plane of grass: height rises by tan(grade) per metre along x
    and by tan(roll) per metre along y; start at rest at (3, 6) facing +x, goal far ahead."""
    nx, ny = int(size[0] / res) + 1, int(size[1] / res) + 1
    x = np.arange(nx) * res
    y = np.arange(ny) * res
    H = x[None, :] * math.tan(math.radians(grade_deg)) + y[:, None] * math.tan(math.radians(roll_deg))
    scn = {"name": "plane", "map": {"heights": [[0.0, 0.0], [0.0, 0.0]], "resolution": 1.0},
           "terrain": "grass", "vehicle": "p3at", "start": {"x": 3.0, "y": 6.0, "yaw_deg": 0.0, "v": 0.0},
           "goal": {"x": size[0] - 3.0, "y": 6.0, "radius": 1.0}, "cost": "time"}
    return api.load_world(scn, heights=H, resolution=res, **planner)


def _edge(world, X, control, margin=True):
    """One searched edge (propagate) from X: (cost or code, end state)."""
    Q, data = PB.pack_world(world, "time", margin=margin)
    out = np.zeros(SS.NX)
    X = WO._start(world, X)
    c = SS.propagate(Q, data, X, np.array(control, float), out)
    return c, out


# ---- the drive's share ---------------------------------------------------------------------
def test_the_drive_share_is_0_at_no_current_and_1_at_either_bound():
    k, ra, imax, vm = P3AT["k"], P3AT["ra"], P3AT["imax"], P3AT["v_max"]
    assert window_share(0.0, 3.0, vm, k, ra, imax) == 0.0
    assert window_share(imax, 1.0, vm, k, ra, imax) == pytest.approx(1.0)        # continuous limit
    w = 8.0                                                                         # the voltage bound
    assert window_share((vm - k * w) / ra, w, vm, k, ra, imax) == pytest.approx(1.0)
    assert window_share(-imax, -1.0, vm, k, ra, imax) == pytest.approx(1.0)
    # over-speed (back-EMF beyond the supply): no driving current is left
    assert window_share(0.0 + 1e-9, 9.5, vm, k, ra, imax) == 1.0


@given(st.floats(-8.0, 8.0), st.floats(0.0, 1.0))
def test_the_drive_share_is_the_current_over_its_bound(w, f):
    """Within the window the share is linear in the current: f of the bound is f."""
    k, ra, imax, vm = P3AT["k"], P3AT["ra"], P3AT["imax"], P3AT["v_max"]
    lo, hi = current_window(w, vm, k, ra, imax)
    if hi > 1e-6:
        assert window_share(f * hi, w, vm, k, ra, imax) == pytest.approx(f, abs=1e-12)
    if lo < -1e-6:
        assert window_share(f * lo, w, vm, k, ra, imax) == pytest.approx(f, abs=1e-12)


# ---- the turn reserve ------------------------------------------------------------------------
def test_a_turn_at_the_drives_limit_breaks_the_turn_reserve_and_a_straight_run_at_top_speed_does_not():
    """On level grass the P3-AT's (4, 2) rad/s turn needs its whole drive (share 1 in
    steady state, bench: 0.90 on flat asphalt): with margin_turn 0.05 the edge fails on
    the margin, without it passes. Straight at the no-load speed the drive sits on its
    voltage bound too, but straight commands drive any symmetric vehicle straight: it passes."""
    w = _plane(margin_turn=0.05, margin=0.0, margin_tip_deg=0.0)
    X = WO.start_state(w)
    _, _, X, _ = CK.replay(w, "time", [(4.0, 4.0, 2.0)], every=1 << 30, start=X)     # at speed
    c, _ = _edge(w, X, (4.0, 2.0, 2.0))
    assert c == -SS.MARGIN
    c0, _ = _edge(w, X, (4.0, 2.0, 2.0), margin=False)
    assert c0 > 0.0
    top = w.vehicle.no_load_speed
    c1, S = _edge(w, X, (top, top, 2.0))
    assert c1 > 0.0 and S[SS.X_MT] == 0.0           # valid: straight commands never run the timer
    v = w.vehicle
    assert window_share(S[K.S_IL], S[K.S_WL], v.v_max, v.torque_constant, v.armature_resistance,
                        v.current_limit) == pytest.approx(1.0, abs=1e-3)     # ... though at the bound


# ---- the pessimistic twin --------------------------------------------------------------------
@pytest.fixture(scope="module")
def ramp():
    """Grass at 11.5 deg: the P3-AT holds it (12.2 deg at most); 10 % heavier with 10 %
    more grip it does not (about 10.5 deg)."""
    return _plane(11.5, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0)


def test_the_twin_fails_a_climb_the_heavier_vehicle_cannot_drive(ramp):
    """From 2 s of climbing at 4 rad/s, four more seconds straight up: the nominal
    vehicle gets through, the edge fails on the margin, and the twin's verdict is the
    heavier vehicle's own: the same controls driven by it at 1 kHz stall."""
    w = ramp
    lead = [(4.0, 4.0, 2.0)]
    X = WO.start_state(w)
    _, end, X1, _ = CK.replay(w, "time", lead, every=1 << 30, start=X)
    assert end == 0
    c, _ = _edge(w, X1, (4.0, 4.0, 4.0))
    assert c == -SS.MARGIN
    c0, _ = _edge(w, X1, (4.0, 4.0, 4.0), margin=False)
    assert c0 > 0.0
    v = w.vehicle
    heavy = replace(w, vehicle=v.replace(mass=v.mass * 1.1, inertia=v.inertia * 1.1),
                    terrains=tuple(t.replace(mu_sa=t.mu_sa * 1.1, mu_op=t.mu_op * 1.1) for t in w.terrains))
    _, end_h, _, _ = CK.replay(heavy, "time", lead + [(4.0, 4.0, 4.0)], every=1 << 30, dt=0.001)
    _, end_n, _, _ = CK.replay(w, "time", lead + [(4.0, 4.0, 4.0)], every=1 << 30, dt=0.001)
    assert end_h == -SS.STALL and end_n == 0


def test_a_gentler_climb_keeps_the_margin(ramp):
    """At 8 deg both vehicles climb: the margin passes the edge at the nominal's cost."""
    w = _plane(8.0, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0)
    X = WO.start_state(w)
    _, _, X1, _ = CK.replay(w, "time", [(4.0, 4.0, 2.0)], every=1 << 30, start=X)
    c, S = _edge(w, X1, (4.0, 4.0, 4.0))
    c0, S0 = _edge(w, X1, (4.0, 4.0, 4.0), margin=False)
    assert c > 0.0 and c == c0
    assert np.array_equal(S[:K.NS], S0[:K.NS])          # the vehicle's own state: untouched by the twin
    assert S[SS.X_TW + K.S_WL] < S[K.S_WL]             # the twin, heavier, lags on the climb


def test_a_grade_allowance_fails_a_climb_only_the_steeper_slope_would_stall():
    """margin_grade_deg (the map's slopes that far off): on 9 deg of grass the 10 %
    heavier twin climbs (it holds about 10.5 deg), so the edge keeps the margin; with
    2.5 deg more it meets 11.5 deg, which it cannot hold (the ramp test above: the
    heavier vehicle's own 1 kHz drive stalls there), and the edge fails on the margin;
    with 1 deg (10 deg) it still climbs."""
    costs = {}
    for a in (0.0, 1.0, 2.5):
        w = _plane(9.0, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0, margin_grade_deg=a)
        _, end, X1, _ = CK.replay(w, "time", [(4.0, 4.0, 2.0)], every=1 << 30, start=WO.start_state(w))
        assert end == 0
        costs[a] = _edge(w, X1, (4.0, 4.0, 4.0))[0]
    assert costs[0.0] > 0.0 and costs[1.0] == costs[0.0]
    assert costs[2.5] == -SS.MARGIN


def test_a_grade_allowance_makes_a_reversing_climb_steeper_too():
    """Reversing up 9 deg of grass (the nose downhill), the allowance is nose-down: with
    2.5 deg the twin meets 11.5 deg and the edge fails on the margin, without it the edge
    keeps the margin (an allowance added nose-up would have made the climb gentler)."""
    costs = {}
    for a in (0.0, 2.5):
        w = _plane(-9.0, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0, margin_grade_deg=a)
        w = replace(w, scenario=replace(w.scenario, start=dict(w.scenario.start, x=30.0)))
        _, end, X1, _ = CK.replay(w, "time", [(-4.0, -4.0, 2.0)], every=1 << 30, start=WO.start_state(w))
        assert end == 0
        costs[a] = _edge(w, X1, (-4.0, -4.0, 4.0))[0]
    assert costs[0.0] > 0.0 and costs[2.5] == -SS.MARGIN


def test_the_twin_with_an_allowance_meets_a_descent_of_that_grade_as_level_ground():
    """The allowance is added to the grade the twin meets (the tangent of the sum), and
    nothing else: on a 2 deg descent with 2 deg of allowance the twin's drive (wheel
    speeds, currents, energy) is the twin's on level ground from the same state, while
    the vehicle itself drives downhill on less energy."""
    lvl = _plane(0.0, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0)
    down = _plane(-2.0, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0, margin_grade_deg=2.0)
    X = WO.start_state(lvl)
    _, S0 = _edge(lvl, X, (4.0, 4.0, 3.0))
    _, S1 = _edge(down, X, (4.0, 4.0, 3.0))
    tw = [SS.X_TW + k for k in (K.S_WL, K.S_WR, K.S_E, K.S_STALLT)]
    assert np.allclose(S1[tw], S0[tw], rtol=1e-9, atol=1e-9)
    assert S1[K.S_E] < 0.8 * S0[K.S_E]


def test_the_value_tables_give_the_twin_the_same_allowance():
    """The value's motion tables judge the twin's manoeuvres on grades shifted by the
    allowance: with 2.5 deg (two of the tables' 1.25 deg steps) the twin holds at grade
    g what it holds at g + 2.5 deg without (reversing, g - 2.5 deg); the planning
    vehicle's own rows unchanged."""
    from sbmpc.planning import motions as MO
    t0 = MO.tables(_plane(0.0, margin=0.1))
    t1 = MO.tables(_plane(0.0, margin=0.1, margin_grade_deg=2.5))
    assert MO.GRADE_STEP * 2 == 2.5
    back = t0["cmds"].sum(axis=1) < 0.0        # reversing: the allowance nose-down
    assert back.any() and (~back).any()
    assert np.array_equal(t1["ok_twin"][:, :-2][..., ~back], t0["ok_twin"][:, 2:][..., ~back])
    assert np.array_equal(t1["ok_twin"][:, 2:][..., back], t0["ok_twin"][:, :-2][..., back])
    assert np.array_equal(t1["ok"], t0["ok"]) and np.array_equal(t1["p"], t0["p"])
    assert t1["ok_twin"].sum() < t0["ok_twin"].sum()


# ---- the tip-over margin -----------------------------------------------------------------------
def test_a_side_slope_inside_the_tip_margin_fails_on_the_margin_and_passes_without():
    """Driving along the contour of a 27 deg side slope: 3 deg from the 30 deg tip-over
    limit, inside the 5 deg margin."""
    w = _plane(0.0, 27.0, size=(40.0, 20.0), margin=0.0, margin_turn=0.0, margin_tip_deg=5.0)
    X = WO.start_state(replace(w, scenario=replace(w.scenario, start=dict(w.scenario.start, y=10.0))))
    c, _ = _edge(w, X, (3.0, 3.0, 1.0))
    assert c == -SS.MARGIN
    c0, _ = _edge(w, X, (3.0, 3.0, 1.0), margin=False)
    assert c0 > 0.0


def _flank(at_deg, yaw_deg=0.0, margin_tip_deg=5.0):
    """A world on a flank that steepens uphill (heights c y^2: the side slope grows with
    y), and the state at rest facing ``yaw_deg`` from +x (0: along the contour, positive:
    up it) where its slope is ``at_deg``."""
    res, c = 0.25, 0.0255
    x, y = np.arange(0.0, 30.0 + res / 2, res), np.arange(0.0, 20.0 + res / 2, res)
    H = np.repeat((c * y * y)[:, None], x.size, axis=1)
    scn = {"name": "flank", "map": {"heights": [[0.0, 0.0], [0.0, 0.0]], "resolution": 1.0},
           "terrain": "grass", "vehicle": "p3at", "start": {"x": 5.0, "y": 2.0, "yaw_deg": 0.0, "v": 0.0},
           "goal": {"x": 25.0, "y": 2.0, "radius": 1.0}, "cost": "time"}
    w = api.load_world(scn, heights=H, resolution=res, margin=0.0, margin_turn=0.0, margin_tip_deg=margin_tip_deg)
    y0 = math.tan(math.radians(at_deg)) / (2.0 * c)
    return w, WO.start_state(replace(w, scenario=replace(w.scenario, start=dict(w.scenario.start, y=y0,
                                                                                   yaw_deg=yaw_deg))))


def test_a_search_from_inside_the_tip_margin_may_lead_out_of_it_and_none_steeper():
    """A vehicle that drifted onto a 27 deg flank (inside the 5 deg margin of 30 deg): every
    edge from there failed on the margin at its first step, so the fallback without the
    margin rode the tip-over limit. From inside, the margin's limit is where it stands:
    along the contour and down the flank pass, on up it (steeper) fails."""
    w, X = _flank(27.0)
    assert math.degrees(PB.standing_tilt(w, X)) == pytest.approx(27.0, abs=0.3)
    Q, data = PB.pack_world(w, "time", margin=True)
    assert math.degrees(Q[SS.Q_TIPM]) == pytest.approx(25.0)
    inside = PB.from_inside(Q, w, X)
    assert math.degrees(inside[SS.Q_TIPM]) == pytest.approx(math.degrees(PB.standing_tilt(w, X)), abs=1e-6)
    assert Q[SS.Q_ASIDE] == 0.1 and inside[SS.Q_ASIDE] == 0.0     # inside itself: no allowance aside left
    assert PB.from_inside(Q, w, _flank(20.0)[1]) is Q                 # flatter than the margin: as it was
    X0 = WO._start(w, X)

    def edge(Qx, control):
        return SS.propagate(Qx, data, X0.copy(), np.array(control, float), np.zeros(SS.NX))
    assert edge(Q, (3.0, 3.0, 1.0)) == -SS.MARGIN                    # before: the first step fails
    assert edge(inside, (3.0, 3.0, 1.0)) > 0.0                       # along the contour
    assert edge(inside, (4.0, 1.0, 1.0)) > 0.0                       # turning right: down the flank
    w, X = _flank(27.0, yaw_deg=10.0)                                  # heading a little up the flank
    X0 = WO._start(w, X)
    inside = PB.from_inside(Q, w, X)
    assert edge(inside, (3.0, 3.0, 1.0)) == -SS.MARGIN               # straight on: steeper
    assert edge(inside, (-3.0, -3.0, 1.0)) > 0.0                     # backing down: out of it


@given(grade=st.floats(-20.0, 20.0), roll=st.floats(-20.0, 20.0), yaw=st.floats(-180.0, 180.0),
       aside=st.floats(0.0, 0.5))
def test_on_a_plane_the_margins_aside_changes_no_tilt(grade, roll, yaw, aside):
    """planner.margin_aside_m judges the tilt with the vehicle moved aside; on a plane the
    tilt is the same everywhere (the map's bilinear heights are exact there), so it
    changes nothing: the allowance bites only where the tilt changes with the place."""
    w = _plane(grade, roll, size=(20.0, 20.0))
    X = WO.start_state(w)
    X[K.S_X], X[K.S_Y], X[K.S_YAW] = 10.0, 10.0, math.radians(yaw)
    assert PB.standing_tilt(w, X, aside) == pytest.approx(PB.standing_tilt(w, X), abs=1e-9)


def test_beside_narrow_pass_wall_the_margin_keeps_the_vehicle_its_aside_off_the_wall():
    """narrow_pass's pass wall rises 1.6 m in one 0.25 m cell: a vehicle whose wheels
    stand 2 cm short of its foot is level, 5 cm further aside (3 cm onto it) it rolls 25
    deg or more (about 8 deg a centimetre; a drawn truth a centimetre off its prediction rolled over
    there, 2026-12-07). An edge along the wall that close fails on the margin with the
    default 10 cm aside, and passes with none; 10 cm further from the wall it passes."""
    base = api.load_world(ROOT / "scenarios" / "narrow_pass.yaml")
    aside = base.scenario.planner.margin_aside_m
    assert aside == 0.1
    X = WO.start_state(base)
    X[K.S_X], X[K.S_Y], X[K.S_YAW] = 14.8, 10.28, 0.0        # left wheels at 10.48: the wall's foot at 10.5
    assert PB.standing_tilt(base, X) == 0.0
    assert math.degrees(PB.standing_tilt(base, X, 0.05)) > 25.0
    X1 = X.copy()
    X1[K.S_Y] = 10.18
    assert math.degrees(PB.standing_tilt(base, X1, aside)) == 0.0

    def edge(world, X):
        Q, data = PB.pack_world(world, "time", margin=True)
        return SS.propagate(Q, data, WO._start(world, X), np.array((4.0, 4.0, 1.0)), np.zeros(SS.NX))
    assert edge(base, X) == -SS.MARGIN
    assert edge(api.load_world(ROOT / "scenarios" / "narrow_pass.yaml", margin_aside_m=0.0), X) > 0.0
    assert edge(base, X1) > 0.0


def test_beside_the_wall_a_search_keeps_the_clearance_it_has_and_a_drive_judges_the_pose():
    """A vehicle that drifted to 0.25 m from narrow_pass's pass centre line, towards its
    north wall, is level but has less clearance than the 10 cm allowance: a search from
    there keeps the allowance it has (from_inside shrinks it, to the millimetre) rather
    than raising the margin's limit to the tilt 10 cm aside (past the tip-over limit there,
    which let plans drive along the wall's foot): straight on along the wall passes,
    turning towards it fails. A plan made without the margin keeps the allowance against
    the tip-over limit; a drive (the truth's, the 1 kHz check's) judges the pose alone."""
    w = api.load_world(ROOT / "scenarios" / "narrow_pass.yaml")
    X = WO.start_state(w)
    X[K.S_X], X[K.S_Y], X[K.S_YAW] = 15.05, 10.25, 0.0       # just past the wall's crest
    Q, data = PB.pack_world(w, "time", margin=True)
    assert PB.standing_tilt(w, X) == 0.0 and PB.standing_tilt(w, X, 0.1) > Q[SS.Q_TIP]
    inside = PB.from_inside(Q, w, X)
    a = inside[SS.Q_ASIDE]
    assert inside[SS.Q_TIPM] == Q[SS.Q_TIPM] and 0.0 < a < 0.1
    assert PB.standing_tilt(w, X, a) <= Q[SS.Q_TIPM] < PB.standing_tilt(w, X, a + 0.002)

    def edge(Qx, dataX, world, control):
        return SS.propagate(Qx, dataX, WO._start(world, X), np.array(control, float), np.zeros(SS.NX))
    assert edge(inside, data, w, (4.0, 4.0, 1.0)) > 0.0                  # along the wall (lower on)
    assert edge(inside, data, w, (3.0, 4.0, 1.0)) == -SS.MARGIN          # turning towards it
    bare = WO.without_margin(w)
    Qb, datab = PB.pack_world(bare, "time", margin=True)                # the fallback's search
    assert Qb[SS.Q_TIPM] == Qb[SS.Q_TIP] and Qb[SS.Q_ASIDE] == 0.1
    assert edge(PB.from_inside(Qb, bare, X), datab, bare, (3.0, 4.0, 1.0)) == -SS.MARGIN
    Qd, datad = PB.pack_world(w, "time")                                 # a drive's
    assert Qd[SS.Q_ASIDE] == 0.0 and edge(Qd, datad, w, (3.0, 4.0, 1.0)) > 0.0


def test_a_horizon_planner_whose_scenario_starts_inside_the_margin_raises_it_for_that_start_alone():
    """The horizon planner's problem is a template for plans from other starts: a
    scenario that starts on the 27 deg flank raises the margin's limit for a plan from
    there, not for one from flatter ground later."""
    from sbmpc.planning.horizon import HorizonPlanner
    w, X = _flank(27.0)
    w = replace(w, scenario=replace(w.scenario, start=dict(w.scenario.start, y=float(X[K.S_Y]))))
    hp = HorizonPlanner.of(w, "time")
    assert math.degrees(hp.prob.params[SS.Q_TIPM]) == pytest.approx(25.0)
    assert math.degrees(hp._params(WO._start(w, X))[SS.Q_TIPM]) == pytest.approx(
        math.degrees(PB.standing_tilt(w, X)), abs=1e-6)
    assert math.degrees(hp._params(WO._start(w, _flank(20.0)[1]))[SS.Q_TIPM]) == pytest.approx(25.0)


def test_the_guard_lets_a_vehicle_inside_its_band_drive_a_period_no_steeper_than_where_it_stands():
    """At rest on a 28.5 deg flank heading a little up it, inside the guard's band (half the
    5 deg margin: 27.5 deg): holding the wheels at rest or backing down the flank is
    driven, driving on up it is
    held back (before, every period was, and the run stopped on the flank)."""
    w, X = _flank(28.5, yaw_deg=10.0)
    g = [EX.Executor(w, "time", tip_guard=True)]
    X = WO._start(w, X)
    assert EX.holder(g, X, (0.0, 0.0, 1.0), True) == 0
    assert EX.holder(g, X, (-3.0, -3.0, 1.0), True) == 0
    assert EX.holder(g, X, (3.0, 3.0, 1.0), True) == 1
    # the map's tilt off where it stands: the band's limit falls, where it stands does not
    assert EX.holder(g, X, (0.0, 0.0, 1.0), True, tilt_error=math.radians(1.5)) == 0


def test_the_guard_holds_back_a_period_after_which_braking_would_come_within_its_band():
    """At the top speed, heading 25 deg up a flank that steepens uphill: a half-second
    period at full speed ends 0.2 deg short of the guard's band (27.5 deg), but braking to
    rest after it runs on into the band: held back (a period held back is braked through,
    so the brake must stay safe after every period driven); braking now is driven."""
    w, X = _flank(20.0)
    v = w.vehicle
    top = v.v_max / v.torque_constant
    g = [EX.Executor(w, "time", tip_guard=True)]
    M = EX.Executor(w, "time").step(WO._start(w, X), (top, top, 3.0), record=False)[2]     # at speed
    M[K.S_X], M[K.S_Y], M[K.S_YAW] = 5.0, 11.0, math.radians(25.0)
    _, end, S = g[0].step(M, (top, top, 0.5), record=False)
    assert end == 0 and math.degrees(PB.standing_tilt(w, S)) < 27.5     # the period alone: clear of it
    assert EX.moving(S)
    assert EX.holder(g, M, (top, top, 0.5), True) == 1
    assert EX.holder(g, M, (0.0, 0.0, 0.5), True) == 0


# ---- the plan: fallback and report ---------------------------------------------------------------
def test_where_no_plan_keeps_the_margin_the_plan_rides_the_limit_and_says_so(ramp, tmp_path):
    """Up the 11.5 deg ramp no path keeps a 10 % margin (the twin stalls on the way):
    the plan is the one without it, its JSON says margin.kept false with a note, and it
    reaches the goal at 1 kHz; its recording marks where it runs closest to the limits."""
    w = _plane(11.5, size=(20.0, 12.0), margin=0.1, margin_turn=0.0, margin_tip_deg=0.0, max_expansions=4000)
    p = PL.plan(w, "time")
    assert p.found and p.check.reached
    assert p.margin["kept"] is False and "margin" in p.margin["note"]
    assert p.margin["invalid_edges_with_margin"][SS.CODES[SS.MARGIN - 1]] > 0
    from sbmpc import recording
    rrd = recording.write(tmp_path / "p.rrd", w.emap, {"time": p}, scenario=w.scenario, vehicle=w.vehicle)
    ents = recording.entities(rrd)
    assert ents.get("/margins/time/tip") == 1 and ents.get("/margins/time/drive") == 1
    d = json.loads(json.dumps(p.to_json()))
    from sbmpc.schemas import plan as plan_schema
    import jsonschema
    jsonschema.validate(d, plan_schema())


def test_the_report_reads_the_tip_margin_and_the_drive_at_its_limit():
    """A straight run at top speed along a 20 deg side slope: least tip-over margin 10 deg
    (30 - 20, within the map's bilinear rounding) and no drive headroom held 0.5 s (the
    voltage bound at top speed)."""
    w = _plane(0.0, 20.0, size=(40.0, 20.0), margin=0.0, margin_turn=0.0, margin_tip_deg=0.0)
    X = WO.start_state(replace(w, scenario=replace(w.scenario, start=dict(w.scenario.start, y=10.0))))
    top = w.vehicle.no_load_speed
    traj, end, _, _ = CK.replay(w, "time", [(top, top, 6.0)], start=X, dt=0.001)
    rep = report(w, traj)
    assert rep["tip"]["least_deg"] == pytest.approx(10.0, abs=0.3)
    assert rep["drive_headroom"]["least"] == pytest.approx(0.0, abs=1e-6)
    assert rep["turn_headroom"] is None


def test_robustness_counts_the_drawn_vehicles_that_stall():
    """The ramp's plan without margin, replayed by vehicles drawn with 10 % sd: some
    (the heavier) stall, and the shares are consistent."""
    w = _plane(11.5, size=(20.0, 12.0), margin=0.0, margin_turn=0.0, margin_tip_deg=0.0, max_expansions=4000)
    p = PL.plan(w, "time")
    r = robustness(w, "time", p.controls, 12, sd=0.10)
    assert r["samples"] == 12 and 0.0 < r["p_stall"] <= r["p_miss"] <= 1.0


# ---- settings -------------------------------------------------------------------------------------
def test_a_tip_margin_at_or_beyond_the_tip_limit_is_refused_with_the_key():
    from sbmpc.errors import InputError
    with pytest.raises(InputError, match="planner.margin_tip_deg: expected a margin below planner.tip_over_deg"):
        api.load_scenario({"name": "x", "map": {"heights": [[0, 0], [0, 0]], "resolution": 1.0}, "terrain": "grass",
                           "vehicle": "p3at", "start": {"x": 0.2, "y": 0.2}, "goal": {"x": 0.8, "y": 0.8},
                           "planner": {"tip_over_deg": 20, "margin_tip_deg": 20}})


# ---- the run's guard -----------------------------------------------------------------------
def test_the_guards_twin_and_the_run_after_a_stall_are_the_planners_twin():
    """The run's guard and, once the vehicle proves weaker, its planning model are the
    twin the search drives every edge with: mass, inertia, mu_sa and mu_op times
    1 + margin, packed to the same numbers; planned with no margin of its own, the
    tip-over margin only after the guard held a period back."""
    from dynamics.resistance import friction_table
    from sbmpc import receding as R
    w = _plane(5.0, margin=0.1, margin_turn=0.0, margin_tip_deg=5.0)
    tw = WO.pessimistic(w)
    assert tw.vehicle.mass == pytest.approx(1.1 * w.vehicle.mass)
    assert tw.vehicle.inertia == pytest.approx(1.1 * w.vehicle.inertia)
    for a, b in zip(tw.terrains, w.terrains):
        assert (a.mu_sa, a.mu_op) == pytest.approx((1.1 * b.mu_sa, 1.1 * b.mu_op))
    Q, data = PB.pack_world(w, "time", margin=True)
    block = np.concatenate([K.pack(tw.vehicle, tw.terrains[0]), friction_table(tw.vehicle, tw.terrains[0])])
    off = int(Q[SS.Q_OFFTW])
    assert np.array_equal(data[off:off + block.size], block)
    guards = R._guards(w, "time")
    assert [g.Q[SS.Q_TIPM] for g in guards] == pytest.approx([math.radians(27.5)] * 4)
    o = int(guards[1].Q[SS.Q_OFFT])           # the guard's twin drives as the vehicle of its own world
    assert np.array_equal(guards[1].data[o:o + block.size], block)
    # ... and an optimistic one, mass, inertia and grip divided by 1 + margin and the battery
    # voltage times it (a lighter or faster vehicle drives further into a period)
    light = K.pack(w.vehicle.replace(mass=w.vehicle.mass / 1.1, inertia=w.vehicle.inertia / 1.1,
                                     v_max=w.vehicle.v_max * 1.1),
                   w.terrains[0].replace(mu_sa=w.terrains[0].mu_sa / 1.1, mu_op=w.terrains[0].mu_op / 1.1))
    o = int(guards[2].Q[SS.Q_OFFT])
    assert np.allclose(guards[2].data[o:o + K.NP], light, rtol=1e-12)
    # ... and the fastest, for the map's edge alone: that one with the voltage times 1 + 3 margin
    fastest = K.pack(w.vehicle.replace(mass=w.vehicle.mass / 1.1, inertia=w.vehicle.inertia / 1.1,
                                       v_max=w.vehicle.v_max * 1.3),
                     w.terrains[0].replace(mu_sa=w.terrains[0].mu_sa / 1.1, mu_op=w.terrains[0].mu_op / 1.1))
    assert np.allclose(guards[3].data[o:o + K.NP], fastest, rtol=1e-12)
    ps = EX.twin_planner(w).scenario.planner
    assert (ps.margin, ps.margin_turn, ps.margin_tip_deg) == (0.0, 0.0, 0.0)
    assert EX.twin_planner(w, tip=True).scenario.planner.margin_tip_deg == 5.0
    assert EX.twin_planner(w).vehicle.mass == tw.vehicle.mass
    assert len(R._guards(_plane(5.0, margin=0.0, margin_tip_deg=5.0), "time")) == 1
    assert R._guards(_plane(5.0, margin=0.1, margin_tip_deg=0.0), "time") == []


class _Prediction:
    """A guard whose 1 kHz prediction of any period ends with ``end``."""

    world = None                     # (no map: the guard takes no floor)

    def __init__(self, end):
        self.end = end

    def step(self, X, control, record=False, tilt_error=0.0, floor=0.0):
        return None, self.end, X


@pytest.mark.parametrize("nominal, twin, kept, held", [
    (0, 0, True, False), (0, 0, False, False),
    (-SS.MARGIN, 0, True, True),          # a plan that keeps the margin: the planning vehicle within half of it
    (-SS.MARGIN, 0, False, False),        # a fallback plan rides within it by design
    (-SS.TIP, 0, False, True),            # ... but never into a tip-over
    (0, -SS.MARGIN, False, True),         # the twin within half of it: held, whatever the plan
    (0, -SS.MARGIN, True, True), (0, -SS.TIP, False, True),
    (-SS.STALL, -SS.STALL, False, False),  # a stall is the stall test's, not the guard's
])
def test_the_guard_holds_a_period_back_by_the_rule(nominal, twin, kept, held):
    from sbmpc import receding as R
    assert R._held([_Prediction(nominal), _Prediction(twin)], np.zeros(SS.NX), (1.0, 1.0, 1.0), kept) is held


def test_a_plan_that_keeps_the_margin_ranks_before_a_cheaper_one_that_does_not():
    """The cross-check of an energy plan against the time plan (and compare's both ways):
    where the energy search found no plan that keeps the margin and fell back to one at the
    nominal vehicle's limit, the time plan that keeps it is the plan, though it uses more
    energy (hills_field: 4 013 J with the margin against 3 275 J without); between two
    that keep it, or two that do not, the cheaper one."""
    def made(cost, energy, seconds, kept):
        traj = {"t": np.array([0.0, seconds]), "energy_J": np.array([0.0, energy]),
                "x": np.array([0.0, 10.0]), "y": np.array([0.0, 0.0])}
        return PL.Plan("s", cost, "found", None, [(1.0, 1.0, seconds)], traj, margin={"kept": kept})
    bare = made("energy", 3275.0, 98.7, False)
    fast = made("time", 4013.0, 97.5, True)
    out = PL.cross_checked(bare, fast)
    assert out.energy_J == 4013.0 and out.cost == "energy" and out.found_by.startswith("time search")
    assert "margin" in out.found_by
    # the other way round: the energy plan keeps it, the time plan does not
    assert PL.cross_checked(made("energy", 3500.0, 99.0, True), made("time", 3400.0, 97.0, False)).energy_J == 3500.0
    # both keep it (or neither does): the cheaper on the plan's own cost
    assert PL.cross_checked(made("energy", 3500.0, 99.0, True), made("time", 3400.0, 97.0, True)).energy_J == 3400.0
    assert PL.cross_checked(made("energy", 3500.0, 99.0, False), made("time", 3400.0, 97.0, False)).energy_J == 3400.0


def _energy_fails_on_the_margin(monkeypatch) -> list:
    """Every energy search with the margin finds nothing, its edges having failed on the
    margin (as hills_field's does in its budget); other searches run as they are. Returns
    the (cost, planner.margin) of every search made, in order."""
    real = PL._search_plan
    calls = []

    def fake(world, cost=None, *a, **k):
        calls.append((cost, world.scenario.planner.margin))
        if cost == "energy" and world.scenario.planner.margin > 0:
            return PL.Plan(world.scenario.name, cost, "no_path", "node budget of 10 expansions used up (the test's)",
                           failure="node_budget", invalid_edges={SS.CODES[SS.MARGIN - 1]: 5})
        return real(world, cost, *a, **k)
    monkeypatch.setattr(PL, "_search_plan", fake)
    return calls


def test_an_energy_plan_searches_again_without_the_margin_only_where_the_time_plan_does_not_keep_it(monkeypatch):
    """The energy search finds no plan that keeps the margin (its edges failed on it): where
    the time plan keeps it, that is the plan (cross_checked would not take one without the
    margin), so the energy search does not run a second time without it; where the time
    plan does not keep it either, it does, and the cheaper plan without it is the plan."""
    calls = _energy_fails_on_the_margin(monkeypatch)
    flat = _plane(0.0, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0)
    p = PL.plan(flat, "energy")
    assert calls == [("time", 0.1), ("energy", 0.1)]
    assert p.found and p.margin["kept"] and p.found_by.startswith("time search")
    assert "the test's" in p.found_by and "no plan it found keeps the planner's margin" in p.found_by
    # on the 11.5 deg ramp the time plan does not keep the margin either: the energy
    # search runs again without it
    calls.clear()
    w = _plane(11.5, size=(20.0, 12.0), margin=0.1, margin_turn=0.0, margin_tip_deg=0.0, max_expansions=4000)
    q = PL.plan(w, "energy")
    assert calls[:2] == [("time", 0.1), ("time", 0.0)] and ("energy", 0.0) in calls
    assert q.found and q.margin["kept"] is False


def test_where_the_time_plan_does_not_hold_at_1_khz_the_energy_search_searches_again_without_the_margin(monkeypatch):
    """The time plan kept the margin at its search's step, so the energy search (which
    found no plan that keeps it) did not search again without it; checked at 1 kHz after
    the energy search, the time plan does not hold: the energy plan without the margin is
    the one left, and it is made then (rather than no plan at all)."""
    real_check = PL._checked_plan
    calls = _energy_fails_on_the_margin(monkeypatch)

    def time_fails(w, cost, *a, **k):
        q = real_check(w, cost, *a, **k)
        return replace(q, status="no_path", reason="does not hold at 1 kHz (the test's)",
                       failure="controller_rate") if cost == "time" else q
    monkeypatch.setattr(PL, "_checked_plan", time_fails)
    p = PL.plan(_plane(0.0, margin=0.1, margin_turn=0.0, margin_tip_deg=0.0), "energy")
    assert calls == [("time", 0.1), ("energy", 0.1), ("energy", 0.0)]
    assert p.found and p.cost == "energy" and p.found_by == "" and p.margin["kept"] is False
    assert "the test's" in p.margin["note"] and p.rival["status"] == "no_path"


def _descent(at_deg, speed=0.8):
    """A world on a descent that steepens downhill (heights -c y^2: heading +y the grade
    grows), and a state heading down it at ``speed`` x the top wheel speed where its
    grade is ``at_deg``."""
    res, c = 0.25, 0.0255
    x, y = np.arange(0.0, 30.0 + res / 2, res), np.arange(0.0, 20.0 + res / 2, res)
    H = np.repeat((-c * y * y)[:, None], x.size, axis=1)
    scn = {"name": "descent", "map": {"heights": [[0.0, 0.0], [0.0, 0.0]], "resolution": 1.0},
           "terrain": "grass", "vehicle": "p3at", "start": {"x": 15.0, "y": 2.0, "yaw_deg": 90.0, "v": 0.0},
           "goal": {"x": 15.0, "y": 19.0, "radius": 1.0}, "cost": "time"}
    w = api.load_world(scn, heights=H, resolution=res, margin=0.0, margin_turn=0.0, margin_tip_deg=5.0)
    y0 = math.tan(math.radians(at_deg)) / (2.0 * c)
    X = WO._start(w, WO.start_state(replace(w, scenario=replace(w.scenario, start=dict(w.scenario.start, y=y0)))))
    top = w.vehicle.v_max / w.vehicle.torque_constant
    X[K.S_WL] = X[K.S_WR] = X[K.S_REFL] = X[K.S_REFR] = speed * top
    return w, X, top


def test_a_vehicle_that_cannot_brake_out_of_the_band_drives_a_period_no_steeper_than_braking():
    """Heading down a descent 0.5 deg past the steepest grade its drive brakes on grass
    (22.5 deg), at speed, where it steepens: braking to rest (the wheels commanded to
    rest, the drive at its current limit) runs on into the guard's band, so holding a
    period back is no safer than driving one. A period that goes no steeper than braking
    (slowing to 2 rad/s, or to half speed: the same saturated drive) is driven; full speed
    down, or a turn, goes steeper and is held back. Before, every period was held, the
    vehicle braked into the steeper ground and the run stopped it rolling (a drawn
    `hills_field` horizon truth, 2026-12-07)."""
    from dynamics.limits import steepest_braked_grade
    w, X, top = _descent(23.0)
    assert math.degrees(steepest_braked_grade(w.vehicle, w.terrains[0], 0.8 * top)) == pytest.approx(-22.5, abs=0.1)
    g = [EX.Executor(w, "time", tip_guard=True)]
    brake = (0.0, 0.0, 1.0)
    assert EX.holder(g, X, brake, True) == 1                     # braking itself comes into the band
    floor = EX.braking_floor(g, X)
    assert 27.5 < math.degrees(floor) < 30.0
    for slower in ((2.0, 2.0, 1.0), (0.5 * top, 0.5 * top, 1.0)):
        assert EX._holder(g, X, slower, True) == 1 and EX.holder(g, X, slower, True) == 0
    for steeper in ((top, top, 1.0), (0.3 * top, 0.8 * top, 1.0)):
        assert EX.holder(g, X, steeper, True) == 1
    # 1.5 deg gentler the drive brakes it: nothing changes there
    w, X, top = _descent(21.0)
    g = [EX.Executor(w, "time", tip_guard=True)]
    assert EX.braking_floor(g, X) is None and EX.holder(g, X, brake, True) == 0
    # and a vehicle at rest has no brake to compare with: the band alone
    w, X, top = _descent(24.0, speed=0.0)
    g = [EX.Executor(w, "time", tip_guard=True)]
    assert EX.holder(g, X, (0.5 * top, 0.5 * top, 1.0), True) == EX._holder(g, X, (0.5 * top, 0.5 * top, 1.0), True)


def test_a_run_that_stops_a_moving_vehicle_follows_it_braking_to_rest():
    """The simulated truth of a stopped controller (its command: the wheels at rest) is
    followed until it comes to rest: on a 15 deg descent, which its drive brakes, from
    speed it stops within half a metre and the recorded rows end at rest; past the
    steepest braked grade, steepening, it runs away and the run's end is that it tipped
    over, never a 'stopped' with the vehicle still moving (receding._at_rest, which the
    finish of whole-route and horizon runs calls); a run out of its wall clock ends as it
    was."""
    from sbmpc import receding, truth as TT
    w = _plane(15.0, size=(40.0, 12.0))
    X = WO._start(w, WO.start_state(replace(w, scenario=replace(
        w.scenario, start=dict(w.scenario.start, x=30.0, yaw_deg=180.0)))))
    X[K.S_WL] = X[K.S_WR] = X[K.S_REFL] = X[K.S_REFR] = 8.0
    real = EX.Executor(w, "time", 0.05)
    pieces = []
    S, end = receding._to_rest(real, X, TT.Dropper(0.0, np.random.default_rng(0)), 0.1, pieces)
    assert end == 0 and not EX.moving(S) and pieces and 0.1 < X[K.S_X] - S[K.S_X] < 5.0
    assert "came to rest" in receding._rolled(X, S)
    w, X, top = _descent(26.0)
    pieces = []
    S, status, reason, end = receding._at_rest(EX.Executor(w, "time"), X, TT.Dropper(0.0, np.random.default_rng(0)),
                                               0.1, pieces, "failed", "stopped at (15.00, 9.56): ...", "stopped")
    assert (status, end) == ("failed", "tipped") and S[K.S_Y] > X[K.S_Y] + 0.5
    assert reason.startswith("the vehicle tipped over") and reason.endswith("after the run ended: stopped at (15.00, 9.56): ...")
    same = receding._at_rest(EX.Executor(w, "time"), X, TT.Dropper(0.0, np.random.default_rng(0)), 0.1, [],
                             "failed", "wall-clock limit reached", "timeout")
    assert same[1:] == ("failed", "wall-clock limit reached", "timeout") and same[0] is X


def test_a_held_period_is_driven_in_part_where_braking_a_whole_period_after_the_part_is_safe():
    """From rest at the top of a descent that steepens (24 and 26 deg where it stands, 27.5
    deg 1-3 m on): a full-speed period of 1 s and braking after it run into the guard's
    band; half of it, or a quarter rounded down to 0.2 s, with a whole second of braking after it, does not:
    the controller drives that part and plans again from where it is (it creeps up to
    the band instead of stopping short of it). The brake judged is the whole period's:
    half a period braked for half a period passes where braking to rest does not. Where
    the robot's control period is half the plan's, or the map is 1.5 deg steeper than
    it says, nothing shorter passes."""
    w, X, top = _descent(24.0, speed=0.0)
    g = [EX.Executor(w, "time", tip_guard=True)]
    full = (top, top, 1.0)
    assert EX.holder(g, X, full, True) == 1
    assert EX.shortened(g, X, full, True, 0.0, 0.1) == (top, top, 0.5)
    w, X, top = _descent(26.0, speed=0.0)
    g = [EX.Executor(w, "time", tip_guard=True)]
    assert EX.holder(g, X, (top, top, 0.5), True) == 0 and EX.holder(g, X, (top, top, 0.5), True, brake_s=1.0) == 1
    part = EX.shortened(g, X, full, True, 0.0, 0.1)
    assert part[:2] == (top, top) and part[2] == pytest.approx(0.2)
    assert EX.shortened(g, X, full, True, 0.0, 0.5) is None
    assert EX.shortened(g, X, full, True, math.radians(1.5), 0.1) is None
