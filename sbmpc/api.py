"""The Python way in: one call plans, compares or runs a scenario.

    >>> import sbmpc
    >>> plan = sbmpc.plan_scenario("scenarios/hill_tradeoff.yaml", cost="energy")
    >>> plan.found, round(plan.energy_J)
    >>> plan.trajectory["x"]                      # NumPy arrays, sampled every 0.05 s
    >>> plans = sbmpc.compare_scenario("scenarios/hill_tradeoff.yaml")   # {"time": Plan, "energy": Plan}
    >>> run = sbmpc.run_scenario("scenarios/flat.yaml", truth="p3at")

A scenario is a YAML file, a dict with the file's keys, or a :class:`Scenario`. A map
can come as a heights array: ``heights`` (2-D, [m], row j = y, column i = x) with
``resolution`` [m] and ``origin`` (the world (x, y) of cell [0, 0]) replace the
scenario's ``map``. Keyword ``planner`` settings (``max_expansions=...``,
``threads=...``, ``device="cuda"``, ...) override the scenario's. Everything is
validated as the command line validates it: a bad value raises
:class:`sbmpc.errors.InputError` naming the key, what was expected and what was found.
"""
from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path

from .errors import InputError


def _plain(x, key=None):
    """:func:`maps.io.plain_data` (imported when needed: ``import sbmpc`` stays light)."""
    from maps.io import plain_data
    return plain_data(x, key)


def _cost(cost):
    """``cost`` checked before the world is loaded (None: the scenario's)."""
    from .scenario import checked_cost
    return cost if cost is None else checked_cost(cost)


def load_scenario(scenario, heights=None, resolution=None, origin=(0.0, 0.0), **planner):
    """A validated :class:`sbmpc.scenario.Scenario` from a path, a dict or a Scenario (a
    Scenario built or changed in code is checked as its file would be), with an optional
    heights array for its map (``origin`` None: (0, 0)) and planner overrides."""
    from . import scenario as SC
    from dynamics import Vehicle
    vehicle = None
    if isinstance(scenario, SC.Scenario):
        data = SC.to_data(scenario)
        src, path = str(scenario.path or f"<scenario {scenario.name!r:.40}>"), scenario.path
        if isinstance(scenario.vehicle, Vehicle):      # a vehicle object (validated when it was made) is kept
            vehicle, data["vehicle"] = scenario.vehicle, scenario.vehicle.name or "vehicle"
    elif isinstance(scenario, dict):
        data, src, path = dict(scenario), "<scenario dict>", None
    elif isinstance(scenario, (str, Path)):
        data = None
    else:
        raise InputError(f"scenario: expected a path, a dict or a Scenario, found {type(scenario).__name__}")
    if data is None:
        scn = SC.load(scenario)
    else:
        data = _plain(data)
        if heights is not None:      # (a stand-in for validation; the array replaces it below)
            data["map"] = {"heights": [[0.0, 0.0], [0.0, 0.0]], "resolution": 1.0}
        scn = SC.parse(data, src, path)
        if vehicle is not None:
            scn = replace(scn, vehicle=vehicle)
    if heights is not None:
        if resolution is None:
            raise InputError("resolution: expected the cell size in metres of the heights array, found None")
        origin = (0.0, 0.0) if origin is None else _plain(origin)
        scn = replace(scn, map_spec={"heights": heights, "resolution": _plain(resolution),
                                     "origin": origin})
    if planner:
        known = {f.name for f in fields(SC.PlannerSettings)}
        unknown = sorted(set(planner) - known)
        if unknown:
            raise InputError(f"planner.{unknown[0]}: expected one of the keys {', '.join(sorted(known))}, "
                             "found an unknown key")
        # validated as a scenario file's planner section would be
        merged = {f.name: getattr(scn.planner, f.name) for f in fields(SC.PlannerSettings)}
        merged.update(_plain(planner))
        spec = {k: (list(v) if isinstance(v, tuple) else v) for k, v in merged.items() if v is not None}
        probs = SC._Problems(str(scn.path or scn.name))
        settings = SC._planner(spec, probs)
        probs.raise_if_any()
        scn = replace(scn, planner=settings)
    return scn


def load_world(scenario, heights=None, resolution=None, origin=(0.0, 0.0), **planner):
    """The scenario made concrete (:class:`sbmpc.planning.world.World`: map, vehicle, terrains
    loaded and the start and goal checked against the map)."""
    from .planning.world import resolve
    return resolve(load_scenario(scenario, heights, resolution, origin, **planner))


def plan_scenario(scenario, cost: str | None = None, heights=None, resolution=None, origin=(0.0, 0.0),
                  progress=None, **planner):
    """Plan a scenario for ``cost`` ('time' or 'energy'; default the scenario's): a
    :class:`sbmpc.planning.plan.Plan` (``found``, ``controls`` [(wl, wr, duration_s)],
    ``trajectory`` {name: array}, ``travel_time_s``, ``energy_J``, ``reason`` when no
    path was found). An energy plan is checked against the time plan (the time search
    runs first, in the same time budget; ``planner.energy_vs_time``, :func:`sbmpc.planning.plan.plan`).
    ``progress(expansions, nodes, elapsed_s)`` is called while it searches, during both
    searches of an energy plan (a callback with a fourth parameter also gets the best
    plan's cost so far, or None)."""
    from .planning.plan import plan
    _cost(cost)
    if progress is not None and not callable(progress):
        raise InputError(f"progress: expected a function (expansions, nodes, elapsed_s), found {type(progress).__name__}")
    return plan(load_world(scenario, heights, resolution, origin, **planner), cost, progress=progress,
                time_progress=progress)


def compare_scenario(scenario, heights=None, resolution=None, origin=(0.0, 0.0), **planner) -> dict:
    """The time- and the energy-optimal plans, {'time': Plan, 'energy': Plan} (as
    ``sbmpc compare``: a search that found nothing takes the other's plan when that one
    reaches the goal)."""
    from .planning.plan import plan_both
    return plan_both(load_world(scenario, heights, resolution, origin, **planner))


def run_scenario(scenario, cost: str | None = None, truth=None, heights=None, resolution=None,
                 origin=(0.0, 0.0), **planner):
    """A receding-horizon run (``sbmpc run``): plan, execute on ``truth`` (a vehicle
    name, a vehicle YAML path or a :class:`dynamics.Vehicle`; default the planning
    vehicle itself), re-plan where the vehicle leaves the prediction. Returns a
    :class:`sbmpc.receding.RunResult`."""
    from . import receding
    _cost(cost)
    return receding.run(load_world(scenario, heights, resolution, origin, **planner), cost, truth)
