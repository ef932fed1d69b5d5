"""``sbmpc run``: receding-horizon execution of a scenario by a simulated true vehicle."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from ..errors import InputError, NoResult
from .files import Outputs, atomic, path_arg, scenario_inputs, write_json
from .compiling import compile_note
from .plan import Progress, _world, add_backend_flags, bag_out, write_bag_out


def add_parsers(sub):
    r = sub.add_parser("run", help="execute a scenario with receding-horizon SBMPC (plan, drive, re-plan)",
                       description="Receding-horizon SBMPC: plan with the scenario's vehicle, let a simulated true "
                       "vehicle (--truth, default the same) drive the plan period by period, and re-plan from the "
                       "measured state when it leaves the tolerance around the prediction (or every period). "
                       "Prints predicted vs executed time and energy and the re-plans. Exit code 1 when the run "
                       "fails to reach the goal.")
    r.add_argument("scenario", type=path_arg, nargs="?", help="scenario YAML file (not with --replay)")
    r.add_argument("--replay", type=path_arg, metavar="RUN.json", help="make a run again from its JSON (sbmpc run "
                   "--json, a sweep's closed-loop runs): the same scenario, planning vehicle, cost, settings and "
                   "drawn truth; prints whether it ends as recorded")
    r.add_argument("--draw", type=path_arg, metavar="DRAW.yaml", help="the truth drawn from a YAML mapping {seed, "
                   "vary, faults} (docs/robustness.md): vehicle and terrain parameters, map errors, command delay, "
                   "odometry error, dropped commands")
    r.add_argument("--truth", help="the vehicle that really drives: a shipped name or a vehicle YAML "
                   "(e.g. the extended vehicle of sbmpc diagnose); default: the planning vehicle")
    r.add_argument("--truth-mass", type=float, metavar="F", help="the true vehicle's mass (and inertia) times F "
                   "(e.g. 1.1: a 10 %% heavier payload)")
    r.add_argument("--truth-grip", type=float, metavar="F", help="the true ground's mu_sa and mu_op times F on "
                   "every terrain (e.g. 0.9: 10 %% less grip)")
    r.add_argument("--vehicle", help="the vehicle the planner plans with (default: the scenario's)")
    r.add_argument("--cost", choices=("time", "energy"), help="what to minimise (default: the scenario's)")
    r.add_argument("--trigger", choices=("tolerance", "every"), help="when to re-plan (default: the scenario's "
                   "run.trigger, else tolerance)")
    r.add_argument("--json", type=path_arg, help="write the run JSON (schema sbmpc.run/1) here")
    r.add_argument("--rrd", type=path_arg, help="write a rerun recording (.rrd) here")
    r.add_argument("--seed", type=int, help="seed of the Halton sampling (default: the scenario's)")
    add_backend_flags(r)
    r.add_argument("--quiet", action="store_true", help="no progress lines on long searches")
    r.set_defaults(func=run_run)


def summary(res) -> str:
    d = res.to_json()
    pred, ex = d["predicted"], d["executed"]
    lines = [f"{res.scenario} [{res.cost}], planning with {res.vehicle}, driven by {res.truth}: {res.status}"
             + (f": {res.reason}" if res.reason else "")]
    if ex["travel_time_s"] is not None and pred["travel_time_s"] is not None:
        lines.append(f"  {'':10}{'time [s]':>10}{'energy [J]':>12}")
        lines.append(f"  {'predicted':10}{pred['travel_time_s']:10.2f}{pred['energy_J']:12.1f}")
        lines.append(f"  {'executed':10}{ex['travel_time_s']:10.2f}{ex['energy_J']:12.1f}")
    rt = d["replan_time_s"]
    hz = d.get("horizon")
    if d.get("guarded"):
        lines.append(f"  {d['guarded']} period{'s' if d['guarded'] > 1 else ''} held back by the tip-over guard "
                     f"(predicted within half the tip-over margin)")
    if d.get("weaker_from_t") is not None:
        lines.append(f"  from t = {d['weaker_from_t']:.1f} s the margin's twin"
                     + (f" of {d['planned_as']}" if d.get("planned_as") not in (None, res.vehicle) else "")
                     + f" planned: the vehicle proved weaker than {res.vehicle}")
    if hz:
        lines.append(f"  {hz['plans']} horizon plans ({hz['horizon_s']:g} s ahead): first {hz['first_s'] * 1e3:.0f} ms, "
                     f"then median {hz['replan_median_s'] * 1e3:.0f} ms, 95th percentile "
                     f"{hz['replan_p95_s'] * 1e3:.0f} ms, max {hz['replan_max_s'] * 1e3:.0f} ms; "
                     f"{hz['kept_previous']} kept the previous plan, {hz['from_measured']} from the measured state"
                     + (f"; {hz['fallbacks']} whole-route plans where the horizon saw no way on "
                        f"({sum(hz['fallback_s']):.2f} s)" if hz["fallbacks"] else "")
                     + (f"; wheels held at rest {hz['settled']} period{'s' if hz['settled'] > 1 else ''} to "
                        f"unload a saturated drive" if hz["settled"] else ""))
        lines.append(f"  executed: {ex['travel_time_s']:.2f} s, {ex['energy_J']:.1f} J, {d['periods']} periods, "
                     f"{d['stalls']} stalls" if ex["travel_time_s"] is not None else "")
        return "\n".join(x for x in lines if x)
    lines.append(f"  {d['replans']} re-plans ({d['trigger']} trigger), {d['stalls']} stalls, {d['periods']} periods; "
                 f"planning {d['planning_time_s']:.2f} s (first {d['first_planning_time_s'] or 0:.2f} s"
                 + (f", re-plans {sum(rt) / len(rt):.2f} s on average)" if rt else ")"))
    last = len(d["plans"]) - 1
    for k, p in enumerate(d["plans"][1:], 1):
        # a failed re-plan drives on with the previous plan, unless it ended the run
        drove_on = " (drove on with the previous plan)" if k < last or res.status == "reached" else ""
        lines.append(f"  re-plan {k} at t = {p['t']:.1f} s: {p['why']}"
                     + ("" if p["status"] == "found" else f" -> {p['reason']}{drove_on}")
                     + (" (the rest of the previous plan: the search found nothing cheaper)"
                        if (p["found_by"] or "").startswith("previous") else "")
                     + (" (aimed at the goal disc itself: no way found into the inner disc re-plans aim at)"
                        if p["goal_radius_m"] == d["plans"][0]["goal_radius_m"] else ""))
    return "\n".join(lines)


def _replay_inputs(args):
    """(world, cost, truth, recorded run JSON) of ``--replay`` (its other inputs refused)."""
    import json
    from .. import receding
    given = [f for f, v in (("SCENARIO", args.scenario), ("--truth", args.truth), ("--truth-mass", args.truth_mass),
                            ("--truth-grip", args.truth_grip), ("--vehicle", args.vehicle), ("--cost", args.cost),
                            ("--draw", args.draw), ("--seed", args.seed)) if v is not None]
    if given:
        raise InputError(f"--replay: expected no {', '.join(given)} (the run JSON names them), found them given")
    try:
        doc = json.loads(Path(args.replay).read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{args.replay}: cannot read: {exc}") from None
    except ValueError as exc:
        raise InputError(f"{args.replay}: expected a run JSON, found invalid JSON ({exc})") from None
    world, cost, truth = receding.replayed(doc, str(args.replay))
    return world, cost, truth, doc


def _drawn_truth(args, world):
    """The truth of ``--draw FILE`` ({seed, vary, faults})."""
    from dynamics.params import read_yaml_text
    from .. import truth as TT
    try:
        doc = read_yaml_text(args.draw)
    except (OSError, ValueError) as exc:
        raise InputError(f"{args.draw}: {exc}") from None
    if not isinstance(doc, dict) or set(doc) - {"seed", "vary", "faults"}:
        raise InputError(f"{args.draw}: expected a mapping with keys among seed, vary, faults, found "
                         f"{sorted(doc) if isinstance(doc, dict) else type(doc).__name__}")
    seed = doc.get("seed", 0)
    bad = TT.problems(doc.get("vary") or {}, doc.get("faults") or {})
    if not (isinstance(seed, int) and not isinstance(seed, bool) and 0 <= seed < 2 ** 31):
        bad.insert(0, f"seed: expected an integer in [0, 2^31), found {seed!r}")
    if bad:
        raise InputError(f"{args.draw}: {'; '.join(bad)}")
    return TT.draw(world, doc.get("vary"), doc.get("faults"), seed)


def run_run(args) -> int:
    from ..planning.world import checked_vehicle, heavier
    if args.replay is None and args.scenario is None:
        raise InputError("expected a scenario YAML file (or --replay RUN.json), found neither")
    outs = Outputs(([args.replay] if args.replay else scenario_inputs(args.scenario) + [args.truth, args.vehicle])
                   + [args.draw])
    outs.file(args.json, "--json")
    outs.file(args.rrd, "--rrd")
    if args.replay is not None:
        world, cost, drawn, recorded = _replay_inputs(args)
        bag_out(args)
        return _run(args, world, cost, drawn, None, world.scenario.run, recorded)
    world = _world(args)          # with --vehicle as its planning vehicle
    bag_out(args)
    truth = checked_vehicle(args.truth, "--truth")
    for flag, f in (("--truth-mass", args.truth_mass), ("--truth-grip", args.truth_grip)):
        if f is not None and not 0.2 <= f <= 5.0:
            raise InputError(f"{flag}: expected a factor in [0.2, 5], found {f}")
    if args.truth_mass is not None:
        v = truth or world.vehicle
        truth = heavier(v, args.truth_mass).replace(name=f"{v.name} x{args.truth_mass:g} mass")
    grip = args.truth_grip
    settings = world.scenario.run
    cost = world.scenario.cost          # --cost applied by _world
    if args.draw is not None:
        if truth is not None or grip is not None:
            raise InputError("--draw: expected no --truth, --truth-mass or --truth-grip with it (the draw is around "
                             "the planning vehicle), found them given")
        truth = _drawn_truth(args, world)
    return _run(args, world, cost, truth, grip, settings)


def _run(args, world, cost, truth, grip, settings, recorded=None) -> int:
    from .. import receding, recording
    from .. import truth as TT
    if args.trigger:
        settings = replace(settings, trigger=args.trigger)
    compile_note(args.quiet)
    res = receding.run(world, cost, truth, settings, progress=lambda label: Progress(label, args.quiet, cost=cost),
                       truth_grip=grip)
    print(summary(res))
    if recorded is not None:
        print(replay_line(recorded, res.to_json()))
    first = res.plans[0].plan if res.plans else None
    write_bag_out(args, world, {cost: first} if first is not None and first.found and first.trajectory else {}, res)
    if args.json:
        write_json(args.json, res.to_json())
    if args.rrd:
        with atomic(args.rrd) as tmp:
            recording.write_run(tmp, world.emap, res, app=f"sbmpc run {world.scenario.name}",
                                scenario=world.scenario, vehicle=truth.world.vehicle if isinstance(truth, TT.Truth) else (truth or world.vehicle))
    if res.status != "reached":
        raise NoResult(f"failed: {res.reason}")
    return 0


def replay_line(old: dict, new: dict) -> str:
    """Whether a replayed run ended as recorded: its end, travel time and energy."""
    def num(d, k):
        return d.get(k) if isinstance(d.get(k), (int, float)) else None
    same = old.get("end", old.get("status")) == new["end"]
    diffs = []
    for k, unit in (("travel_time_s", "s"), ("energy_J", "J")):
        a, b = num(old, k), num(new, k)
        if a is not None and b is not None:
            diffs.append(f"{k.split('_')[0]} {b:.2f} {unit} against {a:.2f} {unit}")
            same = same and abs(a - b) <= 1e-6 * max(1.0, abs(a))
    return (f"replay: {'ended as recorded' if same else 'ended otherwise than recorded'} "
            f"({new['end']} against {old.get('end', old.get('status'))}{'; ' if diffs else ''}{'; '.join(diffs)})"
            + ("" if same else "; a different version of sbmpc plans otherwise, and a plan's search may end on its "
               "wall-clock budget, which a loaded machine changes"))
