"""Scenario files: map, terrain (one or a layer of regions), vehicle, start, goal, cost and
planner settings, validated with every problem reported at once by its key path.

The minimum is docs/formats.md's; additions (all optional)::

    description: what the scenario shows
    map: {generate: {...}}          # or {file: x.png, resolution:, height_range: [lo, hi]}
    terrain:                        # a layer of regions instead of one name
      default: asphalt
      regions:
        - {terrain: grass, rect: [x0, y0, x1, y1]}
        - {terrain: packed_dirt, circle: [x, y, r]}
        - {terrain: grass, polygon: [[x, y], [x, y], [x, y]]}   # later regions win
    planner: {branching: 16, period_s: 1.0, ...}                 # see PlannerSettings
    run: {trigger: tolerance, tol_xy: 0.5, ...}                  # see RunSettings (sbmpc run)
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np
import yaml

from dynamics.params import did_you_mean, read_yaml_text, yaml_kind

from .errors import InputError
from .schema_parts import NUM, obj

COSTS = ("time", "energy")


def checked_cost(cost) -> str:
    """``cost`` when it is 'time' or 'energy'; an InputError else (any other value planned
    for energy)."""
    if cost not in COSTS:
        raise InputError(f"cost: expected 'time' or 'energy', found {cost!r:.40}")
    return cost


@dataclass(frozen=True)
class PlannerSettings:
    """Settings of the SBMPC search (scenario key ``planner``).

    branching: controls tried per expansion; period_s: how long each new control is
    held [s] (a held one hold_periods times as long); dt: integration step of the edge rollouts [s]; cell_xy [m], cell_yaw_deg [deg],
    cell_v [m/s]: the implicit grid; max_expansions and time_budget_s: budgets after
    which the search gives up with the reason; seed: scrambles the Halton sequence;
    wheel_speeds: [low, high] range of desired wheel speeds sampled [rad/s] (default
    [-0.5, 1] x the no-load speed); samples: 'fixed' (the same Halton points at every
    expansion) or 'rotating' (each node its own window of the sequence, by node number);
    hold: one of the sampled controls is the one that reached the node (a control held
    for several periods: a long gentle arc, a steady speed; docs/planner.md#controls);
    hold_periods: controls that last this many periods join the one-period ones (1:
    every control one period); long_controls: where they enter, 'held' (the held
    control becomes one edge of hold_periods periods, new controls stay one period) or
    'sampled' (the sampled rows are drawn from both lengths, a node's window by its
    number, and a held control keeps its own length; docs/planner.md#controls);
    tip_over_deg: pitch or roll at which an edge is rejected; time_weight, energy_weight:
    w of weighted A* for each cost (1: optimal over the grid; w > 1: at most w times the
    optimum, found with far fewer expansions; the time heuristic is tight, so 1.1
    suffices; for energy 1.1 too, since its heuristic counts the copper loss: over
    Halton seeds the energy plans of hill_tradeoff, steep_hill and mixed_terrain spread
    by 1.8-3.7 % at 1.1 (2.0-4.8 % before the stall test ran on fixed windows, 2.2-3.1 %
    with one-period controls, 3.1-7.0 % at 1.2 with the older heuristic); 2.0 lost up to
    24 %, bench/bench_energy_plans.py; with the value over position and heading, which
    already leads the search greedily, energy_weight 1: on hill_tradeoff, mixed_terrain,
    steep_hill and narrow_pass its plans used 722-851 J against 756-886 J at 1.1, in
    about the same time, bench/bench_value.py); refine:
    after the first solution, go on (anytime weighted A*, pruning with the unweighted
    bound) for refine times the expansions it took, keeping the best plan (0: stop at
    the first; on the shipped scenarios refinement changed no time plan by more than
    0.04 s and did not recover what a weight of 2 lost for energy); threads: CPU threads
    that simulate a node's edges and the polish's trials in parallel (0: all of numba's,
    one per core; the plan is the serial search's); batch: nodes whose edges are simulated together, the next
    node's and those of the open nodes next in line, kept until those are expanded (the
    plan is the serial search's; 0: 16 on several CPU threads, 1 on one, 64 on a GPU;
    the batch grows to it with the search, by one node every 32 expansions); device:
    'cpu' or 'cuda' (the edges on an NVIDIA GPU through numba-cuda; without one, a
    one-line note and the CPU); polish_time, polish_energy: after the search, polish
    the plan of that cost by a local search over its controls (:mod:`sbmpc.planning.polish`; on
    by default for energy, whose plans the sampled speeds and the seed otherwise move
    by several per cent); energy_vs_time: an energy plan is checked against the time
    plan (the time search runs too) and the one that uses less energy at the controller
    rate is kept (:func:`sbmpc.planning.plan.plan`); corridor_time, corridor_energy: half-width
    [m] of the corridor round a coarse search's route that the search of that cost looks
    in (:mod:`sbmpc.planning.corridor`; 0: the whole map); margin: every edge is also driven by a
    pessimistic twin, mass, inertia, mu_sa and mu_op raised by this share, along the same
    path from its own drive state, and fails where the twin stalls (0: none;
    docs/planner.md#margin); margin_turn: while the commands turn, the drive keeps this
    share of its reach (eq. 27's window at the wheel's speed) unused, except for
    ``MARGIN_TIME`` at a time (0: none); margin_tip_deg: edges keep pitch and roll this
    far below tip_over_deg; margin_heading_deg: the twin meets the steeper of the grades
    along headings this far either side; margin_grade_deg: the twin meets every grade
    this much steeper in the direction it drives (the map's slopes that far off: about atan(sd / correlation
    length) of its heights' error, 1.4 deg for 5 cm at 2 m); margin_aside_m: pitch and roll
    are also kept within the margin (within the tip-over limit in a plan made without
    it) with the vehicle this far [m] to either side of its pose, on a search's edges (beside a wall the map's roll rises by degrees a centimetre); horizon_s: ``sbmpc run`` (and ``plan``/``compare``
    with ``--horizon``) plans receding-horizon, each plan a search this many seconds
    ahead with the cost-to-go grid as its terminal cost, made while the vehicle drives
    the period before (:mod:`sbmpc.planning.horizon`; 0: whole-route plans); horizon_budget_s,
    horizon_first_budget_s, horizon_expansions: each horizon plan's wall-clock budget,
    the first one's, and its node budget; horizon_weight, horizon_energy_weight: w of
    the time and of the energy horizon searches, which is also what the terminal cost is
    worth against the cost so far (the grid is a lower bound: 1.3 values the way made
    near what it costs for time; 2 drove energy plans too fast, 13-55 % dearer than
    whole-route runs, 1.3 still 3-23 % on six of nine energy runs, 1.15 within 5 % on five
    of nine, and 1 ran out of the budget before the horizon; bench/bench_horizon.py;
    with the value as the terminal cost, not a lower bound, 1: at 1.3 / 1.15 its
    horizon runs cost 1.07-1.57x the whole-route runs on hill_tradeoff, mixed_terrain,
    narrow_pass and hills_field, at 1 0.98-1.24x; with value off, set 1.3 and 1.15);
    value: guide the searches with the value over position and heading
    (:mod:`sbmpc.planning.value`: one backward Dijkstra over the vehicle's own steady
    motions, with the margin): the horizon's terminal cost, and in whole-route searches
    the heuristic raised towards it, at most to value_w2 (time) or value_energy_w2
    (energy) times the admissible grid (a plan then costs about at most w w2 times the
    optimum over the search's grid, docs/planner.md; time plans at 2 took up to 9.5 % longer than the grid's on narrow_pass,
    runup_ramp and hills_field, at 1.25 -2.8 to +3.5 %, bench/bench_value.py);
    value_cell: the value's lattice spacing [m].
    """

    branching: int = 16
    period_s: float = 1.0
    dt: float = 0.02
    cell_xy: float = 0.5
    cell_yaw_deg: float = 7.5
    cell_v: float = 0.2
    max_expansions: int = 150000
    time_budget_s: float = 60.0
    seed: int = 0
    wheel_speeds: tuple | None = None
    samples: str = "rotating"
    hold: bool = True
    hold_periods: int = 2
    long_controls: str = "held"
    tip_over_deg: float = 30.0
    time_weight: float = 1.1
    energy_weight: float = 1.0
    refine: float = 0.0
    batch: int = 0
    threads: int = 0
    device: str = "cpu"
    polish_time: bool = False
    polish_energy: bool = True
    energy_vs_time: bool = True
    corridor_time: float = 0.0
    corridor_energy: float = 0.0
    margin: float = 0.1
    margin_turn: float = 0.0
    margin_tip_deg: float = 5.0
    margin_heading_deg: float = 0.0
    margin_grade_deg: float = 0.0
    margin_aside_m: float = 0.1
    horizon_s: float = 0.0
    horizon_budget_s: float = 0.09
    horizon_first_budget_s: float = 0.5
    horizon_expansions: int = 2000
    horizon_weight: float = 1.0
    horizon_energy_weight: float = 1.0
    value: bool = True
    value_cell: float = 0.5
    value_w2: float = 1.25
    value_energy_w2: float = 2.0

    def weight(self, cost: str) -> float:
        return self.time_weight if cost == "time" else self.energy_weight

    def polishes(self, cost: str) -> bool:
        return self.polish_time if cost == "time" else self.polish_energy

    def corridor(self, cost: str) -> float:
        """Half-width [m] of the coarse route's corridor the search of ``cost`` looks in
        (:mod:`sbmpc.planning.corridor`; 0: the whole map)."""
        return self.corridor_time if cost == "time" else self.corridor_energy


@dataclass(frozen=True)
class RunSettings:
    """Settings of a receding-horizon run (scenario key ``run``; ``sbmpc run``).

    trigger: 'tolerance' (re-plan only when the measured state leaves the tolerance
    around the state the plan predicted, or the plan ends short of the goal) or 'every'
    (re-plan after every period); tol_xy [m], tol_yaw_deg [deg], tol_v [m/s]: the
    tolerance; execute_periods: periods executed before an 'every' re-plan;
    replan_time_budget_s: wall-clock budget of each re-plan (the first plan has the
    planner's); stall_replan_time_budget_s: that of a re-plan the vehicle waits for (it
    stalled, or the tip-over guard held its next period back); max_replans: the run fails beyond it; max_stalls: stalls of the vehicle
    (each followed by a re-plan from where it stopped) before the run fails;
    max_stalls_near: stalls within ``execution.MARK_NEAR`` of one another (the vehicle
    stuck at one place) before the run fails;
    max_time_factor: the run fails when it takes longer than this times the first
    plan's travel time (plus 30 s); control_period_s: how often a horizon run's controller
    is called (:class:`sbmpc.robot.Controller`, the robot's loop: 0.05-1 s);
    adapt_periods: a whole-route run refits the vehicle (:func:`sbmpc.estimate.fit`) every
    this many periods driven and, where the fit is confident and differs, re-plans with
    the vehicle as measured (0: only at stalls); beside: a horizon run's controller makes
    a whole-route plan beside its horizon plans from the start and hands over to it
    without planning the whole route again (:mod:`sbmpc.planning.rejoin`; off by
    default: docs/planner.md says what it measured); firm_margin: an adaptation also
    firms the margin to two standard errors of the fitted mass and grip
    (:func:`sbmpc.estimate.firmed_margin`; off by default: docs/robustness.md says what it
    measured).
    """

    trigger: str = "tolerance"
    tol_xy: float = 0.5
    tol_yaw_deg: float = 15.0
    tol_v: float = 0.25
    execute_periods: int = 1
    replan_time_budget_s: float = 10.0
    stall_replan_time_budget_s: float = 30.0
    max_replans: int = 50
    max_stalls: int = 3
    max_stalls_near: int = 3
    max_time_factor: float = 3.0
    control_period_s: float = 0.1
    adapt_periods: int = 0
    beside: bool = False
    firm_margin: bool = False


_RUN_RANGES = {
    "tol_xy": (float, 1e-3, 100.0),
    "tol_yaw_deg": (float, 0.1, 180.0),
    "tol_v": (float, 1e-3, 10.0),
    "execute_periods": (int, 1, 1000),
    "replan_time_budget_s": (float, 0.01, 86400.0),
    "stall_replan_time_budget_s": (float, 0.01, 86400.0),
    "max_replans": (int, 0, 100000),
    "max_stalls": (int, 0, 1000),
    "max_stalls_near": (int, 0, 1000),
    "max_time_factor": (float, 1.0, 1000.0),
    "control_period_s": (float, 0.05, 1.0),
    "adapt_periods": (int, 0, 1000),
}
TRIGGERS = ("tolerance", "every")

# (key, type, low, high) of the numeric settings; low/high inclusive
_SETTING_RANGES = {
    "branching": (int, 4, 256),
    "period_s": (float, 0.05, 10.0),
    "dt": (float, 1e-4, 0.05),
    "cell_xy": (float, 0.01, 10.0),
    "cell_yaw_deg": (float, 1.0, 180.0),
    "cell_v": (float, 0.01, 5.0),
    "max_expansions": (int, 1, 10_000_000),
    "time_budget_s": (float, 0.01, 86400.0),
    "seed": (int, 0, 2**31 - 1),
    "tip_over_deg": (float, 1.0, 89.0),
    "time_weight": (float, 1.0, 10.0),
    "refine": (float, 0.0, 100.0),
    "hold_periods": (int, 1, 8),
    "horizon_s": (float, 0.0, 3600.0),
    "horizon_budget_s": (float, 0.001, 3600.0),
    "horizon_first_budget_s": (float, 0.001, 3600.0),
    "horizon_expansions": (int, 1, 10_000_000),
    "horizon_weight": (float, 1.0, 10.0),
    "horizon_energy_weight": (float, 1.0, 10.0),
    "energy_weight": (float, 1.0, 10.0),
    "batch": (int, 0, 4096),
    "threads": (int, 0, 1024),
    "corridor_time": (float, 0.0, 1000.0),
    "corridor_energy": (float, 0.0, 1000.0),
    "margin": (float, 0.0, 0.5),
    "margin_turn": (float, 0.0, 0.5),
    "margin_tip_deg": (float, 0.0, 30.0),
    "margin_heading_deg": (float, 0.0, 45.0),
    "margin_grade_deg": (float, 0.0, 10.0),
    "margin_aside_m": (float, 0.0, 1.0),
    "value_cell": (float, 0.05, 10.0),
    "value_w2": (float, 1.0, 100.0),
    "value_energy_w2": (float, 1.0, 100.0),
}
# the settings that take one of a few words
_SETTING_CHOICES = {"samples": ("fixed", "rotating"), "device": ("cpu", "cuda"),
                    "long_controls": ("held", "sampled")}


@dataclass(frozen=True)
class Region:
    terrain: str
    kind: str          # rect | circle | polygon
    coords: tuple


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. ``path`` is the file it came from (None if built in code)."""

    name: str
    map_spec: dict
    terrain: object            # str (name or path) or {"default": str, "regions": [Region]}
    vehicle: object            # str (name or path), or a dynamics.Vehicle built in code
    start: dict
    goal: dict
    cost: str = "time"
    planner: PlannerSettings = field(default_factory=PlannerSettings)
    description: str = ""
    path: Path | None = None
    run: RunSettings = field(default_factory=RunSettings)

    @property
    def base(self) -> Path:
        return self.path.parent if self.path is not None else Path(".")

    def with_cost(self, cost: str) -> "Scenario":
        return replace(self, cost=cost)


class Verbatim(str):
    """A 'found' text shown as is (not as a repr)."""


def shown(value, limit: int = 60) -> str:
    """A value read from a YAML file, for an error message, in YAML's spelling: null,
    true and false, lists and mappings in YAML's flow style (keys sorted), text quoted
    at the top level; cut to ``limit`` characters."""
    if value is None:
        r = "null"
    elif isinstance(value, bool):
        r = "true" if value else "false"
    elif isinstance(value, int) and abs(value) >= 10 ** 30:
        r = f"an integer of {len(str(abs(value)))} digits"
    elif isinstance(value, (list, dict)):
        try:
            r = yaml.safe_dump(value, default_flow_style=True, width=10 ** 6).strip()
        except yaml.YAMLError:
            r = repr(value)
    else:
        r = repr(value)
    return r if len(r) <= limit else r[:limit] + " ..."


def shown_number(value) -> str:
    """:func:`shown` for a value that should be a number: a text that reads as one is
    said to be text (``maps.generate.text_number_hint``: PyYAML reads 1e3 as a string)."""
    from maps.generate import text_number_hint
    return Verbatim(shown(value) + text_number_hint(value))


MISSING = Verbatim("nothing (the key is missing)")


class _Problems:
    """Collects every problem of a file, then raises one InputError listing them."""

    def __init__(self, src: str):
        self.src = src
        self.items: list[str] = []

    def add(self, key: str, expected: str, found):
        self.items.append(f"{key}: expected {expected}, found {found if isinstance(found, Verbatim) else shown(found)}")

    def add_line(self, line: str):
        self.items.append(line)

    def raise_if_any(self):
        if len(self.items) == 1:
            raise InputError(f"{self.src}: {self.items[0]}")
        if self.items:
            raise InputError(f"{self.src}: {len(self.items)} problems:\n  " + "\n  ".join(self.items))


def _num(d: dict, key: str, where: str, probs: _Problems, default=None, lo=-math.inf, hi=math.inf, what="a number"):
    if key not in d:
        if default is None:
            probs.add(f"{where}.{key}", what, MISSING)
            return math.nan
        return default
    v = d[key]
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 10 ** 30:
        probs.add(f"{where}.{key}", what, v)
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or not lo <= v <= hi:
        probs.add(f"{where}.{key}", what, shown_number(v))
        return math.nan
    return float(v)


def _unknown(d: dict, known: set, where: str, probs: _Problems):
    for k in d:
        if k not in known:
            probs.add(f"{where}.{k}" if where else str(k), f"one of the keys {', '.join(sorted(known))}",
                      Verbatim(f"an unknown key{did_you_mean(k, known)}"))


def _point_list(v, n_min):
    return (isinstance(v, (list, tuple)) and len(v) >= n_min
            and all(isinstance(p, (list, tuple)) and len(p) == 2
                    and all(isinstance(a, (int, float)) and not isinstance(a, bool) and -1e300 < a < 1e300
                            for a in p) for p in v))


def _numbers(v, n):
    return (isinstance(v, (list, tuple)) and len(v) == n
            and all(isinstance(a, (int, float)) and not isinstance(a, bool) and -1e300 < a < 1e300 for a in v))


def _terrain(spec, probs: _Problems):
    if isinstance(spec, str):
        return spec
    if not isinstance(spec, dict):
        probs.add("terrain", "a terrain name, a path to a terrain YAML, or {default:, regions:}", spec)
        return "vinyl"
    _unknown(spec, {"default", "regions", "raster"}, "terrain", probs)
    default = spec.get("default")
    if not isinstance(default, str):
        probs.add("terrain.default", "a terrain name or path", MISSING if "default" not in spec else default)
    raster = spec.get("raster")
    if raster is not None:
        ok = (isinstance(raster, dict) and set(raster) <= {"file", "classes"} and isinstance(raster.get("file"), str)
              and isinstance(raster.get("classes"), dict) and raster["classes"]
              and all(isinstance(k, int) and not isinstance(k, bool) and isinstance(v, str)
                      for k, v in raster["classes"].items()))
        if not ok:
            probs.add("terrain.raster", "{file: a .npy, .png or .tif of integer classes on the map's grid, "
                      "classes: {integer: terrain name or path}}", raster)
            raster = None
    regions = []
    raw = spec.get("regions", [])
    if not isinstance(raw, list):
        probs.add("terrain.regions", "a list of regions", raw)
        raw = []
    for i, r in enumerate(raw):
        w = f"terrain.regions[{i}]"
        if not isinstance(r, dict):
            probs.add(w, "a mapping {terrain:, rect:|circle:|polygon:}", r)
            continue
        _unknown(r, {"terrain", "rect", "circle", "polygon"}, w, probs)
        if not isinstance(r.get("terrain"), str):
            probs.add(f"{w}.terrain", "a terrain name or path", MISSING if "terrain" not in r else r.get("terrain"))
        shapes = [k for k in ("rect", "circle", "polygon") if k in r]
        if len(shapes) != 1:
            probs.add(w, "exactly one of rect, circle, polygon", shapes or None)
            continue
        k = shapes[0]
        v = r[k]
        ok = (_numbers(v, 4) and v[0] < v[2] and v[1] < v[3]) if k == "rect" else \
             (_numbers(v, 3) and v[2] > 0) if k == "circle" else _point_list(v, 3)
        if not ok:
            want = {"rect": "[x0, y0, x1, y1] with x0 < x1, y0 < y1",
                    "circle": "[x, y, r] with r > 0", "polygon": "a list of at least 3 [x, y] points"}[k]
            probs.add(f"{w}.{k}", want, v)
            continue
        regions.append(Region(str(r.get("terrain")), k, tuple(map(tuple, v)) if k == "polygon" else tuple(v)))
    out = {"default": default if isinstance(default, str) else "vinyl", "regions": regions}
    if raster is not None:
        out["raster"] = {"file": raster["file"], "classes": dict(raster["classes"])}
    return out


def _numeric_settings(spec: dict, ranges: dict, where: str, probs: _Problems) -> dict:
    kw = {}
    for key, (typ, lo, hi) in ranges.items():
        if key not in spec:
            continue
        v = spec[key]
        ok = (not isinstance(v, bool) and isinstance(v, (int, float)) and -1e300 < v < 1e300 and lo <= v <= hi
              and (typ is float or float(v).is_integer()))
        if not ok:
            kind, show = ("an integer", lambda x: str(int(x))) if typ is int else ("a number", lambda x: f"{x:g}")
            probs.add(f"{where}.{key}", f"{kind} in [{show(lo)}, {show(hi)}]", v)
        else:
            kw[key] = typ(v)
    return kw


def _planner(spec, probs: _Problems) -> PlannerSettings:
    if spec is None:
        return PlannerSettings()
    if not isinstance(spec, dict):
        probs.add("planner", "a mapping of planner settings", spec)
        return PlannerSettings()
    names = {f.name for f in fields(PlannerSettings)}
    _unknown(spec, names, "planner", probs)
    kw = _numeric_settings(spec, _SETTING_RANGES, "planner", probs)
    if "wheel_speeds" in spec:
        v = spec["wheel_speeds"]
        if not (_numbers(v, 2) and v[0] < v[1]):
            probs.add("planner.wheel_speeds", "[low, high] desired wheel speeds in rad/s with low < high", v)
        else:
            kw["wheel_speeds"] = (float(v[0]), float(v[1]))
    for key, choices in _SETTING_CHOICES.items():
        if key in spec:
            if spec[key] not in choices:
                probs.add(f"planner.{key}", " or ".join(f"'{c}'" for c in choices), spec[key])
            else:
                kw[key] = spec[key]
    for key in ("hold", "polish_time", "polish_energy", "energy_vs_time", "value"):
        if key in spec:
            if not isinstance(spec[key], bool):
                probs.add(f"planner.{key}", "true or false", spec[key])
            else:
                kw[key] = spec[key]
    if kw.get("dt", 0.01) > kw.get("period_s", 1.0):
        probs.add("planner.dt", "a step no longer than planner.period_s", kw.get("dt"))
    tip = kw.get("tip_over_deg", PlannerSettings.tip_over_deg)
    if kw.get("margin_tip_deg", PlannerSettings.margin_tip_deg) >= tip:
        probs.add("planner.margin_tip_deg", f"a margin below planner.tip_over_deg ({tip:g})",
                  kw.get("margin_tip_deg", PlannerSettings.margin_tip_deg))
    return PlannerSettings(**kw)


def _run(spec, probs: _Problems) -> RunSettings:
    if spec is None:
        return RunSettings()
    if not isinstance(spec, dict):
        probs.add("run", "a mapping of run settings", spec)
        return RunSettings()
    _unknown(spec, {f.name for f in fields(RunSettings)}, "run", probs)
    kw = _numeric_settings(spec, _RUN_RANGES, "run", probs)
    if "trigger" in spec:
        if spec["trigger"] not in TRIGGERS:
            probs.add("run.trigger", "'tolerance' or 'every'", spec["trigger"])
        else:
            kw["trigger"] = spec["trigger"]
    for key in ("beside", "firm_margin"):
        if key in spec:
            if not isinstance(spec[key], bool):
                probs.add(f"run.{key}", "true or false", spec[key])
            else:
                kw[key] = spec[key]
    return RunSettings(**kw)


def parse(data, src: str = "<scenario>", path: Path | None = None) -> Scenario:
    """A :class:`Scenario` from parsed YAML; raises InputError listing every problem."""
    probs = _Problems(src)
    if not isinstance(data, dict):
        raise InputError(f"{src}: expected a mapping of scenario keys (name, map, terrain, vehicle, start, goal), "
                         f"found {yaml_kind(data)}")
    known = {"name", "description", "map", "terrain", "vehicle", "start", "goal", "cost", "planner", "run"}
    _unknown(data, known, "", probs)
    name = data.get("name", path.stem if path else "scenario")
    if not isinstance(name, str) or not name:
        probs.add("name", "a non-empty string", name)
    desc = data.get("description", "")
    if not isinstance(desc, str):
        probs.add("description", "a string", desc)
    map_spec = data.get("map")
    if not isinstance(map_spec, dict):
        probs.add("map", "a mapping with 'file' or 'generate'", MISSING if "map" not in data else map_spec)
    terrain = _terrain(data.get("terrain", "vinyl"), probs)
    vehicle = data.get("vehicle", "p3at")
    if not isinstance(vehicle, str):
        probs.add("vehicle", "a vehicle name or a path to a vehicle YAML", vehicle)
    start, goal = {}, {}
    s = data.get("start")
    if not isinstance(s, dict):
        probs.add("start", "a mapping {x:, y:, yaw_deg:, v:}", MISSING if "start" not in data else s)
    else:
        _unknown(s, {"x", "y", "yaw_deg", "v"}, "start", probs)
        start = {"x": _num(s, "x", "start", probs), "y": _num(s, "y", "start", probs),
                 "yaw_deg": _num(s, "yaw_deg", "start", probs, default=0.0),
                 "v": _num(s, "v", "start", probs, default=0.0, lo=-2.0, hi=2.0, what="a speed in [-2, 2] m/s")}
    g = data.get("goal")
    if not isinstance(g, dict):
        probs.add("goal", "a mapping {x:, y:, radius:}", MISSING if "goal" not in data else g)
    else:
        _unknown(g, {"x", "y", "radius"}, "goal", probs)
        goal = {"x": _num(g, "x", "goal", probs), "y": _num(g, "y", "goal", probs),
                "radius": _num(g, "radius", "goal", probs, default=0.5, lo=0.01, hi=1e4, what="a radius in [0.01, 10000] m")}
    cost = data.get("cost", "time")
    if cost not in COSTS:
        probs.add("cost", "time or energy", cost)
    for key, what in (("planner", "planner settings"), ("run", "run settings")):
        if key in data and data[key] is None:       # 'planner:' with nothing under it
            probs.add(key, f"a mapping of {what} (or no '{key}' key for the defaults)", None)
    planner = _planner(data.get("planner"), probs)
    run = _run(data.get("run"), probs)
    probs.raise_if_any()
    for line in schema_problems(data):
        probs.add_line(line)
    probs.raise_if_any()
    return Scenario(name, map_spec, terrain, vehicle, start, goal, cost, planner, desc, path, run)


def to_data(scn: Scenario) -> dict:
    """The scenario-file mapping of a :class:`Scenario` (what :func:`parse` reads back to
    an equal value): a Scenario built or changed in code is validated by parsing this."""
    terrain = scn.terrain
    if isinstance(terrain, dict) and isinstance(terrain.get("regions"), (list, tuple)):
        regions = []
        for r in terrain["regions"]:
            if isinstance(r, Region):
                coords = [list(p) for p in r.coords] if r.kind == "polygon" else list(r.coords)
                r = {"terrain": r.terrain, r.kind: coords}
            regions.append(r)
        terrain = {**terrain, "regions": regions}      # (anything else: parse names it)
    planner = scn.planner
    if dataclasses.is_dataclass(planner) and not isinstance(planner, type):
        planner = {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(planner).items()
                   if v is not None}
    run = scn.run
    if dataclasses.is_dataclass(run) and not isinstance(run, type):
        run = dataclasses.asdict(run)
    return {"name": scn.name, "description": scn.description, "map": scn.map_spec, "terrain": terrain,
            "vehicle": scn.vehicle, "start": scn.start, "goal": scn.goal, "cost": scn.cost,
            "planner": planner, "run": run}


def _as_json(x, key=None):
    """Scenario data as JSON Schema sees it: tuples as lists, NumPy scalars as numbers, a
    map's ``heights`` (a NumPy array from Python: checked by the map reader) as []."""
    if key == "heights":
        return []
    if isinstance(x, dict):
        return {k: _as_json(v, k) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_as_json(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


def schema_problems(data) -> list:
    """The scenario JSON Schema (``sbmpc schema scenario``, :mod:`sbmpc.schemas`) run over
    scenario data: one line per violation, 'key.path: message (schema)'. The hand-written
    checks of :func:`parse` run first and say more (did-you-mean, what was found); the
    schema is the second, formal check of the same rules, so a file the schema refuses
    is never planned."""
    import jsonschema
    v = jsonschema.Draft202012Validator(json_schema())
    out = []
    for e in sorted(v.iter_errors(_as_json(data)), key=lambda e: list(map(str, e.absolute_path))):
        msg = e.message
        if e.context:          # none of a oneOf/anyOf's forms fits
            sub = jsonschema.exceptions.best_match(e.context)
            if len(sub.absolute_path) > len(e.absolute_path):
                e, msg = sub, sub.message      # the closest form fails deeper in: name that key
            else:
                msg = "fits none of the forms the schema allows"
        where = ".".join(str(k) for k in e.absolute_path) or "(the file)"
        value = repr(e.instance)
        if len(value) > 40 and msg.startswith(value):      # not the whole mapping again
            msg = "the value" + msg[len(value):]
        msg = msg if len(msg) <= 200 else msg[:197] + "..."
        out.append(f"{where}: {msg} (schema)")
    return out


def load(path: Path | str) -> Scenario:
    """Read and validate a scenario file (the file is only read)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: expected a scenario YAML file, found a folder")
    if not path.exists():
        raise InputError(f"{path}: expected a scenario YAML file, found no such file")
    if not path.is_file():
        raise InputError(f"{path}: expected a scenario YAML file, found a special file (a device or a pipe)")
    try:
        data = read_yaml_text(path)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the scenario: {exc.strerror}") from None
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None
    try:
        return parse(data, str(path), path)
    except InputError as exc:
        more = _file_problems(data, path)
        if not more:
            raise
        msg = str(exc)
        head, _, rest = msg.partition(": ")
        items = rest.split("\n  ")[1:] if " problems:\n  " in rest else [rest]
        # the schema's line for a key the file's own problem names more closely goes
        named = {m.split(":")[0].split(".")[0] for m in more}
        items = [i for i in items if not (i.endswith("(schema)") and i.split(":")[0].split(".")[0] in named)]
        items += more
        raise InputError(f"{head}: " + (items[0] if len(items) == 1 else
                                        f"{len(items)} problems:\n  " + "\n  ".join(items))) from None


def _file_problems(data, path: Path) -> list:
    """The map, vehicle and terrain problems of a scenario that also has problems of its
    own (so that one run lists them all): each file or name is tried where the raw YAML
    names it."""
    from dynamics import ParameterError, load_terrain, load_vehicle
    from maps.io import MapError, load_map
    if not isinstance(data, dict):
        return []
    out = []
    m = data.get("map")
    if isinstance(m, dict):
        try:
            load_map(m, path.parent, "map")
        except MapError as exc:
            out.append(str(exc))
        except Exception:                # its own problems are in the parse stage's list
            pass
    v = data.get("vehicle")
    if isinstance(v, str):
        try:
            load_vehicle(v, path.parent)
        except ParameterError as exc:
            out.append(f"vehicle: {exc}")
    t = data.get("terrain")
    names = [t] if isinstance(t, str) else ([t.get("default")] + [r.get("terrain") for r in t.get("regions") or []
                                                                   if isinstance(r, dict)]
                                            if isinstance(t, dict) and isinstance(t.get("regions", []), list) else [])
    for n in dict.fromkeys(x for x in names if isinstance(x, str)):
        try:
            load_terrain(n, path.parent)
        except ParameterError as exc:
            out.append(f"terrain: {exc}")
    return out


def terrain_layer(regions, default_index: int, names: list, x: np.ndarray, y: np.ndarray,
                  base: np.ndarray | None = None) -> np.ndarray:
    """Raster of terrain indices (into ``names``) over the grid of cell centres (x, y):
    ``base`` (a class raster already mapped to indices) or the default everywhere, the
    regions drawn on top in their order."""
    from matplotlib.path import Path as MplPath
    X, Y = np.meshgrid(x, y)
    layer = np.full(X.shape, default_index, dtype=np.int64) if base is None else base.astype(np.int64).copy()
    for r in regions:
        k = names.index(r.terrain)
        if r.kind == "rect":
            x0, y0, x1, y1 = r.coords
            inside = (X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1)
        elif r.kind == "circle":
            cx, cy, rad = r.coords
            inside = (X - cx) ** 2 + (Y - cy) ** 2 <= rad ** 2
        else:
            inside = MplPath(np.array(r.coords)).contains_points(np.c_[X.ravel(), Y.ravel()]).reshape(X.shape)
        layer[inside] = k
    return layer


def _ranges(table: dict) -> dict:
    props = {}
    for key, (typ, lo, hi) in table.items():
        props[key] = {"type": "integer" if typ is int else "number", "minimum": lo, "maximum": hi}
    return props


def json_schema() -> dict:
    """The scenario JSON Schema (``sbmpc schema scenario``): its numeric ranges are the
    validator's own tables (``_SETTING_RANGES``, ``_RUN_RANGES``), so the two cannot
    drift apart."""
    point = {"type": "array", "items": NUM, "minItems": 2, "maxItems": 2}
    region = obj({"terrain": {"type": "string"},
                   "rect": {"type": "array", "items": NUM, "minItems": 4, "maxItems": 4},
                   "circle": {"type": "array", "items": NUM, "minItems": 3, "maxItems": 3},
                   "polygon": {"type": "array", "items": point, "minItems": 3}}, ("terrain",), extra=False)
    planner = _ranges(_SETTING_RANGES)
    planner.update({"wheel_speeds": {"type": "array", "items": NUM, "minItems": 2, "maxItems": 2},
                    "hold": {"type": "boolean"},
                    "polish_time": {"type": "boolean"}, "polish_energy": {"type": "boolean"}, "energy_vs_time": {"type": "boolean"},
                    "value": {"type": "boolean"}})
    planner.update({key: {"enum": list(choices)} for key, choices in _SETTING_CHOICES.items()})
    run = _ranges(_RUN_RANGES)
    run["trigger"] = {"enum": list(TRIGGERS)}
    run["beside"] = {"type": "boolean"}
    run["firm_margin"] = {"type": "boolean"}
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": "sbmpc.scenario/1", "title": "sbmpc scenario (YAML, as data)",
        **obj({
            "name": {"type": "string", "minLength": 1},
            "description": {"type": "string"},
            "map": {"oneOf": [
                obj({"file": {"type": "string"}, "resolution": {"type": "number", "exclusiveMinimum": 0},
                      "origin": point, "height_range": point, "nodata": {"enum": ["wall", "error"]},
                      "topic": {"type": "string"}, "layer": {"type": "string"}, "message": {"type": "integer"}},
                     ("file",), extra=False),
                obj({"generate": {"type": "object"}}, ("generate",), extra=False),
                obj({"heights": {"type": "array"}, "resolution": {"type": "number", "exclusiveMinimum": 0},
                      "origin": point}, ("heights", "resolution"), extra=False)]},
            "terrain": {"oneOf": [{"type": "string"},
                                  obj({"default": {"type": "string"}, "regions": {"type": "array", "items": region},
                                        "raster": obj({"file": {"type": "string"},
                                                        "classes": {"type": "object",
                                                                    "additionalProperties": {"type": "string"}}},
                                                       ("file", "classes"), extra=False)},
                                       ("default",), extra=False)]},
            "vehicle": {"type": "string"},
            "start": obj({"x": NUM, "y": NUM, "yaw_deg": NUM, "v": {"type": "number", "minimum": -2, "maximum": 2}},
                          ("x", "y"), extra=False),
            "goal": obj({"x": NUM, "y": NUM, "radius": {"type": "number", "minimum": 0.01, "maximum": 1e4,
                                                          "default": 0.5}},
                         ("x", "y"), extra=False),
            "cost": {"enum": ["time", "energy"]},
            "planner": obj(planner, extra=False),
            "run": obj(run, extra=False),
        }, ("map", "start", "goal"), extra=False)}
