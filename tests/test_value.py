"""The value over position and heading (sbmpc.planning.value): what the vehicle's own
steady motions cost, its symmetries and limits, its cache, and what the searches make of it."""
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sbmpc
from dynamics import kernels as K
from dynamics.limits import steepest_grade
from sbmpc.planning import motions as MO, problem as PB, value as VA, world as WO
from sbmpc.planning.heuristics import climb_limit
from sbmpc.problems import skidsteer as SS


def _world(heights, res=0.25, start=(2.0, 5.0, 0.0), goal=(18.0, 5.0), terrain="asphalt", **planner):
    ny, nx = heights.shape
    scn = {"name": "value", "terrain": terrain,
           "start": {"x": start[0], "y": start[1], "yaw_deg": start[2]},
           "goal": {"x": goal[0], "y": goal[1], "radius": 0.5}}
    return sbmpc.load_world(scn, heights, res, **planner)


@pytest.fixture(scope="module")
def flat():
    return _world(np.zeros((41, 81)))


def test_tables_physics_on_the_level(flat):
    """Steady straight driving: the speed is the commanded wheel speed times the radius
    (the PID holds it on the level), the power grows with the speed, and climbing costs
    more per metre than the level, which costs more than a descent."""
    tb = MO.tables(flat)
    g = tb["grades"]
    lvl = int(np.argmin(np.abs(g)))
    r = flat.vehicle.wheel_radius
    for c in np.flatnonzero(tb["kinds"] == MO.STRAIGHT):
        v = tb["v"][0, lvl, c]
        assert v == pytest.approx(r * tb["cmds"][c, 0], rel=0.08)
        assert tb["ok"][0, lvl, c] and tb["ok_twin"][0, lvl, c]
    mc = MO.motion_costs(flat, "energy", np.array([1.0]), np.array([0.4]))
    e = mc["straight"][0]
    up, down = int(np.searchsorted(g, math.radians(8))), int(np.searchsorted(g, math.radians(-8)))
    assert e[up] > e[lvl] > e[down] >= 0.0


def test_tables_close_what_the_drive_cannot_climb(flat):
    """No straight climb is held beyond the drive's steepest grade (dynamics.limits:
    eqs. 24-27 at constant speed), and the value's straight motions open at most
    RUNUP_DEG past it."""
    tb = MO.tables(flat)
    g = tb["grades"]
    steep = steepest_grade(flat.vehicle, flat.terrains[0])
    held = tb["ok"][0][:, tb["kinds"] == MO.STRAIGHT].any(axis=1)
    assert not held[g > steep + math.radians(MO.GRADE_STEP)].any()
    assert held[(g >= 0) & (g < steep - math.radians(2))].all()
    mc = MO.motion_costs(flat, "time", np.array([1.0]), np.array([0.4]))
    open_ = np.isfinite(mc["straight"][0])
    assert not open_[g > steep + math.radians(MO.RUNUP_DEG + MO.GRADE_STEP)].any()


def test_value_on_the_level_is_distance_over_the_steady_speed(flat):
    """Facing the goal on level ground, V for time is the distance to the disc over the
    best steady speed, within the lattice's step (0.5 m) and no detour (the goal lies on
    a lattice heading); facing away it costs more by at least the turn, and the start's
    value reads the same from any nearby heading on both sides (symmetry)."""
    val = VA.build(flat, "time")
    mc = MO.motion_costs(flat, "time", np.array([1.0]), np.array([0.4]))
    lvl = int(np.argmin(np.abs(MO.grades())))
    per_m = mc["straight"][0, lvl]
    d = 16.0 - 0.5
    v0 = val.at(2.0, 5.0, 0.0)
    assert d * per_m - 0.5 * per_m <= v0 <= (d + 0.5) * per_m
    assert val.at(2.0, 5.0, math.pi) > v0 + 1.0
    for a in (0.2, 0.7, 1.5, 2.5):
        assert val.at(2.0, 5.0, a) == pytest.approx(val.at(2.0, 5.0, -a), rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(x=st.floats(3.0, 17.0), dy=st.floats(0.0, 3.5), yaw=st.floats(-math.pi, math.pi))
def test_value_mirror_symmetry(flat, x, dy, yaw):
    """The level map and the goal are symmetric about y = 5, and so are the lattice's
    headings and the vehicle's turns: V(x, 5 + dy, yaw) = V(x, 5 - dy, -yaw)."""
    val = _cached_value(flat)
    a = val.at(x, 5.0 + dy, yaw)
    b = val.at(x, 5.0 - dy, -yaw)
    assert a == pytest.approx(b, rel=1e-9)


_VALS = {}


def _cached_value(world):
    key = id(world)
    if key not in _VALS:
        _VALS[key] = VA.build(world, "time")
    return _VALS[key]


def test_a_ramp_too_steep_for_the_drive_is_closed():
    """A ramp up to a plateau holding the goal, in a lane 2 m wide between cliffs: at
    10 deg the value climbs it; at a grade past the drive's steepest plus the run-up
    (short of tipping over) V is infinite at the start, as no motion of the vehicle gets
    up it. Without the cliffs the value climbs it in switchbacks, across the grade:
    finite, and dearer than the 10 deg ramp straight up."""
    res, nx, ny = 0.25, 81, 41
    x = np.arange(nx) * res
    y = np.arange(ny) * res
    w0 = _world(np.zeros((ny, nx)))
    steep = math.degrees(climb_limit(w0)) + 3.0
    lane = np.where(np.abs(y - 5.0) > 1.0, 4.0, 0.0)[:, None]
    got = {}
    for deg in (10.0, steep):
        z = np.clip((x - 8.0) * math.tan(math.radians(deg)), 0.0, 2.0)[None, :]
        for walls in (True, False):
            H = z + (lane if walls else 0.0) + np.zeros((ny, 1))
            w = _world(H, margin_tip_deg=0.0, tip_over_deg=45.0)
            got[deg, walls] = VA.build(w, "time").at(2.0, 5.0, 0.0)
    assert math.isfinite(got[10.0, True]) and math.isinf(got[steep, True])
    assert got[10.0, True] == pytest.approx(got[10.0, False], rel=0.02)
    assert math.isfinite(got[steep, False]) and got[steep, False] > 1.2 * got[10.0, False]


def test_energy_value_counts_the_climb():
    """Energy over a 1 m hill straight between start and goal: at least the potential
    energy m g h (no regeneration) on top of the level's rolling, and the value from
    the far side (the descent first) is the smaller by about that climb."""
    res, nx, ny = 0.25, 81, 41
    x = np.arange(nx) * res
    z = 1.0 * np.exp(-((x - 10.0) / 2.5) ** 2)
    H = np.tile(z, (ny, 1))
    hill = _world(H)
    level = _world(np.zeros((ny, nx)))
    e_hill = VA.build(hill, "energy").at(2.0, 5.0, 0.0)
    e_level = VA.build(level, "energy").at(2.0, 5.0, 0.0)
    mgh = hill.vehicle.mass * 9.81 * 1.0
    assert e_hill >= e_level + 0.9 * mgh


def test_disk_cache_reads_the_same(tmp_path, monkeypatch, flat):
    """A value is written to the disk cache by content and read back the same; another
    goal is another file."""
    monkeypatch.setenv("SBMPC_CACHE_DIR", str(tmp_path))
    VA.value.cache_clear()
    a = VA.value(flat, "time")
    assert not a.cached and len(list(tmp_path.glob("value-*.npy"))) == 1
    VA.value.cache_clear()
    b = VA.value(flat, "time")
    assert b.cached and np.array_equal(a.V, b.V, equal_nan=True)
    other = _world(np.zeros((41, 81)), goal=(18.0, 8.0))
    VA.value(other, "time")
    assert len(list(tmp_path.glob("value-*.npy"))) == 2
    VA.value.cache_clear()


def test_the_search_heuristic_is_the_value_clamped_by_the_anchor(flat):
    """Whole-route searches read max(grid, min(V, w2 grid)); with the value off the grid
    alone; a horizon search reads max(grid, V) (its terminal cost)."""
    X = WO.start_state(flat)
    Q, data = PB.pack_world(flat, "time", margin=True)
    off = replace(flat, scenario=replace(flat.scenario, planner=replace(flat.scenario.planner, value=False)))
    Q0, data0 = PB.pack_world(off, "time", margin=True)
    assert Q0[SS.Q_OFFV] == -1 and Q[SS.Q_OFFV] >= 0
    gap = Q[SS.Q_GOALGAP]
    anchor = SS.heuristic(Q0, data0, X) + gap
    v = VA.value(flat, "time").at(X[K.S_X], X[K.S_Y], X[K.S_YAW])
    h = SS.heuristic(Q, data, X) + gap
    assert h == pytest.approx(max(anchor, min(v, Q[SS.Q_VW2] * anchor)), rel=1e-9)
    Q1 = Q.copy()
    Q1[SS.Q_VW2] = 1.0
    assert SS.heuristic(Q1, data, X) + gap == pytest.approx(anchor, rel=1e-9)
    Qh = Q.copy()
    Qh[SS.Q_HORIZON] = 10.0
    assert SS.heuristic(Qh, data, X) + gap == pytest.approx(max(anchor, v), rel=1e-9)


def test_value_close_to_the_plan_driven_at_1khz():
    """The value is an estimate, not a bound: on steep_hill its start reads within 15 %
    of the time and energy the time and energy plans use when driven at 1 kHz."""
    from pathlib import Path
    scn = Path(__file__).resolve().parents[1] / "scenarios" / "steep_hill.yaml"
    world = sbmpc.load_world(scn)
    X = WO.start_state(world)
    for cost in ("time", "energy"):
        plan = sbmpc.plan_scenario(scn, cost, threads=1)
        assert plan.found
        got = plan.travel_time_s if cost == "time" else plan.energy_J
        v = VA.value(world, cost).at(X[K.S_X], X[K.S_Y], X[K.S_YAW])
        assert abs(v - got) <= 0.15 * got, (cost, v, got)


def test_a_goal_whose_lattice_states_are_all_closed_gives_no_value_and_no_crash():
    """A plane tilted 27 deg, with the tip-over limit less its margin at 15 deg (45 and 30):
    at every heading the pitch or the roll is at least 19.8 deg, so every lattice state
    (the goal's too) is closed. The Dijkstra starts from
    closed goal states (value 0), reads no motion from them (their grade is nan: before,
    a pivot read the table at int(nan), far outside it), and V is infinite everywhere
    else: the search reads the admissible grid alone there."""
    res, nx, ny = 0.25, 61, 41
    y = np.arange(ny) * res
    H = np.tile((math.tan(math.radians(27.0)) * y)[:, None], (1, nx))
    w = _world(H, start=(2.0, 5.0, 0.0), goal=(12.0, 5.0), tip_over_deg=45.0, margin_tip_deg=30.0)
    val = VA.build(w, "time")
    finite = np.isfinite(val.V)
    assert np.all(val.V[finite] == 0.0) and 0 < finite.sum() <= 9 * 16     # the disc's lattice points
    assert math.isinf(val.at(2.0, 5.0, 0.0))


def test_tables_are_shared_by_worlds_of_the_same_vehicle_and_settings(flat):
    """The motion tables depend on the vehicle, terrains, margin settings, wheel speeds
    and step, not on the map: another world (another map and goal) with the same ones
    gets the very same tables; a heavier vehicle gets its own."""
    other = _world(np.zeros((33, 41)), goal=(8.0, 3.0))
    assert MO.tables(other) is MO.tables(flat)
    heavy = replace(flat, vehicle=WO.heavier(flat.vehicle, 1.2))
    assert MO.tables(heavy) is not MO.tables(flat)


def test_each_cost_clamps_the_value_by_its_own_w2(flat):
    """planner.value_w2 bounds the time searches' heuristic, value_energy_w2 the energy
    searches'."""
    Qt, _ = PB.pack_world(flat, "time", margin=True)
    Qe, _ = PB.pack_world(flat, "energy", margin=True)
    ps = flat.scenario.planner
    assert (Qt[SS.Q_VW2], Qe[SS.Q_VW2]) == (ps.value_w2, ps.value_energy_w2) and ps.value_w2 != ps.value_energy_w2


def test_where_the_value_is_infinite_the_horizon_adds_the_grids_turn_cost(flat):
    """Off the value's lattice (V infinite) a horizon's terminal cost is the grid plus the
    turn cost per radian of heading error, as with the value off."""
    X = WO.start_state(flat)
    X[K.S_YAW] = math.pi                      # facing away from the goal
    Q, data = PB.pack_world(flat, "time", margin=True)
    off = replace(flat, scenario=replace(flat.scenario, planner=replace(flat.scenario.planner, value=False)))
    Q0, data0 = PB.pack_world(off, "time", margin=True)
    blind = data.copy()
    n = int(Q[SS.Q_VNX] * Q[SS.Q_VNY] * 16)
    blind[int(Q[SS.Q_OFFV]):int(Q[SS.Q_OFFV]) + n] = np.inf
    for q in (Q, Q0):
        q[SS.Q_HORIZON] = 10.0
        q[SS.Q_TURNCOST] = 2.0
    assert SS.heuristic(Q, blind, X) == pytest.approx(SS.heuristic(Q0, data0, X), rel=1e-12)
    assert SS.heuristic(Q, blind, X) > SS.heuristic(_with_turn_cost(Q0, 0.0), data0, X) + 5.0


def _with_turn_cost(Q, k):
    Q = Q.copy()
    Q[SS.Q_TURNCOST] = k
    return Q


def test_a_state_beside_a_wall_is_closed_by_the_margins_allowance_aside():
    """The value closes a lattice state as the search's edges judge the margin, with
    the vehicle ``margin_aside_m`` to either side (maps.grid.aside_tilts): heading along
    a wall that climbs 1 m in one 0.25 m cell, with its left wheels 5 cm short of the
    foot, the footprint stands level but 10 cm to its left it rolls 27 deg (past 30 - 5):
    closed with the allowance, open without; heading at the wall (the allowance moves it
    along the foot) open either way. On a plane the allowance closes nothing."""
    w = _world(np.zeros((41, 81)))
    hl, hw = w.half_length, w.half_width
    res = 0.25
    y = np.arange(41) * res
    wall = np.clip((y - 5.0) / res, 0.0, 1.0)[:, None] * np.ones((1, 81))
    tan_tip = math.tan(math.radians(25.0))
    y0 = 5.0 - hw - 0.05

    def grades(H, aside, y_at=y0):
        G, _, _ = VA._states(H, res, 0.0, 0.0, hl, hw, tan_tip, aside, 0.5, 4.0, y_at, 1, 1, 0.5, np.zeros(0, np.int64))
        return G[0, 0]

    along = int(np.argmin(np.abs(np.array(VA.ANGLES_T)))), int(np.argmin(np.abs(np.array(VA.ANGLES_T) - math.pi)))
    across = int(np.argmin(np.abs(np.array(VA.ANGLES_T) - math.pi / 2)))
    without, with_ = grades(wall, 0.0), grades(wall, 0.1)
    for k in along:
        assert np.isfinite(without[k]) and np.isnan(with_[k])
    assert np.isfinite(without[across]) and np.isfinite(with_[across])
    plane = (np.arange(81) * res * math.tan(math.radians(12.0)))[None, :] + 0.02 * y[:, None]
    np.testing.assert_array_equal(grades(plane, 0.0, 5.0), grades(plane, 0.1, 5.0))
    assert np.isfinite(grades(plane, 0.1, 5.0)).all()
    # the value is kept by content: another allowance is another value
    keys = {VA._content_key(_world(np.zeros((41, 81)), margin_aside_m=a), "time", 0.5) for a in (0.0, 0.1)}
    assert len(keys) == 2
