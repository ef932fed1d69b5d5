"""Planning: a scenario's world to a checked plan, read top to bottom.

* :mod:`.world`: the scenario resolved (map, vehicle, terrains, start state);
* :mod:`.heuristics`, :mod:`.problem`: what is known before the search (cost-to-go grid,
  reachability) and the packed search problem;
* :mod:`.corridor`: a coarse search's route the search looks along (opt-in);
* :mod:`.plan`: search (:mod:`sbmpc.search` over :mod:`sbmpc.problems.skidsteer`), then
  :mod:`.polish`, :mod:`.check` at the controller rate and :mod:`.repair`;
* :mod:`.margin`: how close a plan runs to the vehicle's limits;
* :mod:`.horizon`: receding-horizon plans a few seconds ahead.

Entry points: :func:`plan.plan` (a world and a cost to a :class:`Plan`; not re-exported:
the name is its module's), :func:`plan_both`, :func:`search_plan`, :class:`HorizonPlanner`,
:func:`resolve` (a scenario to a world).
"""
from dynamics._jitcache import refresh_once

refresh_once()     # numba's cache, consistent across files (dynamics._jitcache): heuristics compiles

from .horizon import HorizonPlan, HorizonPlanner  # noqa: E402
from .plan import Plan, plan_both, search_plan  # noqa: E402
from .world import World, resolve, start_state  # noqa: E402

__all__ = ["HorizonPlan", "HorizonPlanner", "Plan", "World", "plan_both", "resolve", "search_plan", "start_state"]
