"""A scenario made concrete: its map, vehicle and terrains loaded (:class:`World`), the
wheel-speed range and control set the planner samples, and the planner state at the start.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from dynamics import ParameterError, kernels as K
from dynamics.params import Terrain, Vehicle, load_terrain, load_vehicle
from dynamics.simulate import Model
from maps import ElevationMap
from maps.io import MapError, load_class_raster, load_map

from ..errors import InputError
from ..problems import skidsteer as SS
from .. import scenario as SC
from ..scenario import Scenario, terrain_layer


@dataclass(frozen=True, eq=False)
class World:
    """A scenario resolved: the map (with its terrain layer), the vehicle, the terrains."""

    scenario: Scenario
    emap: ElevationMap
    vehicle: Vehicle
    terrains: tuple
    keep_out: np.ndarray | None = None   # (ny, nx) nodes off a corridor search's corridor (sbmpc.planning.corridor),
                                         # where the cost-to-go grid adds heuristics.OFF_CORRIDOR

    @property
    def half_length(self) -> float:
        """Half the wheelbase [m]: where the axles touch the ground ahead and behind."""
        v = self.vehicle
        return 0.25 * (v.patch_outer + v.patch_inner)

    @property
    def half_width(self) -> float:
        return 0.5 * self.vehicle.width

    @property
    def margin(self) -> float:
        """Half-diagonal of the footprint [m]: how close the centre may come to the map edge."""
        v = self.vehicle
        return math.hypot(0.5 * v.patch_outer, 0.5 * (v.width + v.patch_width))

    def terrain_at(self, x: float, y: float) -> Terrain:
        k = self.emap.terrain_index(x, y)
        return self.terrains[max(k, 0)]

    def model(self, x: float, y: float) -> Model:
        return Model(self.vehicle, self.terrain_at(x, y), self.scenario.planner.dt)


def resolve(scn: Scenario, given: dict | None = None) -> World:
    """Load the map, vehicle and terrains of a scenario; one InputError listing every
    problem (map, vehicle, each terrain, start and goal) at once. ``given`` names where
    a key's value came from when not from the file (``{"start": "--start"}``)."""
    if not isinstance(scn, Scenario):
        raise InputError(f"scn: expected a Scenario (sbmpc.scenario.load, or sbmpc.load_world for a path or a dict), "
                         f"found {type(scn).__name__}")
    given = given or {}
    label = lambda key: f"{key} ({given[key]})" if key in given else key     # noqa: E731
    src = str(scn.path) if scn.path else scn.name
    problems = []
    emap = vehicle = None
    try:
        emap = load_map(scn.map_spec, scn.base, "map")
    except MapError as exc:
        problems.append(str(exc))
    try:
        vehicle = load_vehicle(scn.vehicle, scn.base)
    except ParameterError as exc:
        problems.append(f"vehicle: {exc}")
    raster = None if isinstance(scn.terrain, str) else scn.terrain.get("raster")
    if isinstance(scn.terrain, str):
        names = [scn.terrain]
    else:
        names = ([scn.terrain["default"]] + (list(raster["classes"].values()) if raster else [])
                 + [r.terrain for r in scn.terrain["regions"]])
        names = list(dict.fromkeys(names))
    terrains = []
    for n in names:
        try:
            terrains.append(load_terrain(n, scn.base))
        except ParameterError as exc:
            problems.append(f"terrain: {exc}")
    if problems:
        raise InputError(f"{src}: " + (problems[0] if len(problems) == 1 else
                                       f"{len(problems)} problems:\n  " + "\n  ".join(problems)))
    if not isinstance(scn.terrain, str):
        ny, nx = emap.shape
        ox, oy = emap.origin
        base = None
        if raster:
            try:
                C = load_class_raster(raster["file"], scn.base, emap.shape)
            except MapError as exc:
                raise InputError(f"{src}: {exc}") from None
            base = np.zeros(C.shape, np.int64)          # classes not listed: the default terrain
            for cls, name in raster["classes"].items():
                base[C == cls] = names.index(name)
        layer = terrain_layer(scn.terrain["regions"], 0, names, ox + emap.resolution * np.arange(nx),
                              oy + emap.resolution * np.arange(ny), base)
        emap = ElevationMap(emap.heights, emap.resolution, emap.origin, layer, tuple(names), emap.name)
    world = World(scn, emap, vehicle, tuple(terrains))
    problems = []
    x0, x1, y0, y1 = emap.extent
    m = world.margin
    for key, p in (("start", scn.start), ("goal", scn.goal)):
        if not emap.contains(p["x"], p["y"], m):
            problems.append(f"{label(key)}: expected (x, y) at least {math.ceil(m * 1000) / 1000:.3f} m inside the map "
                            f"[{x0:g}, {x1:g}] x [{y0:g}, {y1:g}], found ({p['x']:g}, {p['y']:g})")
    s, g = scn.start, scn.goal
    if not problems and math.hypot(s["x"] - g["x"], s["y"] - g["y"]) <= g["radius"]:
        problems.append(f"{label('start')}: expected a start outside the goal disc (centre ({g['x']:g}, {g['y']:g}), radius "
                        f"{g['radius']:g} m), found ({s['x']:g}, {s['y']:g}) inside it: nothing to plan")
    if scn.cost == "energy" and vehicle is not None and vehicle.regen:
        problems.append(_regen_refused(label("cost"), label("vehicle"), vehicle))
    if problems:
        raise InputError(f"{src}: " + "; ".join(problems))
    return world


# ---- the search problem ------------------------------------------------------------
def wheel_speed_range(world: World) -> tuple:
    ws = world.scenario.planner.wheel_speeds
    if ws is not None:
        return ws
    w0 = world.vehicle.no_load_speed
    return -0.5 * w0, w0


FIXED_CONTROLS = ((1.0, 1.0), (1.0, 0.85), (0.85, 1.0))   # x the top of the range


def control_set(world: World) -> np.ndarray:
    """Controls (m, 3): desired wheel speeds [rad/s] and the periods each is held [-]
    (1): first the fixed rows (top speed straight and two gentle turns at top speed,
    tried at every expansion: a uniform sample of the square almost never has both wheels
    at full speed), then a scrambled Halton sequence over the sampled range (seeded: the
    same seed gives the same plan). With ``planner.hold_periods`` N > 1 the table's
    second half repeats every row held N periods: the held control's variant
    (``long_controls: held``, :func:`sbmpc.search.loop._pick` with hold 2) or rows
    sampled like the others (``sampled``, hold 1 over the whole table)."""
    ps = world.scenario.planner
    lo, hi = wheel_speed_range(world)
    nh = ps.branching - len(FIXED_CONTROLS)
    m = nh * (64 if ps.samples == "rotating" else 1)
    pts = qmc.Halton(d=2, scramble=True, seed=ps.seed).random(m)
    fixed = hi * np.array(FIXED_CONTROLS)
    rows = np.vstack([fixed, lo + (hi - lo) * pts])
    rows = np.column_stack([rows, np.ones(len(rows))])
    if ps.hold_periods > 1:
        # every row again, held for hold_periods periods
        rows = np.vstack([rows, np.column_stack([rows[:, :2], np.full(len(rows), float(ps.hold_periods))])])
    return np.ascontiguousarray(rows)


def hold_mode(ps) -> int:
    """The search's ``Problem.hold`` for planner settings ``ps``: 0 without hold, 1 the
    held control as it came (its own length), 2 its variant held ``hold_periods``
    periods (:func:`control_set`'s second half; ``long_controls: held``)."""
    if not ps.hold:
        return 0
    return 2 if ps.hold_periods > 1 and ps.long_controls == "held" else 1


def start_state(world: World) -> np.ndarray:
    """The model's state at the scenario's start: steady driving at the start speed."""
    s = world.scenario.start
    v = world.vehicle
    w = s["v"] / v.wheel_radius
    return steady_state(world, s["x"], s["y"], math.radians(s["yaw_deg"]), w / v.radius_scale_left,
                        w / v.radius_scale_right, s["v"])


def steady_state(world: World, x: float, y: float, yaw: float, wl: float, wr: float, speed: float) -> np.ndarray:
    """The planner state of the vehicle at (x, y) [m] heading ``yaw`` [rad], its drive
    steady at wheel speeds (wl, wr) [rad/s] on the map's grade there (the references at the
    speeds, the integrals holding the current the load asks for), ``speed`` [m/s] its
    speed; the margin's twin where the vehicle is."""
    e = world.emap
    pitch, _ = e.pitch_roll(x, y, yaw, world.half_length, world.half_width)
    S = world.model(x, y).state(wl, wr, pitch, x, y, yaw, e.height(x, y))
    X = np.zeros(SS.NX)
    X[:K.NS] = S
    X[SS.X_YAWW] = math.atan2(math.sin(yaw), math.cos(yaw))
    X[SS.X_V] = speed
    X[SS.X_TW:SS.X_TW + K.NS] = S          # the margin's twin starts where the vehicle does
    return X


def heavier(vehicle: Vehicle, f: float) -> Vehicle:
    """The vehicle with its mass and inertia times f (a load spread like the body)."""
    return vehicle.replace(mass=vehicle.mass * f, inertia=vehicle.inertia * f)


def gripped(terrains, f: float) -> tuple:
    """The terrains with both friction coefficients of eq. 22, mu_sa and mu_op, times f."""
    return tuple(t.replace(mu_sa=t.mu_sa * f, mu_op=t.mu_op * f) for t in terrains)


@functools.lru_cache(maxsize=8)
def pessimistic(world: World) -> World:
    """The world driven by the margin's pessimistic twin (``planner.margin`` = m): mass and
    inertia, and both friction coefficients of every terrain, times 1 + m (the twin every
    edge of a plan with margin is also driven by, :mod:`sbmpc.problems.skidsteer`). Cached
    per world (worlds hash by identity)."""
    f = 1.0 + world.scenario.planner.margin
    return replace(world, vehicle=heavier(world.vehicle, f), terrains=gripped(world.terrains, f))


@functools.lru_cache(maxsize=8)
def without_margin(world: World) -> World:
    """The world planned without the margin (``planner.margin``, ``margin_tip_deg`` 0):
    :func:`sbmpc.planning.plan.search_plan`'s fallback where no plan keeps it. Cached per world
    (worlds hash by identity), so that a run's re-plans share its cost-to-go grid."""
    ps = replace(world.scenario.planner, margin=0.0, margin_turn=0.0, margin_tip_deg=0.0)
    return replace(world, scenario=replace(world.scenario, planner=ps))


def _start(world: World, start) -> np.ndarray:
    """The planner state to start from: a copy of ``start`` (float64) or the scenario's;
    an InputError unless it is SS.NX finite numbers (the compiled kernels read that many:
    a shorter one read past its end). The margin's twin (SS.X_TW) starts from the
    vehicle's state, whatever ``start`` held there: a plan is made from what is measured."""
    if start is None:
        return start_state(world)
    try:
        X = np.array(start, float)
    except (TypeError, ValueError):
        raise InputError(f"start: expected a planner state of {SS.NX} numbers (world.start_state), "
                         f"found {type(start).__name__}") from None
    if X.shape != (SS.NX,) or not np.all(np.isfinite(X)):
        found = f"shape {X.shape}" if X.shape != (SS.NX,) else "NaN or inf in it"
        raise InputError(f"start: expected a planner state of {SS.NX} finite numbers (world.start_state, "
                         f"a model state and heading and speed), found {found}")
    X[SS.X_TW:SS.X_TW + K.NS] = X[:K.NS]
    return X


def checked_cost(world: World, cost) -> str:
    """``cost``, or the scenario's when None; an InputError for anything but 'time' or
    'energy' (any other value planned for energy), and for 'energy' with a planning
    vehicle that regenerates (its edges could gain energy: the search takes a negative
    edge cost for a failure code, and the energy heuristic banks nothing)."""
    cost = SC.checked_cost(world.scenario.cost if cost is None else cost)
    if cost == "energy" and world.vehicle.regen:
        scn = world.scenario
        raise InputError(f"{scn.path or scn.name}: {_regen_refused('cost', 'vehicle', world.vehicle)}")
    return cost


def _regen_refused(cost_label: str, vehicle_label: str, vehicle) -> str:
    """The one message for an energy plan asked of a regenerating planning vehicle."""
    return (f"{cost_label}: energy needs a planning vehicle without regeneration (regen: false), found "
            f"{vehicle_label} {vehicle.name!r} with regen: true (the energy search counts no energy won back; "
            "plan it for time)")


MAX_REPLAY_STEPS = 10_000_000   # steps of one replay (about 1.5 GB of records): 2.8 h at the 1 kHz rate


def checked_controls(controls, what: str = "controls") -> list:
    """Controls [(wl [rad/s], wr [rad/s], duration [s])], each three finite numbers with a
    duration >= 0; an InputError naming the first that is not."""
    try:
        out = [tuple(float(a) for a in c) for c in controls]
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a list of (wl, wr, duration_s) numbers, found {controls!r:.60}") from None
    for k, c in enumerate(out):
        if len(c) != 3 or not all(math.isfinite(a) for a in c) or c[2] < 0:
            raise InputError(f"{what}[{k}]: expected (wl, wr, duration_s): finite wheel speeds [rad/s] and a "
                             f"duration >= 0 s, found {tuple(controls[k])!r:.60}")
    return out


def checked_budget(seconds, what: str = "time_budget_s"):
    """A time budget [s] (None: the scenario's), a finite number in [0, 86400]."""
    if seconds is None:
        return None
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float, np.floating, np.integer)) \
            or not 0.0 <= seconds <= 86400.0:
        raise InputError(f"{what}: expected seconds in [0, 86400], found {seconds!r:.40}")
    return float(seconds)


def checked_vehicle(vehicle, what: str = "truth", base: Path | None = None):
    """A Vehicle, or one loaded from a shipped name or a file (a relative path from ``base``,
    None: the current folder); None stays None; an InputError naming ``what`` else."""
    if vehicle is None or isinstance(vehicle, Vehicle):
        return vehicle
    if isinstance(vehicle, (str, Path)):
        try:
            return load_vehicle(vehicle, base)
        except ParameterError as exc:
            raise InputError(f"{what}: {exc}") from None
    raise InputError(f"{what}: expected a dynamics.Vehicle, a vehicle name or a vehicle file, "
                     f"found {type(vehicle).__name__}")


@functools.lru_cache(maxsize=32)
def _limits(vehicle: Vehicle, terrains: tuple) -> tuple:
    from dynamics.limits import steepest_grade, tightest_turn
    grade = max(steepest_grade(vehicle, t) for t in terrains)
    turn = min((tightest_turn(vehicle, t), t.name) for t in terrains)
    return grade, turn


def capability(world: World) -> tuple:
    """What the vehicle cannot do on this world, from the model's steady state, before any
    search: (fatal, note). ``fatal``: it cannot hold a constant speed even on level
    ground on any of the terrains (no plan can exist); ``note``: it cannot hold a steady
    turn tighter than half the map's smaller side (its drives saturate in a skid turn).
    Either is None when it does not apply."""
    v = world.vehicle
    grade, (R, tname) = _limits(v, world.terrains)
    names = ", ".join(t.name for t in world.terrains)
    fatal = None
    if grade < 0:
        fatal = (f"the {v.name} cannot hold a constant speed even on level {names}: rolling resistance needs "
                 f"more torque than its drive delivers ({v.continuous_torque:.3g} N m per side)")
    x0, x1, y0, y1 = world.emap.extent
    side = min(x1 - x0, y1 - y0)
    note = None
    if R > 0.5 * side:
        held = "any radius up to 200 m" if math.isinf(R) else f"a radius tighter than {R:g} m"
        note = (f"the {v.name} cannot hold a steady turn of {held} on {tname} (its drives saturate in a skid "
                f"turn) on this {x1 - x0:g} x {y1 - y0:g} m map: expect few ways to the goal")
    return fatal, note


def centres(emap) -> tuple:
    """(X, Y) [m], each (ny, nx): the world coordinates of every cell centre of a map."""
    ny, nx = emap.heights.shape
    return np.meshgrid(emap.origin[0] + emap.resolution * np.arange(nx),
                       emap.origin[1] + emap.resolution * np.arange(ny))
