"""Coarse to fine (sbmpc.planning.corridor): the search looks along a coarse search's route first."""
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sbmpc import scenario as SC

from sbmpc.planning import corridor as CO, heuristics as HE, world as WO
from sbmpc.errors import InputError
from sbmpc.planning.plan import search_plan

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


def _world(name: str, **planner) -> WO.World:
    scn = SC.load(SCEN / f"{name}.yaml")
    return WO.resolve(replace(scn, planner=replace(scn.planner, **planner)))


def test_the_corridor_is_the_nodes_within_its_half_width_of_the_route():
    """A straight route along y = 5 on the flat map: the nodes within the half-width (and
    the half diagonal of a cell the route's points round to) are in, the others out."""
    w = _world("flat")
    e = w.emap
    xs = np.arange(2.0, 16.0, 0.05)
    out = CO.corridor_mask(w, np.column_stack([xs, np.full(xs.size, 5.0)]), 1.5)
    ny, nx = e.shape
    X, Y = np.meshgrid(e.origin[0] + e.resolution * np.arange(nx), e.origin[1] + e.resolution * np.arange(ny))
    dist = np.hypot(np.maximum(0.0, np.maximum(2.0 - X, X - 16.0)), Y - 5.0)
    assert not out[dist <= 1.5].any()
    assert out[dist > 1.5 + math.sqrt(2) * e.resolution].all()


def test_the_grid_charges_the_ways_that_stay_in_the_corridor_and_a_penalty_off_it():
    """In the corridor a node's value is the least cost of the ways that stay in it: never
    below the whole map's, and above it where the straight corridor climbs the hill the
    whole map's ways go round; off it the whole map's plus OFF_CORRIDOR, exactly."""
    w = _world("hill_tradeoff")
    full = HE.cost_to_go(w, "energy")[0]
    e = w.emap
    ys = np.linspace(w.scenario.start["y"], w.scenario.goal["y"], 400)
    xs = np.linspace(w.scenario.start["x"], w.scenario.goal["x"], 400)
    keep_out = CO.corridor_mask(w, np.column_stack([xs, ys]), 1.5)
    narrow = replace(w, keep_out=keep_out)
    grid = HE.cost_to_go(narrow, "energy")[0]
    inside = ~keep_out & (grid < 1e5)
    assert inside.sum() > 100 and (~keep_out).sum() < 0.5 * keep_out.size
    assert np.all(grid[inside] >= full[inside] - 1e-6)
    assert (grid[inside] > full[inside] + 10.0).any()
    reach = keep_out & (full < 1e11)
    np.testing.assert_allclose(grid[reach], full[reach] + HE.OFF_CORRIDOR, rtol=0, atol=1e-6)
    assert e.shape == grid.shape


@pytest.mark.slow
def test_a_corridor_plan_takes_far_fewer_expansions_and_costs_about_the_same():
    """hill_tradeoff's energy plan (seed 0): the coarse route round the hill and the
    search along it expand at most half the nodes of the whole map's search (16 311), and
    the plan, driven at 1 kHz, reaches the goal within 2 % of the whole map's energy.
    Without the margin, as measured (bench/results/corridor.json): with it the corridor
    search expands 0.64x the whole map's (7 362 against 11 535), the twin's refusals
    alike in both. Guided by the grid alone (value off): the value over position and
    heading takes the whole map's search to the goal in fewer expansions (41 at the
    defaults, 2026-12-06) than the corridor's coarse search."""
    plain = search_plan(_world("hill_tradeoff", threads=1, margin=0.0, value=False), "energy")
    fine = search_plan(_world("hill_tradeoff", threads=1, corridor_energy=1.5, margin=0.0, value=False), "energy")
    assert plain.found and fine.found and fine.check.reached
    assert fine.coarse.status == "found" and fine.coarse.cost > fine.energy_J
    assert fine.nodes_expanded <= 0.5 * plain.nodes_expanded, (fine.nodes_expanded, plain.nodes_expanded)
    assert abs(fine.energy_J - plain.energy_J) <= 0.02 * plain.energy_J, (fine.energy_J, plain.energy_J)
    doc = fine.to_json()
    assert doc["coarse"]["expansions"] == fine.coarse.expansions and plain.to_json()["coarse"] is None
    jsonschema = pytest.importorskip("jsonschema")
    from sbmpc import schemas
    jsonschema.Draft202012Validator(schemas.get("plan")).validate(json.loads(json.dumps(doc)))


def test_without_a_coarse_route_the_whole_map_is_searched(monkeypatch):
    """A coarse search that finds nothing within its budget leaves the search as it was:
    the same controls, its expansions counted."""
    plain = search_plan(_world("flat", threads=1), "time")
    monkeypatch.setattr(CO, "COARSE_MAX_EXPANSIONS", 1)
    fine = search_plan(_world("flat", threads=1, corridor_time=1.5), "time")
    assert fine.coarse.status == "no_path" and fine.coarse.cost is None
    assert fine.controls == plain.controls
    assert fine.nodes_expanded == plain.nodes_expanded + fine.coarse.expansions


def test_a_corridor_that_holds_no_way_to_the_goal_still_plans(monkeypatch):
    """A corridor cut off from the goal (every node but those near the start off it): the
    search expands the corridor's nodes first and goes on over the whole map."""
    def near_start_only(world, xy, half_width):
        e = world.emap
        ny, nx = e.shape
        X, Y = np.meshgrid(e.origin[0] + e.resolution * np.arange(nx), e.origin[1] + e.resolution * np.arange(ny))
        s = world.scenario.start
        return np.hypot(X - s["x"], Y - s["y"]) > 2.0
    plain = search_plan(_world("flat", threads=1), "time")
    monkeypatch.setattr(CO, "corridor_mask", near_start_only)
    p = search_plan(_world("flat", threads=1, corridor_time=1.5), "time")
    assert p.found and p.check.reached and p.coarse.status == "found"
    # the corridor's nodes first: more expansions than the whole map's search alone
    assert p.nodes_expanded - p.coarse.expansions > plain.nodes_expanded, (p.nodes_expanded, plain.nodes_expanded)


def test_the_coarse_search_does_not_starve_a_small_node_budget():
    """flat's time plan takes 93 expansions; with a budget of 120 the coarse search's
    expansions (counted, not charged) leave the search its whole budget."""
    plain = search_plan(_world("flat", threads=1, max_expansions=120), "time")
    p = search_plan(_world("flat", threads=1, max_expansions=120, corridor_time=1.5), "time")
    assert plain.found and p.found, p.reason
    assert p.coarse.expansions > 0


@pytest.mark.parametrize("value", [-1.0, "wide"])
def test_a_bad_half_width_is_named(value):
    with pytest.raises(InputError, match="planner.corridor_energy"):
        SC.parse({"name": "x", "map": {"generate": {"size": [10, 10], "resolution": 0.5}}, "terrain": "vinyl",
                  "vehicle": "p3at", "start": {"x": 1, "y": 1}, "goal": {"x": 8, "y": 8, "radius": 0.5},
                  "planner": {"corridor_energy": value}})


def test_off_a_windowed_grid_the_corridor_still_charges_its_penalty():
    """On a map larger than the grid's window the grid is 0 beyond the window (the
    straight-line bound applies there): a node off the corridor there would have been
    cheaper than one in it. It gets the straight-line bound plus OFF_CORRIDOR; nodes in
    the corridor stay below OFF_CORRIDOR."""
    w = _world("flat")
    s, g = w.scenario.start, w.scenario.goal
    xs, ys = np.linspace(s["x"], g["x"], 200), np.linspace(s["y"], g["y"], 200)
    keep_out = CO.corridor_mask(w, np.column_stack([xs, ys]), 1.0)
    narrow = replace(w, keep_out=keep_out)
    grid = HE.cost_to_go(narrow, "time", max_cells=1000)[0]
    j0, j1, i0, i1 = HE.ctg_window(narrow, 1000)
    beyond = np.ones(grid.shape, bool)
    beyond[j0:j1, i0:i1] = False
    assert beyond.any() and (beyond & keep_out).any()
    e = w.emap
    X, Y = np.meshgrid(e.origin[0] + e.resolution * np.arange(grid.shape[1]),
                       e.origin[1] + e.resolution * np.arange(grid.shape[0]))
    vb = HE._bounds(w)[0]
    line = np.maximum(np.hypot(X - g["x"], Y - g["y"]) - g["radius"], 0.0) / vb
    np.testing.assert_allclose(grid[beyond & keep_out], (line + HE.OFF_CORRIDOR)[beyond & keep_out], rtol=0, atol=1e-6)
    assert np.all(grid[~beyond & keep_out] >= HE.OFF_CORRIDOR)
    assert np.all(grid[~beyond & ~keep_out] < HE.OFF_CORRIDOR)


def test_the_summary_says_what_the_coarse_search_did(tmp_path, capsys):
    import yaml
    from sbmpc.commands.cli import main
    doc = yaml.safe_load((SCEN / "flat.yaml").read_text())
    doc.setdefault("planner", {})["corridor_time"] = 1.5
    f = tmp_path / "flat_corridor.yaml"
    f.write_text(yaml.safe_dump(doc))
    assert main(["plan", str(f), "--cost", "time", "--quiet", "--threads", "1"]) == 0
    out = capsys.readouterr().out
    assert "  coarse to fine: a coarse route (" in out and "searched within 1.5 m of it first" in out

