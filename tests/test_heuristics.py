"""The cost-to-go grid: a lower bound of the cost to the goal, also when a large map
gets only a window of it."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sbmpc import heuristics as HE, scenario as SC, world as WO

SCEN = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.mark.parametrize("name", ["hills_field", "steep_hill"])
@pytest.mark.parametrize("cost", ["time", "energy"])
def test_a_window_stays_below_the_whole_maps_grid(name, cost):
    """With the window forced small, every value inside it is at most the whole map's
    (paths leaving the window are counted at the straight-line bound, never more), and
    outside it the grid gives 0 (the straight-line bound takes over)."""
    scn = SC.load(SCEN / f"{name}.yaml")
    world = WO.resolve(scn)
    full, _ = HE.cost_to_go.__wrapped__(world, cost)
    cells = full.size // 4
    j0, j1, i0, i1 = HE.ctg_window(world, cells)      # as small as the start-goal box allows
    assert (j1 - j0) * (i1 - i0) < 0.8 * full.size
    win, _ = HE.cost_to_go.__wrapped__(world, cost, cells)
    inside = win[j0:j1, i0:i1]
    reach = full[j0:j1, i0:i1] < 1e11
    assert np.all(inside[reach] <= full[j0:j1, i0:i1][reach] + 1e-6)
    mask = np.ones(full.shape, bool)
    mask[j0:j1, i0:i1] = False
    assert np.all(win[mask] == 0.0)


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
