"""The Python way in (sbmpc.plan_scenario & co.) and the command line's conveniences:
overrides of start, goal and budgets, --version, vehicle files with a base, 8-bit PNG
maps, compare when only one search finds a path."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import sbmpc
from sbmpc.commands.cli import main
from sbmpc.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
FLAT = ROOT / "scenarios" / "flat.yaml"


def test_one_call_plans_a_file_and_the_trajectory_is_arrays():
    plan = sbmpc.plan_scenario(FLAT)
    assert plan.found and plan.check.reached
    assert isinstance(plan.trajectory["x"], np.ndarray) and len(plan.trajectory["x"]) > 100
    g = {"x": 16.0, "y": 9.0}
    assert np.hypot(plan.trajectory["x"][-1] - g["x"], plan.trajectory["y"][-1] - g["y"]) <= 0.5 + 1e-9


def test_a_heights_array_plans_like_the_same_map_from_a_file(tmp_path):
    """A tilted plane as an array and as a .npy file: the same plan, control for control."""
    H = np.fromfunction(lambda j, i: 0.02 * i * 0.25, (41, 61))          # 2 % grade eastwards
    np.save(tmp_path / "h.npy", H)
    scn = {"name": "tilt", "terrain": "asphalt", "start": {"x": 2.0, "y": 2.0}, "goal": {"x": 12.0, "y": 8.0, "radius": 0.5}}
    a = sbmpc.plan_scenario(scn, heights=H, resolution=0.25, max_expansions=20_000)
    b = sbmpc.plan_scenario(dict(scn, map={"file": str(tmp_path / "h.npy"), "resolution": 0.25}), max_expansions=20_000)
    assert a.found and a.controls == b.controls
    assert a.trajectory["z"][-1] > a.trajectory["z"][0] + 0.15           # it climbed the grade


@pytest.mark.parametrize("kwargs, says", [
    (dict(max_expansions=0), "planner.max_expansions"),
    (dict(foo=1), "planner.foo"),
    (dict(device="tpu"), "planner.device"),
    (dict(cost="speed"), "cost"),
])
def test_bad_api_arguments_raise_one_input_error(kwargs, says):
    with pytest.raises(InputError, match=says):
        sbmpc.plan_scenario(FLAT, **kwargs)


def test_the_api_validates_a_heights_map_as_the_command_line_does():
    scn = {"name": "x", "start": {"x": 200.0, "y": 2.0}, "goal": {"x": 8.0, "y": 8.0, "radius": 0.5}}
    with pytest.raises(InputError, match="start: expected"):
        sbmpc.plan_scenario(scn, heights=np.zeros((41, 41)), resolution=0.25)
    with pytest.raises(InputError, match="finite heights"):
        sbmpc.plan_scenario(dict(scn, start={"x": 2.0, "y": 2.0}), heights=np.full((41, 41), np.nan), resolution=0.25)
    with pytest.raises(InputError, match="resolution"):
        sbmpc.plan_scenario(scn, heights=np.zeros((41, 41)))


def test_a_scenario_object_is_checked_as_its_file_would_be():
    """A Scenario built or changed in code went to the planner unchecked (a negative
    goal radius, a start at 50 m/s, a branching of 2 ended in deep errors); it is parsed
    as its file would be: every shipped scenario reads back equal, a bad value is one
    InputError naming the key."""
    from sbmpc import scenario as SC
    for path in sorted((ROOT / "scenarios").glob("*.yaml")):
        scn = SC.load(path)
        assert sbmpc.load_scenario(scn) == scn, path.name
    scn = SC.load(FLAT)
    for bad, says in [(replace(scn, goal={**scn.goal, "radius": -1.0}), "goal.radius: expected a radius in"),
                      (replace(scn, start={**scn.start, "v": 50.0}), "start.v: expected a speed in"),
                      (replace(scn, start={**scn.start, "x": "a"}), "start.x: expected a number, found 'a'"),
                      (replace(scn, planner=replace(scn.planner, branching=2)), "planner.branching: expected an integer"),
                      (replace(scn, planner=replace(scn.planner, max_expansions=-5)), "planner.max_expansions"),
                      (replace(scn, planner=None), "planner: expected a mapping of planner settings")]:
        with pytest.raises(InputError, match=says):
            sbmpc.load_scenario(bad)
    assert sbmpc.load_scenario(replace(scn, start={"x": 2.0, "y": 2.0})).start == {"x": 2.0, "y": 2.0, "yaw_deg": 0.0, "v": 0.0}
    from dynamics import load_vehicle                # a Vehicle object in the Scenario is kept, as resolve takes it
    heavy = load_vehicle("p3at").replace(mass=40.0)
    assert sbmpc.load_world(replace(scn, vehicle=heavy)).vehicle.mass == 40.0
    with pytest.raises(InputError, match="terrain.regions: expected a list"):
        sbmpc.load_scenario(replace(scn, terrain={"default": "vinyl", "regions": None}))


def test_numpy_numbers_are_numbers_and_bad_python_arguments_are_named():
    """Values computed with NumPy (np.float32, np.int64, an array of two wheel speeds) pass
    as the same Python numbers would; a bad origin, a boolean or complex heights array, a
    progress that is no function and a run's unknown cost are each one InputError."""
    H = np.zeros((21, 21))
    scn = {"name": "np", "terrain": "vinyl", "start": {"x": np.float32(2.0), "y": np.int64(2)},
           "goal": {"x": np.float64(8.0), "y": 8.0, "radius": np.float32(0.5)}}
    s = sbmpc.load_scenario(scn, heights=H, resolution=np.float64(0.5), wheel_speeds=np.array([-3.0, 3.0]),
                            max_expansions=np.int64(100))
    assert s.planner.wheel_speeds == (-3.0, 3.0) and s.planner.max_expansions == 100 and s.start["y"] == 2.0
    assert sbmpc.load_world(scn, heights=H, resolution=0.5, origin=None).emap.extent[0] == 0.0
    for kw, says in [(dict(origin=(np.nan, 0.0)), r"map.origin: expected \[x, y\], two finite numbers"),
                     (dict(origin="ab"), "map.origin"),
                     (dict(heights=H.astype(bool)), "map.heights: expected a 2-D array of real heights in metres, "
                                                    "found an array of bool"),
                     (dict(heights=H.astype(complex)), "found an array of complex128")]:
        with pytest.raises(InputError, match=says):
            sbmpc.load_world(scn, **{"heights": H, "resolution": 0.5, **kw})
    with pytest.raises(InputError, match="progress: expected a function"):
        sbmpc.plan_scenario(FLAT, progress=3)
    with pytest.raises(InputError, match="cost: expected 'time' or 'energy', found 'speed'"):
        sbmpc.run_scenario(FLAT, cost="speed")


def test_the_edge_margin_named_in_a_refusal_is_one_that_passes():
    """A start too close to the map's edge is refused with the distance it needs; that
    distance, as printed, is accepted (it was rounded down: 0.27 m for 0.2732 m, and a
    start at 0.27 m was refused again)."""
    import re
    scn = {"name": "edge", "terrain": "vinyl", "start": {"x": 0.2, "y": 2.0}, "goal": {"x": 8.0, "y": 8.0, "radius": 0.5}}
    H = np.zeros((41, 41))
    with pytest.raises(InputError, match="start: expected") as err:
        sbmpc.load_world(scn, heights=H, resolution=0.25)
    need = float(re.search(r"at least ([0-9.]+) m inside", str(err.value)).group(1))
    world = sbmpc.load_world(dict(scn, start={"x": need, "y": 2.0}), heights=H, resolution=0.25)
    assert 0.0 <= need - world.margin < 1e-3


def test_command_line_overrides_start_goal_and_budgets(tmp_path, capsys):
    out = tmp_path / "p.json"
    assert main(["plan", str(FLAT), "--start", "3,3,45", "--goal", "10,8,0.4", "--max-expansions", "5000",
                 "--time-budget", "30", "--json", str(out), "--quiet"]) == 0
    import json
    doc = json.loads(out.read_text())
    tr = doc["trajectory"]
    assert (tr["x"][0], tr["y"][0]) == (3.0, 3.0) and abs(tr["yaw"][0] - np.radians(45)) < 1e-9
    assert np.hypot(tr["x"][-1] - 10, tr["y"][-1] - 8) <= 0.4 + 1e-9
    capsys.readouterr()
    assert main(["plan", str(FLAT), "--start", "3,x"]) == 2
    assert "--start: expected X,Y" in capsys.readouterr().err
    # a start in the goal disc (a large radius: any start) is nothing to plan, for every command
    for argv in (["plan", str(FLAT), "--goal", "10,8,5000"], ["compare", str(FLAT), "--start", "10,8", "--goal", "10,8"],
                 ["run", str(FLAT), "--start", "16,9"]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "inside it: nothing to plan" in err and "Traceback" not in err
    assert main(["plan", str(FLAT), "--max-expansions", "1", "--quiet"]) == 1
    assert "node budget of 1 expansions" in capsys.readouterr().err


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0 and capsys.readouterr().out.strip() == f"sbmpc {sbmpc.__version__}"


def test_a_vehicle_file_inherits_only_from_a_named_base(tmp_path):
    from dynamics import ParameterError, load_vehicle
    p3at = load_vehicle("p3at")
    part = tmp_path / "mybot.yaml"
    part.write_text("name: mybot\nmass: 80\n")
    with pytest.raises(ParameterError, match="'base'"):
        load_vehicle(part)
    part.write_text("base: p3at\nname: mybot\nmass: 80\n")
    v = load_vehicle(part)
    assert v.mass == 80.0 and v.wheel_radius == p3at.wheel_radius and v.name == "mybot"
    assert "set in" in v.sources["mass"] and "from base p3at" in v.sources["wheel_radius"]
    (tmp_path / "heavier.yaml").write_text("base: mybot.yaml\nmass: 90\n")      # a chain, relative to the file
    assert load_vehicle(tmp_path / "heavier.yaml").mass == 90.0
    (tmp_path / "loop.yaml").write_text("base: loop.yaml\nmass: 90\n")
    with pytest.raises(ParameterError, match="chain"):
        load_vehicle(tmp_path / "loop.yaml")


def test_an_8_bit_png_map_warns_with_its_step_and_the_remedy(tmp_path, capsys):
    from PIL import Image
    from maps import MapWarning, load_map
    img = (np.linspace(0, 255, 61)[None, :] * np.ones((41, 1))).astype(np.uint8)
    Image.fromarray(img).save(tmp_path / "m8.png")
    Image.fromarray(img.astype(np.uint16) * 257).save(tmp_path / "m16.png")
    spec = {"resolution": 0.25, "height_range": [0.0, 2.5]}
    with pytest.warns(MapWarning, match=r"8-bit PNG.*steps of 0.98 cm.*16-bit PNG or a .npy"):
        load_map(dict(spec, file="m8.png"), tmp_path)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", MapWarning)
        m16 = load_map(dict(spec, file="m16.png"), tmp_path)
    assert m16.heights.max() == pytest.approx(2.5)
    scn = tmp_path / "s.yaml"
    scn.write_text(FLAT.read_text().replace("generate: {size: [20, 12], resolution: 0.25, features: []}",
                                            "{file: m8.png, resolution: 0.25, height_range: [0.0, 0.1]}")
                   .replace("x: 16.0, y: 9.0", "x: 12.0, y: 8.0"))
    assert main(["plan", str(scn), "--quiet"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("sbmpc plan: warning: ") and "8-bit PNG" in err[0]


def test_compare_takes_the_other_plan_when_one_search_finds_nothing():
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL, world as WO
    from sbmpc.planning.plan import Plan, plan_both
    world = WO.resolve(SC.load(FLAT))
    real = PL.search_plan

    def energy_fails(w, cost=None, *a, **kw):
        if cost == "energy":
            return Plan(w.scenario.name, "energy", "no_path", "node budget of 3 expansions used up")
        return real(w, cost, *a, **kw)
    PL.search_plan = energy_fails
    try:
        plans = plan_both(world)
        alone = PL.plan(world, "energy")
    finally:
        PL.search_plan = real
    for e in (plans["energy"], alone):     # sbmpc compare, and sbmpc plan --cost energy
        t = plans["time"]
        assert t.found and e.found and e.cost == "energy" and e.controls == t.controls
        assert "time search" in e.found_by and "node budget of 3" in e.found_by


def test_an_energy_plan_is_never_dearer_than_the_time_plan(monkeypatch):
    """``plan(world, "energy")`` runs the time search too and keeps whichever plan uses
    less energy at the controller rate (planner.energy_vs_time). The energy search's own
    plan is made dearer here (its energy channel raised 25 %, as a search that merged
    away the cheap way would return): the time plan is reported, and says so; where the
    own plan is cheaper it stands, with the time plan's figures beside it; with the
    setting off, the own plan stands whatever it costs."""
    from dataclasses import replace
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL, world as WO
    world = WO.resolve(SC.load(FLAT))
    real = PL.search_plan
    calls = []

    def dearer(w, cost=None, *a, **kw):
        calls.append(cost)
        p = real(w, cost, *a, **kw)
        if cost == "energy":
            traj = dict(p.trajectory, energy_J=1.25 * p.trajectory["energy_J"])
            p = replace(p, trajectory=traj)
        return p
    monkeypatch.setattr(PL, "TIME_CHECK_SLACK", 0.5)    # the time plan driven at 1 kHz, its figures compared
    time_plan = real(world, "time")
    own = real(world, "energy")
    assert own.energy_J < time_plan.energy_J            # on flat the energy search wins ...
    kept = PL.plan(world, "energy")
    assert kept.found_by == "" and kept.energy_J == pytest.approx(own.energy_J)
    assert kept.rival["cost"] == "time" and kept.rival["energy_J"] == pytest.approx(time_plan.energy_J)
    assert kept.planning_time_s >= kept.rival["planning_time_s"]        # both searches counted
    monkeypatch.setattr(PL, "search_plan", dearer)
    worse = PL.plan(world, "energy")                    # ... made dearer, it loses
    assert calls == ["time", "energy"]
    assert worse.found and worse.cost == "energy" and worse.controls == time_plan.controls
    assert worse.energy_J == pytest.approx(time_plan.energy_J) and worse.energy_J < 1.25 * own.energy_J
    assert worse.found_by.startswith("time search (better on energy") and f"{1.25 * own.energy_J:.1f} J" in worse.found_by
    scn = world.scenario
    off = WO.resolve(replace(scn, planner=replace(scn.planner, energy_vs_time=False)))
    calls.clear()
    alone = PL.plan(off, "energy")
    assert calls == ["energy"] and alone.rival is None
    assert alone.energy_J == pytest.approx(1.25 * own.energy_J)


def test_what_the_vehicle_cannot_do_is_said_before_searching(tmp_path, capsys):
    """A drive too weak to hold level ground: no path, without a search. The Warthog on
    a 30 x 20 m asphalt map: one note that it cannot hold a steady turn (its drives
    saturate), and the failure names it among the remedies."""
    (tmp_path / "weak.yaml").write_text("base: p3at\nname: weak\ncurrent_limit: 0.05\n")
    scn = {"name": "weak", "map": {"generate": {"size": [20, 12], "resolution": 0.25, "features": []}},
           "terrain": "asphalt", "vehicle": str(tmp_path / "weak.yaml"),
           "start": {"x": 2.0, "y": 2.0}, "goal": {"x": 16.0, "y": 9.0, "radius": 0.5}}
    plan = sbmpc.plan_scenario(scn)
    assert not plan.found and "cannot hold a constant speed even on level asphalt" in plan.reason
    assert plan.nodes_expanded == 0
    wart = tmp_path / "wflat.yaml"
    wart.write_text(FLAT.read_text().replace("vehicle: p3at", "vehicle: warthog").replace("terrain: vinyl", "terrain: asphalt")
                    .replace("size: [20, 12]", "size: [30, 20]"))
    rc = main(["plan", str(wart), "--max-expansions", "300", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 1
    assert err.startswith("note: the warthog cannot hold a steady turn") and "drives saturate" in err
    assert "to try: raise the node budget" in err


def test_the_time_plan_is_driven_at_1_khz_only_where_it_could_be_the_energy_plan(monkeypatch):
    """``plan(world, "energy")`` checks the time plan at the controller rate only where it
    could be the energy plan. On flat the energy plan uses 10 % less energy than the time
    search predicts for its plan: with TIME_CHECK_SLACK at 0.05 that settles it, and the
    time plan is never driven at 1 kHz (rival.checked false, the search's figures, which
    lie within 2 % of that drive's); at 0.5 it is, as always before. The plan is the same
    either way."""
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL, world as WO
    world = WO.resolve(SC.load(FLAT))
    real = PL._checked_plan
    checked = []

    def spy(w, cost, *a, **kw):
        checked.append(cost)
        return real(w, cost, *a, **kw)
    monkeypatch.setattr(PL, "_checked_plan", spy)
    monkeypatch.setattr(PL, "TIME_CHECK_SLACK", 0.5)
    a = PL.plan(world, "energy")
    assert checked == ["energy", "time"] and a.rival["checked"] is True and a.found_by == ""
    checked.clear()
    monkeypatch.setattr(PL, "TIME_CHECK_SLACK", 0.05)
    b = PL.plan(world, "energy")
    assert checked == ["energy"] and b.rival["checked"] is False and b.found_by == ""
    assert b.controls == a.controls and b.energy_J == a.energy_J
    assert b.rival["energy_J"] == pytest.approx(a.rival["energy_J"], rel=0.02)
    assert b.rival["travel_time_s"] == pytest.approx(a.rival["travel_time_s"], rel=0.02)
    assert b.energy_J <= 0.95 * b.rival["energy_J"] and b.planning_time_s >= b.rival["planning_time_s"]


def test_an_energy_plan_and_its_time_check_share_the_time_budget(monkeypatch):
    """The time search runs first; the energy search gets what it left of the budget, and
    an energy search that then runs out says where the time went (and, the time search
    having found nothing either, how to leave it all to the energy search)."""
    from sbmpc import scenario as SC
    from sbmpc.planning import plan as PL, world as WO
    from sbmpc.planning.plan import Plan
    world = WO.resolve(SC.load(FLAT))
    budgets = {}

    def fake(w, cost=None, progress=None, start=None, incumbent=None, time_budget_s=None, **kw):
        budgets[cost] = time_budget_s
        spent = 2.0 if cost == "time" else time_budget_s
        return Plan(w.scenario.name, cost, "no_path", f"time budget of {time_budget_s:.3g} s used up; to try: x",
                    planning_time_s=spent, nodes_expanded=10 if cost == "time" else 7, failure=kind)
    kind = "time_budget"
    monkeypatch.setattr(PL, "search_plan", fake)
    p = PL.plan(world, "energy", time_budget_s=5.0)
    assert budgets == {"time": 5.0, "energy": 3.0}
    assert not p.found and p.planning_time_s == pytest.approx(5.0) and p.nodes_expanded == 17
    assert p.reason == ("time budget of 5 s used up (2.00 s of it by the time search the energy plan is checked "
                        "against, planner.energy_vs_time; 3.00 s left to the energy search); to try: x; the time search "
                        "found no path either; planner.energy_vs_time: false leaves the whole budget to the energy "
                        "search")
    assert p.failure == "time_budget"
    # a time search that overran the whole budget (its grid and 1 kHz check are not cut):
    # the message said "2.00 s of it by the time search ...; 0.00 s left" of 1.5 s
    p = PL.plan(world, "energy", time_budget_s=1.5)
    assert budgets["energy"] == 0.0
    assert p.reason.startswith("time budget of 1.5 s used up (all of it by the time search the energy plan is "
                               "checked against, planner.energy_vs_time, which took 2.00 s: ")
    assert "nothing was left to the energy search" in p.reason and " s of it by" not in p.reason
    kind = "node_budget"                  # told by its kind, not its words: another failure stands as it is
    p = PL.plan(world, "energy", time_budget_s=5.0)
    assert p.reason == "time budget of 3 s used up; to try: x" and p.failure == "node_budget"


def test_the_planning_functions_name_a_bad_argument():
    """From Python: a start of the wrong length was read past its end by the compiled
    replay (a corrupted heap, once an LLVM abort); any cost but 'time' planned for energy
    under the label given; a NaN time budget ran to the node budget; NaN or negative
    control durations, dt = 0, every = 0 were deep errors or skipped; a truth given by
    name or a path given to resolve were AttributeErrors."""
    from sbmpc import receding, scenario
    from sbmpc.planning import check, plan, world
    from sbmpc.problems import skidsteer as SS
    w = world.resolve(scenario.load(FLAT))
    for call, says in [(lambda: check.replay(w, "time", [(5, 5, 2)], start=np.zeros(5)), f"start: expected a planner state of {SS.NX}"),
                       (lambda: plan.plan(w, "time", start=world.start_state(w)[:30]), r"found shape \(30,\)"),
                       (lambda: plan.plan(w, "TIME"), "cost: expected 'time' or 'energy', found 'TIME'"),
                       (lambda: plan.search_plan(w, 5), "cost: expected 'time' or 'energy', found 5"),
                       (lambda: receding.run(w, "foo"), "cost: expected"),
                       (lambda: plan.search_plan(w, "time", time_budget_s=float("nan")), "time_budget_s: expected seconds"),
                       (lambda: check.replay(w, "time", [(5, 5, float("nan"))]), r"controls\[0\]: expected \(wl, wr, duration_s\)"),
                       (lambda: check.replay(w, "time", [(5, 5, -1)]), r"controls\[0\]"),
                       (lambda: check.replay(w, "time", [(5, 5)]), r"controls\[0\]"),
                       (lambda: check.replay(w, "time", [(5, 5, 1e7)]), "expected at most 10,000,000 steps"),
                       (lambda: check.replay(w, "time", [(5, 5, 1)], dt=0), r"dt: expected an integration step in \(0, 1\] s"),
                       (lambda: check.replay(w, "time", [(5, 5, 1)], every=0), "every: expected a whole number"),
                       (lambda: world.resolve(str(FLAT)), "scn: expected a Scenario"),
                       (lambda: receding.run(w, "time", truth=3), "truth: expected a dynamics.Vehicle")]:
        with pytest.raises(InputError, match=says):
            call()
    assert check.replay(w, "time", [(5.0, 5.0, 2.0)])[1] == 0                   # a valid replay still runs
