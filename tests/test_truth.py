"""What can differ from the plan (sbmpc.truth): each fault drawn as documented, each
executed by a run, which reaches or stops and says why, never tips over or leaves the
map; a run made again from its JSON ends as recorded; a stall's inference."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from dynamics import kernels as K
from sbmpc import receding as R
from sbmpc import truth as TT
from sbmpc.api import load_world
from sbmpc.commands.cli import main
from sbmpc.estimate import Evidence

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def flat():
    return load_world(ROOT / "scenarios" / "flat.yaml")


def test_a_draw_is_its_seed_and_its_spec_makes_the_same_truth(flat):
    vary = {"mass": 0.1, "mu_sa": 0.1}
    faults = {"map": {"noise_sd_m": 0.05, "bump": {"height_m": 0.1}}, "delay_s": 0.05}
    a, b, c = (TT.draw(flat, vary, faults, s) for s in (7, 7, 8))
    assert a.spec == b.spec and a.spec != c.spec
    again = TT.from_spec(flat, json.loads(json.dumps(a.spec)))
    assert np.array_equal(again.world.emap.heights, a.world.emap.heights)
    assert again.world.vehicle == a.world.vehicle and again.world.vehicle.delay == pytest.approx(0.05)
    # the planning world is left as it was
    assert flat.emap.heights.max() == flat.emap.heights.min() and flat.vehicle.delay == 0.0


def test_map_errors_have_the_sd_correlation_bias_and_tilt_asked_for(flat):
    e = flat.emap
    t = TT.draw(flat, None, {"map": {"noise_sd_m": 0.05, "corr_m": 2.0}}, 1)
    n = t.world.emap.heights - e.heights
    assert n.std() == pytest.approx(0.05, rel=1e-6)
    lag = int(round(2.0 / e.resolution))     # the correlation at corr_m: about exp(-1/2)
    r = np.corrcoef(n[:, :-lag].ravel(), n[:, lag:].ravel())[0, 1]
    r1 = np.corrcoef(n[:, :-1].ravel(), n[:, 1:].ravel())[0, 1]
    assert 0.35 < r < 0.8 and r1 > 0.95
    t = TT.draw(flat, None, {"map": {"bias_m": 0.3, "tilt_deg": 5.0, "tilt_dir_deg": 0.0}}, 1)
    d = t.world.emap.heights - e.heights
    assert d.mean() == pytest.approx(0.3, abs=1e-9)
    assert np.allclose(np.diff(d, axis=1) / e.resolution, math.tan(math.radians(5.0)))
    assert np.allclose(np.diff(d, axis=0), 0.0)


def test_a_patch_and_a_bump_lie_on_the_way_and_only_in_the_truth(flat):
    t = TT.draw(flat, None, {"map": {"patch": {"terrain": "grass", "radius_m": 1.5}, "bump": {"height_m": 0.12}}}, 3)
    p, b = t.spec["map"]["patch"], t.spec["map"]["bump"]
    s, g = flat.scenario.start, flat.scenario.goal
    for c in (p, b):       # on the straight line from start to goal, a quarter to three quarters along
        f = (c["x"] - s["x"]) / (g["x"] - s["x"])
        assert 0.25 <= f <= 0.75 and c["y"] == pytest.approx(s["y"] + f * (g["y"] - s["y"]))
    assert t.world.terrain_at(p["x"], p["y"]).name == "grass" and flat.terrain_at(p["x"], p["y"]).name == "vinyl"
    assert t.world.terrain_at(p["x"] + 2.0, p["y"] + 2.0).name == "vinyl"
    assert t.world.emap.height(b["x"], b["y"]) - flat.emap.height(b["x"], b["y"]) == pytest.approx(0.12, abs=0.01)


def test_the_odometer_drifts_with_the_distance_and_is_exact_without_error(flat):
    X = R.WO.start_state(flat)
    exact = TT.Truth(flat).odometer()
    assert exact.observe(X) is not X and np.array_equal(exact.observe(X), X)
    o = TT.Truth(flat, {"drift": 0.02, "drift_deg_per_m": 1.0}, seed=5).odometer()
    for k in range(11):                      # 10 m driven along x
        Y = X.copy()
        Y[K.S_X] += k
        o.advance(Y)
    m = o.observe(Y)
    assert math.hypot(m[K.S_X] - Y[K.S_X], m[K.S_Y] - Y[K.S_Y]) == pytest.approx(0.2, rel=1e-9)
    assert abs(m[K.S_YAW] - Y[K.S_YAW]) == pytest.approx(math.radians(10.0), rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(p=st.floats(0.0, 0.9), seed=st.integers(0, 2 ** 31 - 1))
def test_a_dropped_command_leaves_the_drive_at_the_last_it_received(p, seed):
    X = np.zeros(K.NS)
    X[K.S_REFL], X[K.S_REFR] = 1.0, 2.0
    d = TT.Truth(None, dropped=p, seed=seed).dropper()
    last = (1.0, 2.0)
    for k in range(200):
        c = (float(k), -float(k), 0.1)
        a = d.applied(X, c)
        assert a == c or a == (last[0], last[1], 0.1)
        last = a[:2]
    assert d.count == 0 if p == 0.0 else d.count <= 200
    if p > 0.3:
        assert 0.5 * p * 200 < d.count < 1.5 * p * 200 + 10


@pytest.mark.parametrize("faults", [
    {"vary": {"mass": 0.1, "inertia": 0.1, "mu_sa": 0.1, "mu_op": 0.1, "mu_roll": 0.1, "v_max": 0.1}},
    {"map": {"noise_sd_m": 0.05, "corr_m": 2.0}},
    {"map": {"bias_m": 0.5, "tilt_deg": 2.0}},
    {"map": {"patch": {"terrain": "grass", "radius_m": 2.0}}},
    {"map": {"bump": {"height_m": 0.1, "radius_m": 0.5}}},
    {"delay_s": 0.05},
    {"odometry": {"noise_m": 0.03, "noise_deg": 1.0, "drift": 0.05}},
    {"dropped": 0.1},
], ids=["vehicle", "noise", "bias-tilt", "patch", "bump", "delay", "odometry", "dropped"])
def test_each_fault_is_executed_and_the_run_reaches_or_stops_saying_why(flat, faults):
    vary = faults.pop("vary", None)
    t = TT.draw(flat, vary, faults, 11)
    res = R.run(flat, "time", t)
    nominal = R.run(flat, "time")
    d = res.to_json()
    assert res.end in ("reached", "stopped") and (res.end == "reached" or res.reason)
    assert d["truth_at_end"]["x"] == pytest.approx(res.trajectory["x"][-1])
    assert d["truth_spec"] == t.spec
    if res.end == "reached":
        g = flat.scenario.goal      # the true vehicle is in the goal, whatever the odometry says
        assert math.hypot(res.trajectory["x"][-1] - g["x"], res.trajectory["y"][-1] - g["y"]) <= g["radius"] + 1e-6
    # the fault made a difference that the nominal run does not have (odometry: the drift
    # takes the measured pose out of the tolerance: a re-plan from it)
    # dropped: counted (on flat, a lost command is often the same as the one held)
    if "odometry" in faults:
        assert res.replans > nominal.replans
    elif "dropped" not in faults:
        assert (res.energy_J, res.travel_time_s) != (nominal.energy_J, nominal.travel_time_s)
    if "dropped" in faults:
        assert res.dropped > 0
    if "bump" in faults.get("map", {}):
        assert res.trajectory["z"].max() > 0.02 > nominal.trajectory["z"].max()
    if "patch" in faults.get("map", {}):            # grass rolls harder than vinyl
        assert res.energy_J > nominal.energy_J


def test_a_run_json_makes_the_same_run_again(flat, tmp_path, capsys):
    draw = tmp_path / "draw.yaml"
    draw.write_text("seed: 2\nvary: {mass: 0.1}\nfaults: {delay_s: 0.05, odometry: {noise_m: 0.02}, dropped: 0.05}\n")
    out = tmp_path / "run.json"
    assert main(["run", str(ROOT / "scenarios" / "flat.yaml"), "--draw", str(draw), "--json", str(out)]) == 0
    first = json.loads(out.read_text())
    assert main(["run", "--replay", str(out), "--json", str(tmp_path / "again.json")]) == 0
    text = capsys.readouterr().out
    assert "replay: ended as recorded" in text
    again = json.loads((tmp_path / "again.json").read_text())
    assert again["energy_J"] == first["energy_J"] and again["truth_spec"] == first["truth_spec"]
    assert again["dropped"] == first["dropped"]


@pytest.mark.parametrize("draw, words", [
    ("seed: 1\nvary: {mas: 0.1}\n", "vary.mas: expected a numeric vehicle or terrain parameter"),
    ("faults: {map: {tilt: 3}}\n", "faults.map.tilt: expected one of the keys"),
    ("faults: {dropped: 2}\n", "faults.dropped: expected a number in [0, 0.9], found 2"),
    ("seed: -1\n", "seed: expected an integer"),
    ("other: 1\n", "expected a mapping with keys among seed, vary, faults"),
])
def test_a_bad_draw_file_is_one_line_and_exit_2(tmp_path, capsys, draw, words):
    p = tmp_path / "draw.yaml"
    p.write_text(draw)
    assert main(["run", str(ROOT / "scenarios" / "flat.yaml"), "--draw", str(p)]) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1


def test_replay_refuses_what_is_not_a_run_json_and_extra_inputs(tmp_path, capsys):
    p = tmp_path / "x.json"
    p.write_text(json.dumps({"schema": "sbmpc.run/1"}))
    assert main(["run", "--replay", str(p)]) == 2
    assert main(["run", "--replay", str(p), "--cost", "energy"]) == 2
    err = capsys.readouterr().err
    assert "with a replay section" in err and "expected no --cost" in err
    # a run JSON edited by hand: one line each, never a traceback
    good = tmp_path / "run.json"
    assert main(["run", str(ROOT / "scenarios" / "flat.yaml"), "--json", str(good)]) == 0
    doc = json.loads(good.read_text())
    capsys.readouterr()
    for broken in ({**doc, "replay": {**doc["replay"], "cost": "speed"}},
                   {**doc, "replay": {**doc["replay"], "vehicle": {"mass": -1.0}}},
                   {**doc, "truth_spec": {"map": {"bump": {"height_m": 0.1}}}}):
        p.write_text(json.dumps(broken))
        assert main(["run", "--replay", str(p)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "replay" in err, err


def _rec(i: float, v: float, n: int = 50) -> np.ndarray:
    r = np.zeros((n, K.NR))
    r[:, K.R_IL] = r[:, K.R_IR] = i
    r[:, K.R_V] = v
    return r


@pytest.mark.parametrize("i, v, said", [(1.2, 0.5, "weaker"), (1.0, 0.4, "weaker"), (0.8, 0.5, "stronger"),
                                        (1.01, 0.5, "as planned")])
def test_a_stall_is_read_from_the_currents_and_speeds_before_it(i, v, said):
    ev = Evidence()
    X = np.zeros(K.NS)
    assert ev.infer(X)["inferred"] == "unknown"
    for _ in range(5):
        ev.add(_rec(i, v), _rec(1.0, 0.5))
    inf = ev.infer(X)
    assert inf["inferred"] == said and inf["current_ratio"] == pytest.approx(i) and inf["periods"] == 5


def test_a_stronger_vehicles_stalls_are_not_called_weaker():
    from sbmpc import estimate as E2
    why = E2.stall_failure([(1.0, 2.0), (1.5, 2.0)], "p3at", {"inferred": "stronger", "periods": 8,
                                                              "current_ratio": 0.84, "speed_ratio": 1.0})
    assert "not weaker" in why and "0.84 x the predicted current" in why
    assert "weaker there than the planning model" in E2.stall_failure([(1.0, 2.0)], "p3at", None)


def test_a_stall_plans_as_the_vehicle_the_periods_before_it_measured(flat):
    """The online fit (sbmpc.estimate.fit) of a truth 15 % short of battery voltage and
    20 % heavier, from ten periods of the planning vehicle's own driving on the floor:
    v_max and the load (mass and rolling resistance: on level ground the fit cannot tell
    them apart, their product it can) come back within a few per cent; the twin of that
    vehicle plans after the stall."""
    from sbmpc import estimate as E
    truth = E.scaled(flat, {"mass": 1.2, "v_max": 0.85})
    real = R._Executor(truth, "time")
    nominal = R._Executor(flat, "time")
    X = R.WO.start_state(truth)
    ev = E.Evidence()
    for k in range(10):
        c = (8.0, 8.0 + (2.0 if k % 3 == 1 else -2.0 if k % 3 == 2 else 0.0), 1.0)
        pred, _, _ = nominal.step(X, c)
        rec, end, X1 = real.step(X, c)
        assert end == 0
        ev.add(rec, pred, X, c)
        X = X1
    f = E.fit(ev, flat, "time")
    assert f["periods"] == 10
    assert f["v_max"] == pytest.approx(0.85, abs=0.03)
    assert f["mass"] * f["mu_roll"] == pytest.approx(1.2, rel=0.1)
    assert ev.infer(X)["inferred"] == "weaker"
    out = R.RunResult("flat", "time", "p3at", "p3at", flat.scenario.run)
    tw, _, base = R._weaker_model(flat, "time", out, X, f)
    assert base.vehicle.v_max == pytest.approx(round(f["v_max"], 2) * flat.vehicle.v_max)
    assert tw.vehicle.mass == pytest.approx(1.1 * base.vehicle.mass) and out.planned_as.startswith("p3at as measured (")
    assert R._weaker_model(flat, "time", out, X, f)[2] is base          # cached: re-plans share its grids
    _, _, plain = R._weaker_model(flat, "time", out, X)                 # nothing to fit: the planning vehicle's twin
    assert plain is flat


def test_the_maps_tilt_error_is_what_the_imu_shows_beyond_it(flat):
    from sbmpc import execution as EX
    X = R.WO.start_state(flat)                  # on the level floor the map says 0
    assert EX.tilt_error(flat, X, 0.02, -0.05) == pytest.approx(0.05)
    assert EX.tilt_error(flat, X, 0.0, 0.0) == 0.0
    Y = X.copy()
    Y[K.S_X] = -5.0                              # off the map: nothing to compare
    assert EX.tilt_error(flat, Y, 0.3, 0.3) == 0.0


NARROW_TIPPED = {   # a truth drawn by the closed-loop sweep (seed 0) on which narrow_pass's time run rolled over
    "delay_s": 0.05, "dropped": 0.0, "map": {"corr_m": 2.0, "noise_sd_m": 0.05, "seed": 791543436}, "odometry": {},
    "seed": 1648038474, "terrains": [{"mu_op": 0.5589791791057591, "mu_roll": 0.044407442023833954,
                                      "mu_sa": 0.6615215642207078}],
    "vehicle": {"inertia": 0.7477725348850713, "mass": 26.576334411916985, "v_max": 12.52229465247352}}


@pytest.mark.slow
def test_a_lighter_vehicle_on_a_map_5_cm_off_stops_rather_than_roll_over_on_the_pass():
    """A P3-AT 14 % lighter on narrow_pass's map with its heights 5 cm off (2 m
    correlation) and 50 ms of delay: its time run rolled over on the pass's flank at
    (16.6, 10.4), 30 deg of roll, where the planning vehicle's prediction of the period
    stopped at 28.4 and the heavier twin's short of the margin. The guard's optimistic
    twin (a lighter vehicle drives further into the period) holds that period back: the
    run stops and says why, or reaches the goal; it never tips over."""
    w = load_world(ROOT / "scenarios" / "narrow_pass.yaml")
    res = R.run(w, "time", TT.from_spec(w, NARROW_TIPPED))
    assert res.end in ("reached", "stopped"), res.reason
    assert res.guarded >= 1
    if res.end == "stopped":
        assert "the run stops rather than tip over" in res.reason


def test_a_run_that_adapts_plans_for_the_vehicle_it_measures(flat):
    """A P3-AT with 20 % less battery voltage (its top speed 20 % lower) on the floor:
    refitted every 3 periods (run.adapt_periods), the first fit pins v_max at 0.80 (the
    others at 1, mass and grip to standard errors that leave, with run.firm_margin, the
    margin's floor, 0.05 of the file's 0.10) and the run re-plans once as that vehicle: it arrives 2.9 s sooner,
    with 1 re-plan instead of 9, and its prediction is nearer what it executes."""
    from dataclasses import replace
    from sbmpc import estimate as E
    slow = flat.vehicle.replace(v_max=0.8 * flat.vehicle.v_max)
    plain = R.run(flat, "time", slow)
    res = R.run(flat, "time", slow, replace(flat.scenario.run, adapt_periods=3, firm_margin=True))
    assert plain.end == res.end == "reached"
    assert len(res.adapted) == 1 and res.adapted[0]["fit"]["v_max"] == pytest.approx(0.8, abs=0.01)
    assert all(abs(res.adapted[0]["fit"][k] - 1.0) < 0.02 for k in ("mass", "current_limit", "grip", "mu_roll"))
    assert res.adapted[0]["margin"] == E.MARGIN_FLOOR
    assert res.planned_as == "p3at as measured (v_max x0.80, margin 0.05)" and not plain.adapted
    assert res.replans < plain.replans and res.travel_time_s < plain.travel_time_s - 2.0


def test_a_run_that_adapted_names_its_planning_vehicle_before_any_stall(flat):
    """(Adapted, no stall yet: no 'from t = None s'.)"""
    from sbmpc import estimate as E
    out = R.RunResult("flat", "time", "p3at", "p3at", flat.scenario.run)
    measured = E.as_measured(flat, (1.0, 0.8, 1.0, 1.0, 1.0))
    assert R._named(flat, measured, out, measured) == "p3at, then p3at as measured (v_max x0.80)"


@settings(max_examples=60, deadline=None)
@given(se_mass=st.floats(0.0, 0.3), se_grip=st.floats(0.0, 0.3), more=st.floats(0.0, 0.1))
def test_the_margin_firms_with_the_estimate_and_never_below_its_floor_or_above_the_file(flat, se_mass, se_grip, more):
    """The margin an adaptation plans with (estimate.firmed_margin): two standard errors
    of the larger of the twin's factors (mass, grip), rounded up to 0.01, within the
    floor and the file's margin; a less certain fit never gets a smaller margin; a
    factor the periods never excited (the prior's 0.15) keeps the file's."""
    from sbmpc import estimate as E
    fit = {"se": {"mass": se_mass, "grip": se_grip}}
    m = E.firmed_margin(flat, fit)
    file_margin = flat.scenario.planner.margin
    assert E.MARGIN_FLOOR <= m <= file_margin
    assert m >= min(file_margin, 2.0 * max(se_mass, se_grip) - 1e-9)
    looser = {"se": {"mass": se_mass + more, "grip": se_grip}}
    assert E.firmed_margin(flat, looser) >= m
    assert E.firmed_margin(flat, {"se": {"mass": E.FIT_PRIOR, "grip": 0.0}}) == file_margin


def test_a_firm_fit_of_the_files_own_vehicle_plans_with_the_smaller_margin_but_not_as_the_twin(flat):
    """A confident fit that says the vehicle planned for (every factor 1) still changes
    the plans where it firms the margin (0.10 -> 0.05); asked again with that margin it
    changes nothing; without run.firm_margin (the default; and where the plans are made
    for the margin's twin, a stall in this run having shown the model wrong) the file's
    margin stays and nothing changes."""
    from sbmpc import estimate as E
    fit = {k: 1.0 for k in E.FIT} | {"se": {k: 0.01 for k in E.FIT}}
    ones = (1.0,) * len(E.FIT)
    w = E.adapts(flat, fit, (ones, flat.scenario.planner.margin), True)
    assert w is not None and w.scenario.planner.margin == E.MARGIN_FLOOR
    assert w.vehicle.mass == flat.vehicle.mass and "margin 0.05" in w.vehicle.name
    assert E.adapts(flat, fit, (ones, E.MARGIN_FLOOR), True) is None
    assert E.adapts(flat, fit, (ones, flat.scenario.planner.margin), False) is None
    assert E.adapts(flat, {**fit, "se": {k: 0.2 for k in E.FIT}} | {"mass": 1.1}, (ones, 0.1), True) is None


def test_a_stall_puts_back_the_files_margin_that_an_adaptation_firmed(flat):
    """After a stall the plans are made for the margin's twin with the file's margin
    (estimate.at_stall): a world an adaptation firmed to 0.05 goes back to 0.10 with the
    same factors, its twin 10 % heavier; the file's own world and one already at the
    file's margin are returned as they are; asked with the file's margin, as_measured
    gives the one cached world (its grids shared)."""
    from sbmpc import estimate as E
    from sbmpc import execution as EX
    fit = {k: 1.0 for k in E.FIT} | {"mass": 1.1} | {"se": {k: 0.01 for k in E.FIT}}
    ones = (1.0,) * len(E.FIT)
    firmed = E.adapts(flat, fit, (ones, flat.scenario.planner.margin), True)
    assert firmed.scenario.planner.margin == E.MARGIN_FLOOR
    back = E.at_stall(flat, firmed, E.key(fit))
    assert back.scenario.planner.margin == flat.scenario.planner.margin
    assert back is E.as_measured(flat, E.key(fit)) is E.as_measured(flat, E.key(fit), flat.scenario.planner.margin)
    assert back.vehicle.mass == pytest.approx(1.1 * flat.vehicle.mass)
    assert EX.twin_planner(back).vehicle.mass == pytest.approx(1.1 * 1.1 * flat.vehicle.mass)
    assert E.at_stall(flat, flat, ones) is flat and E.at_stall(flat, back, E.key(fit)) is back
