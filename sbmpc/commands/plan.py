"""``sbmpc plan`` and ``sbmpc compare``: plan a scenario for one cost, or for both."""
from __future__ import annotations

import math
import sys
import time
from dataclasses import replace
from pathlib import Path

from ..errors import InputError, NoResult
from ..search.counters import budget_text
from .compiling import compile_note
from .files import Outputs, atomic, path_arg, scenario_inputs, write_json


def add_parsers(sub):
    p = sub.add_parser("plan", help="plan a scenario (SBMPC over its elevation map)",
                       description="Plan a scenario with SBMPC: print a summary; optionally write the plan "
                       "JSON (schema sbmpc.plan/1) and a rerun recording. Exit code 1 when no path is found.")
    p.add_argument("scenario", type=path_arg, help="scenario YAML file")
    p.add_argument("--cost", choices=("time", "energy"), help="what to minimise (default: the scenario's)")
    p.add_argument("--json", type=path_arg, help="write the plan JSON here")
    p.add_argument("--rrd", type=path_arg, help="write a rerun recording (.rrd) here")
    p.add_argument("--seed", type=int, help="seed of the Halton sampling (default: the scenario's)")
    p.add_argument("--quiet", action="store_true", help="no progress lines on long searches")
    p.add_argument("--robustness", type=int, metavar="N", default=0,
                   help="replay the plan open loop at the controller rate by N vehicles with mass, mu_sa and mu_op "
                   "drawn with 5 %% relative sd: p_stall, p_tip, p_miss in the summary and the JSON's margin")
    add_backend_flags(p)
    p.set_defaults(func=run_plan)

    c = sub.add_parser("compare", help="plan both costs and compare the time- and energy-optimal paths",
                       description="Plan the time-optimal and the energy-optimal path of a scenario; write "
                       "compare.json, compare.png (map with both paths; speed, power, energy along each) and "
                       "compare.rrd into --out.")
    c.add_argument("scenario", type=path_arg, help="scenario YAML file")
    c.add_argument("--out", type=path_arg, default=Path("."), help="output folder (created if missing; default .)")
    c.add_argument("--seed", type=int, help="seed of the Halton sampling (default: the scenario's)")
    c.add_argument("--quiet", action="store_true", help="no progress lines on long searches")
    add_backend_flags(c)
    c.set_defaults(func=run_compare)


def add_backend_flags(p):
    p.add_argument("--device", choices=("cpu", "cuda"),
                   help="where the edges are simulated (default: the scenario's planner.device, cpu); "
                   "cuda needs numba-cuda and an NVIDIA GPU, else a note and the CPU")
    p.add_argument("--threads", type=int, help="CPU threads for the edges and the polish (default: the scenario's; 0: every core)")
    p.add_argument("--batch", type=int, help="nodes whose edges are simulated together (default: the scenario's; "
                   "0: 16 on several CPU threads, 1 on one, 64 on a GPU; the batch grows to it with the search)")
    p.add_argument("--max-expansions", type=int, help="node budget (default: the scenario's planner.max_expansions)")
    p.add_argument("--time-budget", type=float, help="wall-clock budget [s] (default: the scenario's)")
    p.add_argument("--start", help="start pose X,Y[,YAW_DEG] [m, m, deg] (default: the scenario's)")
    p.add_argument("--goal", help="goal X,Y[,RADIUS] [m] (default: the scenario's)")
    p.add_argument("--bag", type=path_arg, metavar="OUT", help="also write a ROS 2 bag folder (MCAP) with the plans' "
                   "nav_msgs/Path, a run's nav_msgs/Odometry and the map as sensor_msgs/PointCloud2, for RViz or "
                   "Foxglove (pip install 'sbmpc[ros]'; docs/robot.md)")
    p.add_argument("--frame", default="map", help="the frame_id of the bag's messages (default: map)")
    p.add_argument("--horizon", type=float, metavar="S", help="receding-horizon plans: every period a search S seconds "
                   "ahead, made while the vehicle drives the period before (plan, compare: the planning vehicle "
                   "drives at its controller rate, and the plan is that drive; run: the truth) (default: the scenario's planner.horizon_s, 0: whole-route plans; docs/planner.md#receding-horizon-plans)")
    p.add_argument("--margin", type=float, help="share of the drive's reach every edge keeps in reserve, and of "
                   "mass and grip its pessimistic twin carries more (default: the scenario's planner.margin, "
                   "0.1; 0: plans at the nominal vehicle's limit; docs/planner.md#margin)")


def bag_out(args) -> Path | None:
    """The --bag folder, checked before any work: a new folder in a writable place."""
    out = getattr(args, "bag", None)
    if out is None:
        return None
    out = Path(out)
    if out.exists():
        raise InputError(f"--bag: expected a new folder for the ROS 2 bag, found the existing '{out}'")
    Outputs().folder(out, "--bag")
    if not getattr(args, "frame", "map") or any(c.isspace() for c in args.frame):
        raise InputError(f"--frame: expected a frame id without spaces, found {args.frame!r}")
    from ..rosbag import _rosbags
    _rosbags()
    return out


def write_bag_out(args, world, plans: dict, run=None) -> None:
    """Write --bag (when given): the plans, the run, the map (sbmpc.rosbag.write_bag)."""
    if getattr(args, "bag", None) is None:
        return
    from ..rosbag import write_bag
    counts = write_bag(args.bag, world.emap, plans, args.frame, run)
    print(f"wrote {args.bag}: ROS 2 bag (MCAP), frame {args.frame}: "
          + ", ".join(f"{t} ({n})" for t, n in counts.items()))


def _numbers(text: str, flag: str, n_min: int, n_max: int, what: str) -> list:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if not n_min <= len(vals) <= n_max or not all(-1e9 < v < 1e9 for v in vals):
        raise InputError(f"{flag}: expected {what}, found {text!r:.60}")
    return vals


def _world(args):
    from .. import scenario as SC
    from ..planning import world as WO
    scn = SC.load(args.scenario)
    if args.seed is not None:
        if not 0 <= args.seed < 2**31:
            raise InputError(f"--seed: expected an integer in [0, 2^31), found {args.seed}")
        scn = replace(scn, planner=replace(scn.planner, seed=args.seed))
    over = {}
    for flag, key, hi in (("threads", "threads", 1024), ("batch", "batch", 4096)):
        v = getattr(args, flag, None)
        if v is not None:
            if not 0 <= v <= hi:
                raise InputError(f"--{flag}: expected an integer in [0, {hi}], found {v}")
            over[key] = v
    if getattr(args, "device", None):
        over["device"] = args.device
    if getattr(args, "max_expansions", None) is not None:
        if not 1 <= args.max_expansions <= 10_000_000:
            raise InputError(f"--max-expansions: expected an integer in [1, 10000000], found {args.max_expansions}")
        over["max_expansions"] = args.max_expansions
    if getattr(args, "time_budget", None) is not None:
        if not 0.01 <= args.time_budget <= 86400:
            raise InputError(f"--time-budget: expected seconds in [0.01, 86400], found {args.time_budget}")
        over["time_budget_s"] = args.time_budget
    if getattr(args, "margin", None) is not None:
        if not 0.0 <= args.margin <= 0.5:
            raise InputError(f"--margin: expected a share in [0, 0.5], found {args.margin}")
        over["margin"] = args.margin
    if getattr(args, "horizon", None) is not None:
        if not 0.0 <= args.horizon <= 3600.0:
            raise InputError(f"--horizon: expected seconds in [0, 3600], found {args.horizon}")
        over["horizon_s"] = args.horizon
    if over:
        scn = replace(scn, planner=replace(scn.planner, **over))
    if getattr(args, "start", None) is not None:
        v = _numbers(args.start, "--start", 2, 3, "X,Y or X,Y,YAW_DEG in metres and degrees")
        scn = replace(scn, start=dict(scn.start, x=v[0], y=v[1], **({"yaw_deg": v[2]} if len(v) > 2 else {})))
    if getattr(args, "goal", None) is not None:
        v = _numbers(args.goal, "--goal", 2, 3, "X,Y or X,Y,RADIUS in metres")
        if len(v) > 2 and not 0.01 <= v[2] <= 1e4:
            raise InputError(f"--goal: expected a radius in [0.01, 10000] m, found {v[2]:g}")
        scn = replace(scn, goal=dict(scn.goal, x=v[0], y=v[1], **({"radius": v[2]} if len(v) > 2 else {})))
    from ..planning.problem import device_note
    note = device_note(scn.planner)
    if note:
        print(f"note: {note}", file=sys.stderr)
    if getattr(args, "cost", None) is not None:
        scn = replace(scn, cost=args.cost)
    if getattr(args, "vehicle", None) is not None:     # run's planning vehicle: margins and cost checked with it
        scn = replace(scn, vehicle=WO.checked_vehicle(args.vehicle, "--vehicle"))
    given = {key: f"--{key}" for key in ("start", "goal", "cost", "vehicle") if getattr(args, key, None) is not None}
    world = WO.resolve(scn, given)
    _, limit = WO.capability(world)
    if limit:
        print(f"note: {limit}", file=sys.stderr)
    return world


class Progress:
    """Progress lines on stderr for searches longer than ``after`` seconds: expansions
    against the node budget, nodes, elapsed against the time budget (both as the search
    states them, :meth:`budgets`), the best plan so far (its cost, in the unit of
    ``cost``, or "no plan yet") and the most time left (where the node budget at the
    average rate so far, or the time budget, ends the search). Only on a terminal (a
    log or a pipe gets the summary alone), never with ``quiet``."""

    def __init__(self, label: str, quiet: bool = False, after: float = 2.0, every: float = 2.0,
                 cost: str | None = None):
        self.label, self.after, self.every = label, after, every
        self.unit = {"time": "s", "energy": "J"}.get(cost, "")
        self.quiet = quiet or not sys.stderr.isatty()
        self.next = after
        self.budget = None
        self.time_budget = None

    def budgets(self, max_iterations: int, time_budget_s: float) -> None:
        """The search's node budget and time budget [s] (inf: none)."""
        self.budget = int(max_iterations)
        self.time_budget = time_budget_s if math.isfinite(time_budget_s) else None

    def line(self, iterations, nodes, elapsed, best=None) -> str:
        """The progress line (without the leading indent)."""
        part = f"{iterations:,} expansions"
        left = [self.time_budget - elapsed] if self.time_budget is not None else []
        if self.budget:
            part += f" of {self.budget:,} ({100.0 * iterations / self.budget:.0f} %)"
            if iterations > 0:
                left.append(elapsed * (self.budget - iterations) / iterations)
        t = f"{elapsed:.1f} s" + (f" of {budget_text(self.time_budget)} s" if self.time_budget is not None else "")
        b = "no plan yet" if best is None else f"best plan so far {best:.1f}{' ' + self.unit if self.unit else ''}"
        eta = f", at most ~{max(0.0, min(left)):.0f} s left" if left else ""
        return f"{self.label}: {part}, {nodes:,} nodes, {t}, {b}{eta}"

    def __call__(self, iterations, nodes, elapsed, best=None):
        if self.quiet or elapsed < self.next:
            return
        self.next = elapsed + self.every
        print("  " + self.line(iterations, nodes, elapsed, best), file=sys.stderr, flush=True)


def summary(plan) -> str:
    if not plan.found:
        return (f"{plan.scenario} [{plan.cost}]: no_path: {plan.reason}\n"
                f"  planning {plan.planning_time_s:.2f} s, {plan.nodes_expanded} nodes expanded, "
                f"{plan.edges_simulated} edges simulated")
    return (f"{plan.scenario} [{plan.cost}]: found\n"
            f"  travel time {plan.travel_time_s:.2f} s, energy {plan.energy_J:.1f} J, length {plan.length_m:.2f} m, "
            f"{len(plan.controls)} controls\n"
            + (f"  {plan.found_by}\n" if plan.found_by.startswith("receding horizon") else "")
            + _check_line(plan) + _margin_line(plan) + _rival_line(plan) + _coarse_line(plan) +
            f"  planning {plan.planning_time_s:.2f} s, {plan.nodes_expanded} nodes expanded, "
            f"{plan.edges_simulated} edges simulated")


def _margin_line(plan) -> str:
    """How close the plan runs to the limits (planner.margin), and its robustness when measured."""
    from ..planning.margin import summary_line
    m = plan.margin
    if not m:
        return ""
    out = "  " + summary_line(m, m.get("kept", False)) + "\n"
    if m.get("note"):
        out += f"  note: {m['note']}\n"
    r = m.get("robustness")
    if r:
        out += (f"  robustness: replayed open loop by {r['samples']} vehicles (mass, mu_sa, mu_op drawn with "
                f"{100 * r['relative_sd']:g} % relative sd): p_stall {r['p_stall']:.2f}, p_tip {r['p_tip']:.2f}, "
                f"p_miss {r['p_miss']:.2f}\n")
    return out


def _coarse_line(plan) -> str:
    """One line on the coarse search of a corridor search (planner.corridor_*), or ''."""
    c = plan.coarse
    if c is None:
        return ""
    if c.status != "found":
        return (f"  coarse to fine: the coarse search found no route in {c.expansions} expansions; the whole map "
                "was searched\n")
    unit = "J" if plan.cost == "energy" else "s"
    return (f"  coarse to fine: a coarse route ({c.cost:.1f} {unit} at the planner's step, {c.expansions} expansions, "
            f"{c.seconds:.2f} s, counted below), searched within {c.half_width_m:g} m of it first\n")


def _check_line(plan) -> str:
    c = plan.check
    if c is None:
        return ""
    line = f"  checked: these numbers are the controls driven at the controller rate ({c.dt * 1e3:g} ms steps)"
    if c.miss_m > 0:
        line += f"; it passes {c.miss_m:.2f} m outside the goal disc (open-loop drift allowance {c.drift_m:.2f} m)"
    if plan.repairs:
        line += (f"; {plan.repairs} re-plan{'s' if plan.repairs > 1 else ''} spliced in where that replay "
                 f"parted from the search's prediction")
    return line + "\n"


def _rival_line(plan) -> str:
    """How an energy plan fared against the time plan it was checked against."""
    r = plan.rival
    if r is None:
        return ""
    if plan.found_by:
        return f"  this is the {plan.found_by}\n"
    if r["status"] != "found":
        return "  checked against the time plan: the time search found no path\n"
    if r.get("checked") is False:
        less = 100.0 * (1.0 - plan.energy_J / r["energy_J"])
        why = (f"this plan uses {less:.0f} % less" if less > 0.0 else
               "this plan keeps the planner's margin and the time search's does not")
        return (f"  checked against the time plan: {r['energy_J']:.1f} J in {r['travel_time_s']:.2f} s at the "
                f"search's step, not driven at 1 kHz: {why} (planned in {r['planning_time_s']:.2f} s, counted "
                f"in the planning time)\n")
    return (f"  checked against the time plan: {r['energy_J']:.1f} J in {r['travel_time_s']:.2f} s "
            f"(planned in {r['planning_time_s']:.2f} s, counted in the planning time)\n")


def run_plan(args) -> int:
    from ..planning import plan as PL
    from .. import recording
    outs = Outputs(scenario_inputs(args.scenario))
    outs.file(args.json, "--json")
    outs.file(args.rrd, "--rrd")
    if not 0 <= args.robustness <= 10_000:
        raise InputError(f"--robustness: expected a number of vehicles in [0, 10000], found {args.robustness}")
    world = _world(args)
    bag_out(args)
    cost = args.cost or world.scenario.cost
    compile_note(args.quiet)
    if world.scenario.planner.horizon_s > 0.0:
        from ..receding import horizon_plan
        plan = horizon_plan(world, cost)
    else:
        plan = PL.plan(world, cost, progress=Progress(f"{cost} search", args.quiet, cost=cost),
                       time_progress=Progress("time search (the energy plan is checked against it)", args.quiet,
                                              cost="time"))
    if args.robustness and plan.found and plan.margin is not None:
        from ..planning.margin import robustness
        plan.margin["robustness"] = robustness(world, cost, plan.controls, args.robustness)
    print(summary(plan))
    write_bag_out(args, world, {cost: plan})
    if args.json:
        write_json(args.json, plan.to_json())
    if args.rrd:
        with atomic(args.rrd) as tmp:
            recording.write(tmp, world.emap, {cost: plan}, app=f"sbmpc plan {world.scenario.name}",
                            scenario=world.scenario, vehicle=world.vehicle)
    if not plan.found:
        raise NoResult(f"no path: {plan.reason}")
    return 0


def compare_table(plans: dict) -> str:
    rows = [("", "time [s]", "energy [J]", "length [m]", "planning [s]", "expanded")]
    for label, p in plans.items():
        if p.found:
            rows.append((f"{label}-optimal", f"{p.travel_time_s:.2f}", f"{p.energy_J:.1f}", f"{p.length_m:.2f}",
                         f"{p.planning_time_s:.2f}", str(p.nodes_expanded)))
        else:
            rows.append((f"{label}-optimal", "no path", "", "", f"{p.planning_time_s:.2f}", str(p.nodes_expanded)))
    w = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.rjust(w[i]) if i else c.ljust(w[i]) for i, c in enumerate(r)) for r in rows)


def run_compare(args) -> int:
    from ..planning import plan as PL
    from .. import recording
    from ..figures import plot_compare
    out = args.out
    Outputs(scenario_inputs(args.scenario)).folder(out, "--out", ("compare.json", "compare.png", "compare.rrd"))
    world = _world(args)
    from ..planning.world import checked_cost
    checked_cost(world, "energy")       # both costs are planned: refused before the folder is made
    bag_out(args)
    out.mkdir(parents=True, exist_ok=True)
    compile_note(args.quiet)
    t0 = time.perf_counter()
    if world.scenario.planner.horizon_s > 0.0:
        from ..receding import horizon_plan
        plans = {c: horizon_plan(world, c) for c in ("time", "energy")}
    else:
        plans = PL.plan_both(world, progress=lambda c: Progress(f"{c} search", args.quiet, cost=c))
    print(f"{world.scenario.name}: {world.scenario.description}".rstrip(": "))
    print(compare_table(plans))
    for c, p in plans.items():
        if p.found_by:
            print(f"note: the {c}-optimal plan is the {p.found_by}")
    doc = {"schema": "sbmpc.compare/1", "scenario": world.scenario.name,
           "plans": {c: {k: v for k, v in p.to_json().items() if k not in ("trajectory",)} for c, p in plans.items()},
           "total_time_s": time.perf_counter() - t0}
    t, e = plans["time"], plans["energy"]
    if t.found and e.found:
        doc["tradeoff"] = {"time_saved_s": e.travel_time_s - t.travel_time_s,
                           "energy_saved_J": t.energy_J - e.energy_J,
                           "holds": bool(t.travel_time_s <= e.travel_time_s + 1e-9 and e.energy_J <= t.energy_J + 1e-9)}
    write_json(out / "compare.json", doc)
    found = [c for c, p in plans.items() if p.found]
    title = (f"{world.scenario.name}: time- vs energy-optimal" if len(found) == 2 and not any(p.found_by for p in plans.values())
             else f"{world.scenario.name}: " + ("no path" if not found else
                                                 ", ".join(f"{c}-optimal" + (f" (= the {plans[c].found_by.split(' search')[0]} plan)" if plans[c].found_by else "")
                                                           for c in plans)))
    with atomic(out / "compare.png") as tmp:
        plot_compare(world.emap, plans, world.scenario, tmp, title=title)
    with atomic(out / "compare.rrd") as tmp:
        recording.write(tmp, world.emap, plans, app=f"sbmpc compare {world.scenario.name}",
                        scenario=world.scenario, vehicle=world.vehicle)
    print(f"wrote {out / 'compare.json'}, {out / 'compare.png'}, {out / 'compare.rrd'}")
    write_bag_out(args, world, plans)
    if not any(p.found for p in plans.values()):
        raise NoResult(f"no path: {plans['time'].reason}")
    return 0
