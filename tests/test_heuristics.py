"""The cost-to-go grid: a lower bound of the cost to the goal, also when a large map
gets only a window of it."""
import functools
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sbmpc import scenario as SC

from sbmpc.planning import heuristics as HE, world as WO

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("name", ["hills_field", "steep_hill"])
@pytest.mark.parametrize("cost", ["time", "energy"])
def test_a_window_stays_below_the_whole_maps_grid(name, cost):
    """With the window forced small, every value inside it is at most the whole map's
    (paths leaving the window are counted at the straight-line bound, never more), and
    outside it the grid gives 0 (the straight-line bound takes over)."""
    scn = SC.load(SCEN / f"{name}.yaml")
    world = WO.resolve(scn)
    full, *_ = HE.cost_to_go.__wrapped__(world, cost)
    cells = full.size // 4
    j0, j1, i0, i1 = HE.ctg_window(world, cells)      # as small as the start-goal box allows
    assert (j1 - j0) * (i1 - i0) < 0.8 * full.size
    win, *_ = HE.cost_to_go.__wrapped__(world, cost, cells)
    inside = win[j0:j1, i0:i1]
    reach = full[j0:j1, i0:i1] < 1e11
    assert np.all(inside[reach] <= full[j0:j1, i0:i1][reach] + 1e-6)
    mask = np.ones(full.shape, bool)
    mask[j0:j1, i0:i1] = False
    assert np.all(win[mask] == 0.0)


@pytest.mark.slow      # a 4 M-cell map end to end (7 s); the window itself is tested above
def test_a_large_map_plans_with_a_window(tmp_path):
    """A 2000 x 2000 map (4 M cells) with an 8 m plan: the cost-to-go covers a window."""
    H = np.zeros((2000, 2000))
    np.save(tmp_path / "big.npy", H)
    import sbmpc
    scn = {"name": "big", "map": {"file": str(tmp_path / "big.npy"), "resolution": 0.25},
           "terrain": "asphalt", "start": {"x": 200.0, "y": 200.0}, "goal": {"x": 206.0, "y": 205.0, "radius": 0.5}}
    world = sbmpc.load_world(scn)
    j0, j1, i0, i1 = HE.ctg_window(world)
    assert (j1 - j0) * (i1 - i0) < 0.05 * H.size
    plan = sbmpc.plan_scenario(scn)
    assert plan.found


# ---- the energy step bound (least_step_energy) ----------------------------------------

from hypothesis import example, given, settings
from hypothesis import strategies as st

from dynamics.limits import steepest_grade
from dynamics.params import G
from dynamics.simulate import Model, hold, simulate


@pytest.mark.parametrize("name", ["steep_hill", "narrow_pass"])      # packed dirt, asphalt
def test_the_energy_step_bound_is_the_steady_climbs_draw_from_below(name):
    """A steady straight drive at the top command up constant grades, at 1 kHz: its
    battery energy per metre is at least the step bound's, and the bound stays within 6 %
    of it (the copper loss is what the old rolling-plus-climb bound left out: 4 % on the
    level, 11-12 % at half and 18-20 % near the steepest grade the drive holds)."""
    world = WO.resolve(SC.load(SCEN / f"{name}.yaml"))
    v, t = world.vehicle, world.terrains[0]
    c = HE.copper_coefficient(world)
    m = Model(v, t)
    _, hi = HE.wheel_speed_range(world)
    top = math.degrees(steepest_grade(v, t))
    for deg, share in ((0.0, 0.025), (0.5 * top, 0.08), (top - 0.5, 0.15)):
        th = math.radians(deg)
        tr = simulate(m, hold(hi, 5, 1e-3), hold(hi, 5, 1e-3), state=m.state(hi, hi, th), pitch=th, dt=1e-3)
        k = tr.data["t"] >= 2.0
        ds = tr.data["s"][k][-1] - tr.data["s"][k][0]
        drawn = tr.data["energy_J"][k][-1] - tr.data["energy_J"][k][0]
        rise = v.mass * G * ds * math.sin(th)
        froll = t.mu_roll * v.mass * G * math.cos(th)
        bound = float(HE.least_step_energy(froll, rise, ds * math.cos(th), c))
        linear = froll * ds * math.cos(th) + rise
        assert 0.94 * drawn <= bound <= drawn
        assert bound >= linear * (1.0 + share)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 200.0), st.floats(-500.0, 500.0), st.floats(0.01, 2.0), st.floats(1e-4, 0.05))
def test_the_energy_step_bound_is_never_below_the_linear_one(f, rise, d, c):
    """Never below max(0, rolling + climb) (copper loss is never negative), 0 where the
    step's descent pays for its rolling, and growing with the climb."""
    e = float(HE.least_step_energy(f, rise, d, c))
    lin = max(0.0, f * d + rise)
    assert e >= lin - 1e-9 * (1.0 + abs(lin))
    if f * d + rise <= 0.0:
        assert e == 0.0
    assert float(HE.least_step_energy(f, rise + 1.0, d, c)) >= e


@settings(max_examples=200, deadline=None)
@given(st.floats(1.0, 200.0), st.floats(-100.0, 500.0), st.floats(0.05, 2.0), st.floats(1e-4, 0.05))
@example(67.0, -25.0, 0.375, 0.03125)
def test_the_energy_step_bound_is_the_minimum_over_the_rolled_distance(f, rise, d, c):
    """The closed form equals a brute-force minimum of 2 (W + c W^2 / L), W = f L / 2 +
    rise / 2, over rolled distances L >= d (where there is work to do), and its slope in
    the work is at most the KE factor (the heuristic's credit per joule of KE)."""
    if f * d + rise <= 0.0:
        return
    L = d * np.concatenate([np.linspace(1.0, 2.0, 2001), np.geomspace(2.0, 1e5, 4001)])
    W = 0.5 * f * L + 0.5 * rise
    brute = np.min(2.0 * (W + c * W * W / L))
    e = float(HE.least_step_energy(f, rise, d, c))
    assert e <= brute * (1.0 + 1e-9) + 1e-9
    assert e >= brute * (1.0 - 1e-4) - 1e-6
    q = HE.ke_factor(f, rise, d, c)
    # (a secant short against the work to do, f d + rise: the bound is convex in it, and
    # a long secant overshoots the slope where there is little work, 1.0115 against 1.0104
    # at f 67, rise -25, d 0.375, c 1/32)
    h = 1e-3 * min(1.0 + abs(rise), f * d + rise)
    slope = (float(HE.least_step_energy(f, rise + h, d, c)) - e) / h
    assert 1.0 <= slope <= q * (1.0 + 1e-3) + 1e-6


def test_the_ke_credit_covers_the_steepest_grid_step():
    """On steep_hill the grid keeps run-up steps steeper than the drive holds: the KE
    factor is the slope there (above the 1.41 that the current limit alone gives), so
    the credit never exceeds what KE can save of a step's bound."""
    world = WO.resolve(SC.load(SCEN / "steep_hill.yaml"))
    _, _, q, _ = HE.cost_to_go.__wrapped__(world, "energy")
    v = world.vehicle
    at_limit = 1.0 + 2.0 * HE.copper_coefficient(world) * v.torque_constant * v.current_limit / v.wheel_radius
    assert q > at_limit > 1.3
    assert HE.cost_to_go.__wrapped__(world, "time")[2] == 1.0


@pytest.mark.slow
@pytest.mark.parametrize("name, cost, seen", [("hill_tradeoff", "energy", 0.7), ("runup_ramp", "energy", 0.7),
                                             ("hill_tradeoff", "time", 0.8), ("mixed_terrain", "time", 0.85),
                                             ("steep_hill", "time", 0.7)])
def test_the_heuristic_never_exceeds_what_the_found_path_still_costs(name, cost, seen):
    """Along the search's own path (its states at the planner's step), the heuristic at
    every node is at most what the path still costs to the goal, and at the start at
    least ``seen`` of it: it is informative. For time the grid's steps take the steady
    top speed of their terrain and grade (mixed_terrain's rough field 0.85 m/s, its road
    0.91 m/s) where they took the commanded top wheel speed (1.00 m/s with its margin),
    which left 20 % of mixed_terrain's time plan unseen (86 % seen now)."""
    from sbmpc.planning import problem as PB
    from sbmpc.problems import skidsteer as SS
    from sbmpc.search.astar import Search
    from dynamics import kernels as K
    scn = SC.load(SCEN / f"{name}.yaml")
    for margin in (scn.planner.margin, 0.0):
        # admissible with the default margin too; informative (``seen``) as measured, without
        # it (the twin's longer run-ups and detours are what no position bound sees)
        # the admissible grid alone (the anchor): the value is no bound (tests/test_value.py)
        world = WO.resolve(replace(scn, planner=replace(scn.planner, margin=margin, value=False)))
        prob = PB.problem(world, cost)
        res = Search(prob).run(world.scenario.planner.max_expansions)
        assert res.status == "found"
        C = res.states[:, K.S_T if cost == "time" else K.S_E]
        h = np.array([SS.heuristic(prob.params, prob.data, X) for X in res.states])
        assert np.all(h <= C[-1] - C + 1e-9)
    assert h[0] > seen * (C[-1] - C[0])


@functools.lru_cache(maxsize=2)
def _hill_problem(cost):
    from sbmpc.planning import problem as PB
    world = WO.resolve(SC.load(SCEN / "hill_tradeoff.yaml"))
    return world, PB.problem(world, cost)


@settings(max_examples=60, deadline=None)
@given(u=st.floats(0.0, 0.999), v=st.floats(0.0, 0.999), dz=st.floats(-0.2, 0.2), cost=st.sampled_from(["time", "energy"]))
def test_the_grid_read_is_the_least_corner_less_its_way_to_the_pose(u, v, dz, cost):
    """The heuristic reads the cost-to-go grid at the four corners of the pose's cell,
    each less the most the way from that corner to the pose may cost (what the grid's
    value there may exceed the pose's own by): the cell's diagonal / v_bound for time,
    the energy step bound (least_step_energy at the map's largest rolling force, for
    the distance and the pose's height above the corner) for energy; all less the
    goal's gap (heuristics._goal_gap). A grid low at one node only tells whether the
    read takes the right corners and ways."""
    from sbmpc.problems import skidsteer as SS
    from dynamics import kernels as K
    world, prob = _hill_problem(cost)
    Q, data = prob.params.copy(), prob.data.copy()
    nx, ny, res = int(Q[SS.Q_NX]), int(Q[SS.Q_NY]), Q[SS.Q_RES]
    off = int(Q[SS.Q_OFFD])
    i0, j0 = nx // 3, ny // 2                      # the pose's cell: nodes (i0, j0) .. (i0 + 1, j0 + 1)
    H = world.emap.heights
    for ci, cj in ((0, 0), (1, 0), (0, 1), (1, 1)):
        data[off:off + nx * ny] = 1e7
        data[off + (j0 + cj) * nx + i0 + ci] = 5e4       # far above the straight-line bound
        x = Q[SS.Q_OX] + (i0 + u) * res
        y = Q[SS.Q_OY] + (j0 + v) * res
        X = np.zeros(SS.NX)
        X[K.S_X], X[K.S_Y] = x, y
        X[K.S_Z] = H[j0 + cj, i0 + ci] + dz
        d = math.hypot(u - ci, v - cj) * res
        if cost == "time":
            way = math.sqrt(2.0) * res / Q[SS.Q_VBOUND]      # the cell's diagonal (see _node_to_pose)
        else:
            way = float(HE.least_step_energy(Q[SS.Q_FRMAX], Q[SS.Q_MG] * dz, d, HE.copper_coefficient(world)))
        h = SS.heuristic(Q, data, X)
        assert h == pytest.approx(5e4 - way - Q[SS.Q_GOALGAP], rel=1e-12)
    data[off:off + nx * ny] = 1e7                  # a low node outside the cell is not read
    data[off + (j0 + 2) * nx + i0] = 5e4
    assert SS.heuristic(Q, data, X) > 1e6


@pytest.mark.parametrize("cost", ["time", "energy"])
@pytest.mark.parametrize("gap, bearing", [(0.001, 90.0), (0.001, 200.0), (0.05, 30.0), (0.3, 135.0), (1.0, 200.0)])
def test_the_heuristic_stays_below_a_real_drive_into_a_disc_off_the_grids_nodes(cost, gap, bearing):
    """A path ends where it first touches the goal disc, which can lie up to a cell from
    the nearest grid node inside it (here the disc's centre is half a cell off the
    nodes). From rest, ``gap`` metres outside the disc at ``bearing`` from its centre
    and facing it, the
    heuristic must stay below what driving at the top speed costs to enter it (the
    closed-loop model's own time or battery energy over its 1 s edges). (With the grid
    reaching the disc only through its nodes inside, 1 mm north of this disc read
    1.22 J where entering it costs 0.24 J.)"""
    from sbmpc.planning import problem as PB
    from sbmpc.problems import skidsteer as SS
    scn = SC.load(SCEN / "flat.yaml")
    goal = dict(scn.goal, x=16.125, y=8.51, radius=0.5)
    scn = replace(scn, goal=goal)
    ang = math.radians(bearing)
    x = goal["x"] + (goal["radius"] + gap) * math.cos(ang)
    y = goal["y"] + (goal["radius"] + gap) * math.sin(ang)
    scn = replace(scn, start=dict(scn.start, x=x, y=y, yaw_deg=math.degrees(ang) - 180.0, v=0.0))
    world = WO.resolve(scn)
    prob = PB.problem(world, cost)
    X = prob.start.copy()
    top = WO.wheel_speed_range(world)[1]
    c, S = 0.0, X.copy()
    for _ in range(6):                            # 1 s edges until the disc is entered
        out = np.zeros_like(S)
        step = SS.propagate(prob.params, prob.data, S, np.array([top, top]), out)
        assert step > 0
        c, S = c + step, out
        if SS.is_goal(prob.params, prob.data, S):
            break
    assert SS.is_goal(prob.params, prob.data, S)
    assert SS.heuristic(prob.params, prob.data, X) <= c


# ---- the time step bound (step_speed_bounds) ------------------------------------------
@pytest.mark.parametrize("name", ["narrow_pass", "steep_hill", "hills_field"])     # asphalt, packed dirt, grass
def test_the_time_step_bound_is_the_steady_drives_speed_from_above(name):
    """Straight drives at the top command at 1 kHz, from rest and from the commanded top
    speed, down 10 deg, level, and up half and nearly all of the steepest grade the
    terrain holds: after 2 s the speed is at most the step bound, and within 2.1 % of it
    downhill (the PID's overshoot allowed for) and 0.5 % on the level and half way up:
    the bound is tight. (Near the steepest grade a drive from rest settles at 0.28 m/s
    with its wheels slipping, from the top speed at 0.757 m/s; the bound, 0.759 m/s,
    is the faster.) Entered at the commanded top speed, more than the steady one on the
    level and uphill, the drive gains on the bound by less than CARRY_S (0.018 s near
    the steepest grade)."""
    world = WO.resolve(SC.load(SCEN / f"{name}.yaml"))
    v, t = world.vehicle, world.terrains[0]
    m = Model(v, t)
    _, hi = HE.wheel_speed_range(world)
    vb = HE._bounds(world)[0]
    top = math.degrees(steepest_grade(v, t))
    for deg, slack in ((-10.0, 0.021), (0.0, 0.005), (0.5 * top, 0.005), (top - 0.5, 1.0)):
        th = math.radians(deg)
        bound = float(HE.step_speed_bounds(world, np.zeros(1, int), np.array([th]), vb)[0])
        assert bound < vb
        for w0 in (0.0, hi):
            tr = simulate(m, hold(hi, 5, 1e-3), hold(hi, 5, 1e-3), state=m.state(w0, w0, th), pitch=th, dt=1e-3)
            s, tt = tr.data["s"], tr.data["t"]
            k = tt >= 2.0
            speed = (s[k][-1] - s[k][0]) / (tt[k][-1] - tt[k][0])
            assert (1.0 - slack) * bound <= speed <= bound
            lead = np.max(s - s[0] - bound * (tt - tt[0]))
            assert lead <= HE.CARRY_S * bound



# ---- the band along the map's edge; why a search found nothing --------------------------
def _wall_world(gap_rows: int):
    """A 20 x 10 m asphalt map cut by a 3 m wall with 60 deg flanks at x = 10 m, open
    only in its first ``gap_rows`` rows of 0.25 m cells along the map's edge y = 0."""
    import sbmpc
    res = 0.25
    H = np.zeros((41, 81))
    x = res * np.arange(81)
    wall = np.clip(3.0 - math.tan(math.radians(60)) * np.abs(x - 10.0), 0.0, None)
    H[gap_rows:, :] = wall[None, :]
    scn = {"name": "wall", "terrain": "asphalt", "start": {"x": 3.0, "y": 5.0}, "goal": {"x": 17.0, "y": 5.0, "radius": 0.5}}
    return sbmpc.load_world(scn, heights=H, resolution=res)


def test_the_band_along_the_edge_is_off_limits_to_the_grid_and_the_reachability_check():
    """The vehicle's centre never comes closer to the map's edge than its footprint's
    half-diagonal (an edge that does ends as "left the map"): the reachability check
    avoids those nodes. A wall whose only gap runs along the edge, narrower than that
    band, cuts the goal off, and the plan is refused before any search (the cost-to-go
    grid, a lower bound, still passes there; before, so did the check, and the search
    started); a gap wider than the band leaves it reachable."""
    from sbmpc.planning import plan as PL
    world = _wall_world(2)                                    # nodes y = 0, 0.25: both in the band
    assert world.margin > 0.25
    band = HE.off_limits(world) & ~HE.blocked_cells(world)
    assert band[:, 0].all() and band[:, 1].all() and not band[20, 2]
    why = HE.unreachable_reason(world)
    assert why is not None and "along the map's edge" in why and f"{world.margin:.3f} m" in why
    assert HE.steepest_climb_needed(world) is None
    p = PL.plan(world, "time")
    assert p.status == "no_path" and p.nodes_expanded == 0 and "along the map's edge" in p.reason
    ctg, *_ = HE.cost_to_go.__wrapped__(world, "time")
    j, i = HE._node(world, 3.0, 5.0)
    assert ctg[j, i] < 1e11                                   # the grid's bound passes the band
    open_world = _wall_world(6)                               # 1.5 m of level ground along the edge
    assert HE.unreachable_reason(open_world) is None
    assert HE.steepest_climb_needed(open_world) == 0.0


def test_a_search_that_fails_says_where_it_came_closest_and_whether_a_run_up_is_needed():
    """runup_ramp's ramp (20.6 deg) is steeper than the P3-AT holds on packed dirt
    (13.9 deg): every way climbs 14.9 deg or more somewhere (the grid's 8-neighbour
    steps), so a search cut short is told that only a run-up crosses it, and where it
    came closest to the goal (guided by the grid alone: with the value over position and
    heading the same 30 expansions find the run-up)."""
    from sbmpc.planning import plan as PL
    scn = SC.load(SCEN / "runup_ramp.yaml")
    world = WO.resolve(replace(scn, planner=replace(scn.planner, max_expansions=30, value=False)))
    need = HE.steepest_climb_needed(world)
    assert math.degrees(need) == pytest.approx(14.9, abs=0.1)
    assert need > steepest_grade(world.vehicle, world.terrains[0])
    assert PL.plan(WO.resolve(replace(scn, planner=replace(scn.planner, max_expansions=30))), "time").found
    p = PL.plan(world, "time")
    assert p.status == "no_path"
    assert "closest approach" in p.reason and "run-up" in p.reason and "14.9 deg or more" in p.reason
    flat = WO.resolve(SC.load(SCEN / "flat.yaml"))
    assert HE.steepest_climb_needed(flat) == 0.0


def test_a_start_facing_a_grade_steeper_than_the_vehicle_holds_is_named():
    """A start on a 20 deg plane of asphalt (the P3-AT holds 14.8 deg), heading up the
    fall line: every edge stalls, and the reason names the grade the start faces
    against what the drive holds. Heading along the contour the same start is level
    along its heading and the plan is found (the roll, 20 deg, is within the tip-over
    limit)."""
    import sbmpc
    res = 0.25
    y = res * np.arange(41)
    H = np.tile((math.tan(math.radians(20.0)) * y)[:, None], (1, 61))
    scn = {"name": "tilted", "terrain": "asphalt", "start": {"x": 3.0, "y": 5.0, "yaw_deg": 90.0},
           "goal": {"x": 12.0, "y": 5.0, "radius": 0.5}}
    p = sbmpc.plan_scenario(scn, heights=H, resolution=res)
    assert p.status == "no_path"
    assert ("the start faces a grade of 20.0 deg along its heading (the ground there slopes 20.0 deg), "
            "steeper than the p3at holds (14.8 deg)") in p.reason
    p = sbmpc.plan_scenario(dict(scn, start={"x": 3.0, "y": 5.0, "yaw_deg": 0.0}), heights=H, resolution=res)
    assert p.found
