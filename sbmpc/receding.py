"""Receding-horizon execution: plan, apply the first inputs to a "true" vehicle, measure,
plan again (``sbmpc run``).

The planner plans with the world's vehicle. A simulated *truth* (by default the same
model; or another vehicle, such as one with a flat tyre, or the extended vehicle that
``sbmpc diagnose`` wrote) executes the plan one planning period at a time over the same
map, with the same closed-loop model stepped at the truth's controller rate (1 kHz for
the P3-AT: a plan that only holds at the search's coarser step is caught), and the
planner's prediction is replayed at the planning vehicle's. After each period the
measured state (pose and drive state: wheel speeds, PID references and integrals,
currents) is compared with the state the plan predicted, and the planner re-plans from
the measured state when

* ``trigger: every``: every ``execute_periods`` periods;
* ``trigger: tolerance``: the position, heading or speed left the tolerance around the
  prediction, or the plan ended short of the goal;
* always: the vehicle stalled (it is then re-planned from where it stopped, at most
  ``max_stalls`` times).

Warm start: a re-plan hands the rest of the previous plan to the search as an
incumbent (:func:`sbmpc.planning.plan.plan`): replayed from the measured state with the
planner's model, when it still reaches the goal its cost bounds the search (no node
that cannot beat it is opened), and it is kept when the search finds nothing cheaper
within the re-plan budget. The cost-to-go grid of the heuristic is computed once per
run (cached per world and cost). The searches themselves are not incremental (no
LPA*): the start moves with the vehicle, which invalidates every g value of an A*
tree rooted at the old start.

The truth's ``delay`` extension (commands reaching the drive late) is executed: the
previous command stays applied for the first ``delay`` seconds of each period. The
planner's search does not model a delay.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from dynamics import kernels as K
from dynamics.params import Vehicle

from .errors import InputError
from .planning import plan as PL
from .planning.horizon import periods
from . import trajectory as TR

from .planning import world as WO
from .problems import skidsteer as SS
from .scenario import RunSettings
from . import truth as TT
from .robot.messages import measured  # noqa: F401
from . import estimate as ES
from .estimate import FIT, Evidence, fit as fit_vehicle
from . import execution as EX
from .execution import (HELD, SETTLED, STUCK_HORIZONS, HorizonStats, Replan, deviation,  # noqa: F401
                        Executor as _Executor, guards as _guards, held as _held, keeps_margin as _keeps_margin,
                        protected as _protected, settles as _settles, stopped as _stopped, weaker as _weaker)


@dataclass
class RunResult:
    """The outcome of a receding-horizon run (docs/formats.md ``sbmpc run`` JSON)."""

    scenario: str
    cost: str
    vehicle: str
    truth: str
    settings: RunSettings
    status: str = "failed"            # reached | failed
    reason: str | None = None
    end: str = "failed"     # reached | stopped (rather than tip over) | no_path | tipped | off_map | timeout | failed
    trajectory: dict = field(default_factory=dict)
    plans: list = field(default_factory=list)        # [Replan], the first plan first
    stalls: int = 0
    periods: int = 0
    guarded: int = 0                  # periods held back: their prediction came within the tip-over margin
    weaker_from: float | None = None  # t [s] from which the margin's twin planned (the vehicle proved weaker)
    planned_as: str | None = None     # the vehicle whose twin planned from then on (as a stall measured it)
    horizon: HorizonStats | None = None   # receding-horizon planning (planner.horizon_s > 0)
    driven: list = field(default_factory=list)    # the controls (wl, wr, duration_s) driven, period by period
    truth_spec: dict = field(default_factory=dict)   # what the truth was drawn as (sbmpc.truth.Truth.spec)
    dropped: int = 0                  # periods whose command was lost (the drive held the previous one)
    inferred: list = field(default_factory=list)     # what each stall said of the vehicle (stall_inference)
    source: dict = field(default_factory=dict)       # how to make the run again (sbmpc run --replay)
    adapted: list = field(default_factory=list)      # when the vehicle was refitted and planned for as measured
    truth_at_end: dict = field(default_factory=dict)  # the true vehicle's pose and drive where the run ended

    @property
    def replans(self) -> int:
        return max(0, len(self.plans) - 1)

    @property
    def planning_time_s(self) -> float:
        return float(sum(r.plan.planning_time_s for r in self.plans))

    @property
    def travel_time_s(self):
        return TR.trajectory_span(self.trajectory, "t")

    @property
    def energy_J(self):
        return TR.trajectory_span(self.trajectory, "energy_J")

    @property
    def length_m(self):
        return TR.trajectory_length(self.trajectory)

    @property
    def predicted(self) -> dict:
        """What the first plan predicted."""
        p = self.plans[0].plan if self.plans else None
        return {"travel_time_s": p.travel_time_s if p else None, "energy_J": p.energy_J if p else None}

    def to_json(self) -> dict:
        pred = self.predicted
        ex = {"travel_time_s": self.travel_time_s, "energy_J": self.energy_J, "length_m": self.length_m}

        def err(k):
            return (ex[k] - pred[k]) / pred[k] if pred[k] and ex[k] is not None else None
        s = self.settings
        return {
            "schema": "sbmpc.run/1",
            "scenario": self.scenario,
            "cost": self.cost,
            "vehicle": self.vehicle,
            "truth": self.truth,
            "status": self.status,
            "end": self.end,
            "reason": self.reason,
            "replans": self.replans,
            "planning_time_s": self.planning_time_s,
            "first_planning_time_s": self.plans[0].plan.planning_time_s if self.plans else None,
            "replan_time_s": [r.plan.planning_time_s for r in self.plans[1:]],
            "travel_time_s": ex["travel_time_s"],
            "energy_J": ex["energy_J"],
            "predicted": pred,
            "executed": ex,
            "prediction_error": {"travel_time": err("travel_time_s"), "energy": err("energy_J")},
            "stalls": self.stalls,
            "periods": self.periods,
            "guarded": self.guarded,
            "weaker_from_t": self.weaker_from,
            "planned_as": self.planned_as,
            "adapted": self.adapted,
            "stall_inference": self.inferred,
            "dropped": self.dropped,
            "truth_spec": self.truth_spec,
            "truth_at_end": self.truth_at_end,
            "replay": self.source,
            "trigger": s.trigger,
            "tolerance": {"xy_m": s.tol_xy, "yaw_deg": s.tol_yaw_deg, "v_m_s": s.tol_v},
            "warm_start": ("re-plans hand the rest of the previous plan to the search as an incumbent "
                           "(branch and bound, kept if nothing cheaper is found); the cost-to-go grid is reused"),
            "plans": [r.to_json() for r in self.plans],
            **({"horizon": self.horizon.to_json()} if self.horizon is not None else {}),
            "trajectory": TR.trajectory_json(self.trajectory),
        }


AIM_MARGIN = 0.1   # m (at most a quarter of the goal radius): a run's re-plans aim this far inside the goal disc
MISSES = 3         # re-plans in a row that find no way on while the vehicle drives on: then it brakes to rest
LOST = {-SS.TIP: "tipped", -SS.OFF_MAP: "off_map"}   # end codes that end a run where the vehicle was lost: its end
MISSED = f"{MISSES} re-plans in a row found no way on from the moving vehicle"    # the re-plan's why, from rest


@functools.lru_cache(maxsize=8)
def _aim(world: WO.World) -> WO.World:
    """The world a run re-plans in: its goal disc shrunk by AIM_MARGIN. A time plan only
    grazes the disc, and a vehicle that drives a little off its plan (a flat tyre) then
    passes just outside it and must be turned back by one more plan (2.4 s more on
    flat.yaml). The first plan aims at the disc itself (it is what ``sbmpc plan``
    reports and the run's prediction), and a re-plan that finds no way into the inner
    disc (a goal on a slope the vehicle barely climbs) is made again for the disc. A
    re-plan is not polished (``planner.polish_energy``): the run drives its first periods
    and re-plans again where the vehicle leaves them, and the polish of a whole route took
    most of a re-plan's time (8.4 of 13.7 s over three of `hills_field`'s). Cached per world
    (worlds hash by identity), so that runs on one world share the inner disc's cost-to-go
    grid and value."""
    g = world.scenario.goal
    m = min(AIM_MARGIN, 0.25 * g["radius"])
    ps = replace(world.scenario.planner, polish_energy=False, polish_time=False)
    return replace(world, scenario=replace(world.scenario, goal=dict(g, radius=g["radius"] - m), planner=ps))


def _weaker_model(world: WO.World, cost: str, out: "RunResult", X: np.ndarray, fitted: dict | None = None,
                  base: WO.World | None = None, key: tuple | None = None, repeats: int = 0) -> tuple:
    """(planning world, its executor, the world it is the twin of) once the run has seen
    the vehicle weaker than the planning one (a stall where its plans drove it, or a
    fresh plan whose first period the twin's guard holds back): the margin's pessimistic
    twin (:func:`sbmpc.planning.world.pessimistic`, :func:`sbmpc.execution.twin_planner`) of the vehicle
    as the periods before a stall measured it (``fitted``: :func:`sbmpc.estimate.fit`;
    without, ``base``: the vehicle as last measured (its factors ``key``), or the planning
    vehicle; with the file's margin, :func:`sbmpc.estimate.at_stall`, grown where a turning
    stall ``repeats`` earlier ones, :func:`sbmpc.execution.grown`) plans from the measured
    state X on, and the run records when (``RunResult.weaker_from``) and as what
    (``planned_as``)."""
    if out.weaker_from is None:
        out.weaker_from = float(X[K.S_T])
    if fitted is not None:
        base = ES.as_measured(world, ES.key(fitted))
    base = EX.grown(ES.at_stall(world, base or world, key or (1.0,) * len(FIT)), world, repeats)
    tw = EX.twin_planner(base)
    out.planned_as = base.vehicle.name
    return tw, _Executor(tw, cost), base


def _named(world: WO.World, planner: WO.World, out: "RunResult", base: WO.World | None = None) -> str:
    """The planning model in a run's messages: the world's vehicle, and from
    ``out.weaker_from`` on the margin's twin (``planner``) of it or of ``base`` (the
    vehicle as measured, :func:`sbmpc.estimate.as_measured`)."""
    if planner is world:
        return world.vehicle.name
    if out.weaker_from is None:          # adapted (run.adapt_periods), no stall yet: the vehicle as measured
        return f"{world.vehicle.name}, then {planner.vehicle.name}"
    of = "" if base is None or base is world else f" of {base.vehicle.name}"
    return (f"{world.vehicle.name}, and from t = {out.weaker_from:.1f} s the margin's twin{of}, "
            f"x{1.0 + (base or world).scenario.planner.margin:g} mass and grip")


def _finish(out: RunResult, pieces: list, every: int, status: str, reason: str | None, end: str | None = None,
            Xt: np.ndarray | None = None) -> RunResult:
    """The run's outcome (``end``: how it ended, default reached or failed), its executed
    trajectory (the recorded pieces, every ``every``-th row and the last) and the true
    vehicle's state Xt where it ended, set on ``out``."""
    out.status, out.reason = status, reason
    out.end = end or ("reached" if status == "reached" else "failed")
    if Xt is not None:
        out.truth_at_end = {"t": float(Xt[K.S_T]), "x": float(Xt[K.S_X]), "y": float(Xt[K.S_Y]),
                            "z": float(Xt[K.S_Z]), "yaw_deg": math.degrees(float(Xt[K.S_YAW])),
                            "wl": float(Xt[K.S_WL]), "wr": float(Xt[K.S_WR]), "i_l": float(Xt[K.S_IL]),
                            "i_r": float(Xt[K.S_IR])}
    rec = np.vstack(pieces) if pieces else np.zeros((0, K.NR))
    idx = np.unique(np.r_[np.arange(0, len(rec), every), len(rec) - 1]) if len(rec) else np.zeros(0, int)
    out.trajectory = {name: rec[idx, i].copy() for i, name in enumerate(K.CHANNELS)}
    return out


def _stalled(out: RunResult, stalls: list, X: np.ndarray, Xt: np.ndarray, real: "_Executor", name: str,
             inferred: dict | None = None) -> str | None:
    """A stall of the true vehicle (its state Xt) at the measured state X: counted and placed; the
    failure reason once there are more than ``run.max_stalls``, else None, with the
    stalled drive restarted from where its wheels are, as a stall protection would: its
    references set to the measured speeds, commands still in the pipe dropped. Left at
    the commands that stalled, the rate limit (ref_accel) keeps the drive saturated for a
    second or more whatever the next plan commands, and every control of a re-plan
    stalls again."""
    out.stalls += 1
    stalls.append((float(X[K.S_X]), float(X[K.S_Y])))
    if EX.past_stall_limit(stalls, X, out.settings):
        return ES.stall_failure(stalls, name, inferred)
    _protected(Xt, real)
    return None


def _true_tilt(truth: TT.Truth, Xt: np.ndarray) -> tuple | None:
    """(pitch, roll) [rad] of the true vehicle on the true ground, as its IMU measures
    them; None off the map."""
    w = truth.world
    if not w.emap.contains(Xt[K.S_X], Xt[K.S_Y]):
        return None
    return w.emap.pitch_roll(float(Xt[K.S_X]), float(Xt[K.S_Y]), float(Xt[K.S_YAW]), w.half_length, w.half_width)


def _attitude(m, truth: TT.Truth, Xt: np.ndarray):
    """A measurement (:class:`sbmpc.robot.Measurement`) with the IMU's pitch and roll."""
    pr = _true_tilt(truth, Xt)
    return m if pr is None else replace(m, pitch=float(pr[0]), roll=float(pr[1]))


def _imu(truth: TT.Truth, world: WO.World, Xt: np.ndarray, X: np.ndarray) -> float:
    """How far the planning map's tilt is off [rad] where the vehicle stands
    (:func:`sbmpc.execution.tilt_error`): the IMU's pitch and roll against the map's at
    the measured pose X."""
    pr = _true_tilt(truth, Xt)
    return 0.0 if pr is None else EX.tilt_error(world, X, *pr)


def _ground(truth: TT.Truth, Xt: np.ndarray) -> str:
    """What the true vehicle met where it ended: its pitch and roll on the true map, its
    drive, and what it was (where it differs from the planning vehicle)."""
    w = truth.world
    pr = _true_tilt(truth, Xt)
    tilt = "" if pr is None else (f"{math.degrees(pr[0]):+.1f} deg pitch, {math.degrees(pr[1]):+.1f} deg roll on "
                                  f"the true ground, ")
    return (f"{tilt}currents {Xt[K.S_IL]:.2f}/{Xt[K.S_IR]:.2f} A of {w.vehicle.current_limit:g}; the true "
            f"vehicle: {truth.name}")


REPLAY_SCHEMA = "sbmpc.run-source/1"


def _source(world: WO.World, cost: str, rs: RunSettings) -> dict:
    """What :func:`replayed` needs to make a run again: the scenario as data (its file's
    folder for the files it names), the planning vehicle's parameters, the cost, the run
    settings. Empty where the scenario holds what JSON cannot (arrays given in code)."""
    import dataclasses
    import json
    from . import scenario as SC
    try:
        scn = replace(world.scenario, run=rs)
        data = SC.to_data(scn)
        v = world.vehicle
        data["vehicle"] = v.name or "vehicle"
        doc = {"schema": REPLAY_SCHEMA, "scenario": data, "scenario_path": str(scn.path) if scn.path else None,
               "vehicle": {f.name: getattr(v, f.name) for f in dataclasses.fields(v) if f.name != "sources"},
               "terrains": [{f.name: getattr(t, f.name) for f in dataclasses.fields(t) if isinstance(getattr(t, f.name), float)}
                            for t in world.terrains],
               "cost": cost}
        json.dumps(doc, allow_nan=False)
        return doc
    except (TypeError, ValueError):
        return {}


def replayed(doc: dict, where: str) -> tuple:
    """(world, cost, truth) of a run JSON (``sbmpc run --json``) made again: its scenario,
    planning vehicle, cost and settings, and the truth it met (:func:`sbmpc.truth.from_spec`).
    ``where`` names the file in errors."""
    from pathlib import Path
    from dynamics.params import Vehicle
    from . import scenario as SC
    src = doc.get("replay") if isinstance(doc, dict) else None
    if not isinstance(src, dict) or src.get("schema") != REPLAY_SCHEMA:
        found = "no 'replay' section" if not src else f"replay.schema {src.get('schema')!r}"
        raise InputError(f"{where}: expected a run JSON of sbmpc run --json with a replay section (schema "
                         f"{REPLAY_SCHEMA}), found {found}")
    if not (isinstance(src.get("scenario"), dict) and isinstance(src.get("vehicle"), dict)
            and src.get("cost") in ("time", "energy") and isinstance(src.get("scenario_path") or "", str)):
        raise InputError(f"{where}: replay: expected scenario (a mapping), scenario_path (a path or null), vehicle "
                         f"(a mapping) and cost (time or energy), found {sorted(src)}")
    path = Path(src["scenario_path"]) if src.get("scenario_path") else None
    scn = SC.parse(src["scenario"], f"{where} (replay.scenario)", path)
    try:
        vehicle = Vehicle().replace(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in src["vehicle"].items()})
        world = WO.resolve(replace(scn, vehicle=vehicle))
        ts = src.get("terrains") or [{}] * len(world.terrains)
        if len(ts) == len(world.terrains):       # (a sweep variant's terrain changes)
            world = replace(world, terrains=tuple(t.replace(**d) for t, d in zip(world.terrains, ts)))
        return world, src["cost"], TT.from_spec(world, doc.get("truth_spec") or {})
    except InputError:
        raise
    except Exception as exc:
        raise InputError(f"{where}: replay: {' '.join(str(exc).replace('<replace>: ', '').split())[:300]}") from None


def run(world: WO.World, cost: str | None = None, truth: "Vehicle | TT.Truth | None" = None,
        settings: RunSettings | None = None, progress=None, warm: bool = True,
        truth_grip: float | None = None, wall_limit_s: float | None = None) -> RunResult:
    """Execute the scenario of ``world`` with receding-horizon SBMPC (module doc).

    ``truth``: the vehicle that really drives: a Vehicle (default: the world's own), or a
    :class:`sbmpc.truth.Truth` (a drawn vehicle, map errors, odometry error, command delay,
    dropped commands); ``settings`` default to the scenario's ``run`` section;
    ``progress(label)`` may return a search progress callback; ``warm=False`` plans every
    re-plan from scratch (for the benchmark); ``truth_grip``: the true ground's mu_sa and
    mu_op are the world's terrains' times this factor (with a Vehicle); ``wall_limit_s``:
    the run fails once it has taken this long on the wall clock (checked every period)."""
    import time
    cost = WO.checked_cost(world, cost)
    if not isinstance(truth, TT.Truth):
        truth = TT.nominal(world, WO.checked_vehicle(truth, "truth"), truth_grip)
    rs = settings or world.scenario.run
    ps = world.scenario.planner
    twin = truth.world
    out = RunResult(world.scenario.name, cost, world.vehicle.name, truth.name, rs, truth_spec=truth.spec,
                    source=_source(world, cost, rs))
    deadline = time.perf_counter() + wall_limit_s if wall_limit_s else math.inf
    if ps.horizon_s > 0.0:
        return _run_horizon(world, cost, truth, out, deadline)
    model = _Executor(world, cost)
    nominal = _Executor(world, cost)   # the planning vehicle's one-period predictions (a stall's evidence)
    guards = _guards(world, cost)
    planner = world                    # the planning model: the world's vehicle, its margin's twin after a stall
    base = world                       # ... the twin of this: the world's vehicle, or as a stall measured it
    as_twin = False                    # the margin's twin of ``base`` plans (the vehicle proved weaker)
    since_fit = 0                      # periods driven since the vehicle was last fitted (run.adapt_periods)
    base_key = (1.0,) * len(FIT)       # the factors of ``base`` on the world's vehicle
    guarded = False                    # the last plan's first period was held back by the guard
    real = _Executor(twin, cost, twin.vehicle.delay)
    odo, drop = truth.odometer(), truth.dropper()
    Xt = WO.start_state(twin)          # the true state
    X = odo.observe(Xt)                # the measured state
    tilt = _imu(truth, world, Xt, X)   # how far the map's tilt is off where it stands (the guard's)
    evidence = Evidence()              # what the periods driven say of the vehicle (a stall's inference)
    pieces = []
    every = max(1, round(TR.RECORD_EVERY / real.dt))
    tol_yaw = math.radians(rs.tol_yaw_deg)
    why = "start"
    current, steps, k, P, since = None, [], 0, None, 0
    t_limit = math.inf
    limit_for = (world, False)         # the planning model (base, as_twin) the time limit was set for
    stalls = []
    marks: list = []                   # slopes a second stall marked impassable for the re-plans (execution.marked)
    driven: list = []                  # the periods driven, in order
    retraced = 0                       # retraces made (EX.RETRACE_PERIODS)
    backing: list = []                 # periods of a retrace still to drive
    misses = 0                         # re-plans in a row that found no way on while the vehicle drove on

    def finish(status, reason, end=None):
        nonlocal Xt
        out.dropped = drop.count
        Xt, status, reason, end = _at_rest(real, Xt, drop, ps.period_s, pieces, status, reason, end)
        return _finish(out, pieces, every, status, reason, end, Xt)

    def drive(control, predicted=None) -> int:
        """One period of the true vehicle (its command lost, at times: the drive holds the
        last): the true state Xt advanced, X measured, the period recorded and counted,
        with ``predicted`` (the planning model's record of it) the evidence of the stall
        inference. Returns its end code."""
        nonlocal X, Xt, tilt
        X0 = X.copy()
        applied = drop.applied(Xt, control)
        rec, end, Xt = real.step(Xt, applied)
        pieces.append(rec if not pieces else rec[1:])
        out.periods += 1
        odo.advance(Xt)
        X = odo.observe(Xt)
        tilt = _imu(truth, world, Xt, X)
        if predicted is not None and end != -SS.STALL and applied is control:   # (a lost command: no evidence)
            evidence.add(rec, predicted, X0, control)
        return end

    def ended(end: int, doing: str = ""):
        """The run's result where the period just driven ended it: in the goal, stalled
        once too often (_stalled), tipped over or off the map (``doing``: what it was
        doing, for the reason); else None (a stall is counted)."""
        nonlocal X
        if end == SS.IN_GOAL:
            return finish("reached", None)
        if end == -SS.STALL:
            out.inferred.append(evidence.infer(X))
            failed = _stalled(out, stalls, X, Xt, real, _named(world, planner, out, base), out.inferred[-1])
            X = odo.observe(Xt)
            return finish("failed", f"{failed} ({_ground(truth, Xt)})") if failed else None
        if end < 0:
            return finish("failed", f"the vehicle {SS.CODES[-end - 1]} at ({Xt[K.S_X]:.2f}, {Xt[K.S_Y]:.2f}), "
                                    f"t = {Xt[K.S_T]:.1f} s{doing} ({_ground(truth, Xt)})",
                          LOST.get(end, "failed"))
        return None

    def brake(after: str = "the guard held its period back"):
        """One period with the wheels commanded to rest, driven from X: the guard held
        back a moving vehicle's period (or ``after`` says what else), and a robot that
        waits for a plan brakes (a run that stopped the clock instead re-planned, and
        stopped, from a state the vehicle could not hold). The run's result where the
        period ended it, else None."""
        where = f"({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})"
        return ended(drive((0.0, 0.0, ps.period_s)), f", braking after {after} at {where}")

    def retrace() -> bool:
        """Before a held run stops: the next of RETRACE_PERIODS that the guards let it
        drive back along the way it came (then it re-plans from there)."""
        nonlocal retraced, backing, why, guarded
        if len(out.plans) > rs.max_replans:
            return False
        back, retraced = EX.back_along(guards, X, driven, retraced, tilt)
        if back is None:
            return False
        backing = back
        guarded = False                        # a fresh place: its first hold gets a re-plan
        why = (f"{HELD} at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}), and no way on from there: {len(back) - 1} periods "
               "driven back")
        return True

    while True:
        if time.perf_counter() > deadline:
            return finish("failed", f"wall-clock limit of {wall_limit_s:g} s reached at t = {X[K.S_T]:.1f} s, "
                                    f"({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}), after {len(out.plans)} plans", "timeout")
        if backing:
            # driving back along the way it came (retrace), each period guarded from the
            # measured state before it is driven
            control = backing.pop(0)
            if _held(guards, X, control, True, tilt):
                if not EX.moving(X):
                    return finish("failed", _stopped(X, ps), "stopped")
                backing = []
                why = f"{HELD} at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})"
                result = brake()
                if result is not None:
                    return result
                continue
            end = drive(control)
            result = ended(end, ", driving back along the way it came")
            if result is not None:
                return result
            if end == -SS.STALL:
                backing = []                   # it cannot back up here: re-plan from there (why is set)
            continue
        if why is not None:
            if len(out.plans) > rs.max_replans:
                return finish("failed", f"re-plan limit of {rs.max_replans} reached ({why} at "
                                        f"t = {X[K.S_T]:.1f} s)")
            first = not out.plans
            tail = steps[k:] if (current is not None and warm) else None
            label = "first plan" if first else f"re-plan {len(out.plans)}"
            # a re-plan the vehicle waits for (it stalled, or the guard held its period back)
            # has a budget of its own; after the guard, the plan keeps the tip-over margin
            held = why.startswith(HELD)
            # no plan to drive on while this one is made: stalled, or the plan ran out
            stranded = why.startswith("stalled") or not (current is not None and k < len(steps))
            budget = (None if first else rs.stall_replan_time_budget_s
                      if why.startswith(("stalled", MISSED)) or held else rs.replan_time_budget_s)
            model_world = EX.twin_planner(base, tip=True) if held and as_twin else planner
            clear = world.margin + world.emap.resolution      # (a mark at the start leaves no plan)
            near = tuple(m for m in marks if math.hypot(m[0] - X[K.S_X], m[1] - X[K.S_Y]) > m[2] + clear)
            if near:
                model_world = EX.marked(model_world, near)
            # re-plans aim inside the goal disc, in half the re-plan budget; where nothing
            # reaches the inner disc, at the disc itself in what is left of it
            target = model_world if first else _aim(model_world)
            # the first plan is sbmpc plan's (an energy plan checked against the time plan);
            # a re-plan is the search's alone (it must come quickly, and holds the rest of
            # the checked plan as its incumbent when warm)
            common = dict(progress=progress(label) if progress else None, start=X, incumbent=tail)
            if first:
                p = PL.plan(target, cost, time_budget_s=budget, **common,
                            time_progress=progress(f"{label}, time search (the energy plan is checked against it)")
                            if progress and cost == "energy" else None)
            else:
                p = PL.search_plan(target, cost, time_budget_s=0.5 * budget, **common)
                if not p.found and stranded and not held and PL.margin_on(target.scenario.planner):
                    # stalled where plans with a tip-over margin or turn reserve (and no twin:
                    # with one, the twin plans after a stall, keeping none) drove it: the
                    # vehicle needs all of its drive to get away (search_plan falls back by
                    # itself only where the margin's search ends early); likewise where the
                    # plan ended short of the goal and no plan is left to drive on
                    bare = PL.search_plan(WO.without_margin(target), cost, start=X, incumbent=tail,
                                          progress=progress(f"{label}, without the margin") if progress else None,
                                          time_budget_s=max(budget - p.planning_time_s, 0.25 * budget))
                    if bare.found:
                        bare = replace(bare, margin=dict(bare.margin or {}, kept=False,
                                                         note=f"no plan from ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}) keeps the margin ({p.reason})"))
                    p = PL.counting(bare, p)
            aimed = target.scenario.goal["radius"]
            if not p.found and not first:
                inner, aimed = p, world.scenario.goal["radius"]
                again = PL.search_plan(model_world, cost, progress=progress(f"{label}, the disc itself") if progress else None,
                                       start=X, incumbent=tail,
                                       time_budget_s=max(budget - inner.planning_time_s, 0.5 * budget))
                p = PL.counting(again, inner)      # both searches count
            out.plans.append(Replan(float(X[K.S_T]), float(X[K.S_X]), float(X[K.S_Y]), why, p, bool(tail), aimed))
            if p.found:
                if first:
                    t_limit = rs.max_time_factor * p.travel_time_s + 30.0
                elif (base, as_twin) != limit_for:
                    # the first plan of a new planning model (the vehicle as measured): the
                    # time limit as for a first plan of it, from here
                    t_limit = max(t_limit, X[K.S_T] - out.plans[0].t + rs.max_time_factor * p.travel_time_s + 30.0)
                limit_for = (base, as_twin)
                current, k, P, since, why, misses = p, 0, X.copy(), 0, None, 0
                steps = periods(p.controls, ps.period_s)
            elif not stranded and not held:
                misses += 1
                if misses < MISSES:
                    # like any MPC: when a re-plan fails, keep driving the previous plan and
                    # try again after the next period (not a period the guard held back)
                    why = None
                else:
                    # MISSES re-plans in a row found no way on from the moving vehicle while
                    # it drove on a plan it is off: it brakes to rest and plans from there, as
                    # a vehicle with no plan left, with the budget of a re-plan the vehicle
                    # waits for (the search without the margin after the margin's, and a stop
                    # that says why where neither finds a way). Driving on, a hills_field run
                    # drifted 7 m and 40 deg off its plan through 25 failed re-plans of 10 s
                    # each and ran out of its wall-clock limit (2026-12-07)
                    result = brake(MISSED)
                    if result is not None:
                        return result
                    current, misses = None, 0
                    why = f"{MISSED}: braked to rest at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})"
                    continue
            elif held:
                if retrace():
                    continue
                if not EX.moving(X):
                    return finish("failed", _stopped(X, ps, ("re-plan", p.reason)), "stopped")
                # (driven back, or braked short: the plan from where it comes to rest)
                result = brake()
                if result is not None:
                    return result
                continue
            else:
                # stalled, and no way on from here: drive back along the way it came and
                # re-plan from there (as after the guard), where the guard lets it
                if stalls and not first and retrace():
                    why = why.replace(HELD, "stalled with no way on", 1)   # (not the guard's: no stop on its failure)
                    continue
                # after stalls where the plans drove it, and from where none is seen now
                weaker = (f"; {ES.stall_failure(stalls, _named(world, planner, out, base), out.inferred[-1])}"
                          if stalls else "")
                return finish("failed", f"no path from ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}) at t = {X[K.S_T]:.1f} s "
                                        f"({why}): {p.reason}{weaker}", "no_path")
        control = steps[k]
        if k == len(steps) - 1:
            # the last control was cut where the prediction entered the goal: hold it
            # for a full period (the rollout stops in the goal)
            control = (control[0], control[1], max(control[2], ps.period_s))
        if guards:
            # safety: a period whose prediction from the measured state comes within the
            # tip-over margin is not driven; the vehicle re-plans from where it stands
            # (and stops for good where the fresh plan's first period is held back too)
            # (once the twin plans, the planning vehicle's prediction is of a vehicle the run
            # has seen it is not: it holds a period back only where it would tip over)
            kept = (current is None or _keeps_margin(current)) and not as_twin
            who = EX.holder(guards, X, control, kept, tilt)
            if who:
                if guarded and since == 0 and not as_twin and ps.margin > 0.0 and who != 3:
                    # the fresh plan's first period is held back too: its model is wrong here
                    # (the guard's twin predicts what the plan does not); plan with the twin
                    planner, model, base = _weaker_model(world, cost, out, X, None, base, base_key)
                    as_twin = True
                elif guarded and since == 0:
                    if retrace():
                        out.guarded += 1
                        continue
                    if not EX.moving(X):
                        return finish("failed", _stopped(X, ps), "stopped")
                guarded = True
                out.guarded += 1
                why = f"{HELD} at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})"
                if EX.moving(X):
                    # the plan from where it comes to rest (a moving vehicle cannot wait)
                    result = brake()
                    if result is not None:
                        return result
                continue
        guarded = False
        _, _, P = model.step(P, control, record=False)
        # the evidence of a stall's inference: the period predicted by the planning vehicle
        # from the measured state (one period: no drift; the same reference all run long)
        predicted, _, _ = nominal.step(X, control)
        end = drive(control, predicted)
        driven.append(control)
        k += 1
        since += 1
        result = ended(end)
        if result is not None:
            return result
        if end == -SS.STALL:
            said = out.inferred[-1]["inferred"]
            fitted = fit_vehicle(evidence, world, cost) if ps.margin > 0.0 else None
            out.inferred[-1]["fit"] = fitted
            repeats = EX.twin_grows(stalls, X, (X[K.S_IL], X[K.S_IR]), world.vehicle) if ps.margin > 0.0 else 0
            if ps.margin > 0.0 and (fitted is not None or repeats or (not as_twin and said != "stronger")):
                # stalled where the plans drove it: from here on the margin's twin of the
                # vehicle as the periods before the stall measured it (the online fit; a
                # vehicle measured lighter or stronger gets a twin no heavier than it needs);
                # without periods to fit (a stall in a fresh plan's first periods), of the
                # planning vehicle, unless the run has already measured it
                planner, model, base = _weaker_model(world, cost, out, X, fitted, base, base_key, repeats)
                as_twin = True
                if fitted is not None:
                    base_key = ES.key(fitted)
            out.inferred[-1]["twin_margin"] = base.scenario.planner.margin if as_twin else None
            why = f"stalled at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})"
            if ps.margin > 0.0 and EX.marks_wall(stalls, X, (X[K.S_IL], X[K.S_IR]), world.vehicle):
                # stalled again where it stalled before, with the plans of the vehicle as
                # measured: the slope ahead is steeper than the map says (or the vehicle weaker
                # there than measured); the re-plans keep off it
                marks.append(EX.ahead(world, X, control))
                why += f", again: the slope ahead at ({marks[-1][0]:.2f}, {marks[-1][1]:.2f}) is kept off"
        elif X[K.S_T] - out.plans[0].t > t_limit:
            behind = [r for r in out.plans[1:] if "off by" in r.why or r.why.startswith("stalled")]
            tail = ""
            if len(behind) >= 3:
                xs = np.median([r.x for r in behind])
                ys = np.median([r.y for r in behind])
                tail = (f": {len(behind)} re-plans after it fell behind its plans or stalled, around "
                        f"({xs:.2f}, {ys:.2f}); the vehicle is weaker there than the planning model "
                        f"({_named(world, planner, out, base)}); plan with a model of this vehicle (sbmpc diagnose on a "
                        f"run of it writes one)")
            return finish("failed", f"took longer than {t_limit:.0f} s ({rs.max_time_factor:g} x the first "
                                    f"plan's travel time + 30 s) without reaching the goal{tail}")
        elif k >= len(steps):
            why = "the plan ended short of the goal"
        elif rs.trigger == "every":
            if since >= rs.execute_periods:
                why = f"every {rs.execute_periods} period(s)"
        else:
            dxy, dyaw, dv = deviation(X, P)
            off = [f"position off by {dxy:.2f} m"] if dxy > rs.tol_xy else []
            off += [f"heading off by {math.degrees(dyaw):.1f} deg"] if dyaw > tol_yaw else []
            off += [f"speed off by {dv:.2f} m/s"] if dv > rs.tol_v else []
            if off:
                why = ", ".join(off)
        if rs.adapt_periods and end != -SS.STALL:
            since_fit += 1
            if since_fit >= rs.adapt_periods:
                # adaptation: the vehicle refitted from the periods driven; where the fit is
                # confident and says another vehicle than the one planned for, re-plan as it
                since_fit = 0
                f = fit_vehicle(evidence, world, cost)
                now = ES.adapts(world, f, (base_key, base.scenario.planner.margin), ES.firms(rs, bool(stalls), as_twin))
                if now is not None:         # another vehicle, or margin, than planned for
                    base, base_key = now, ES.key(f)
                    planner = EX.twin_planner(base) if as_twin else base
                    model = _Executor(planner, cost)
                    out.planned_as = base.vehicle.name
                    out.adapted.append({"t": round(float(X[K.S_T]), 3), "fit": f, "margin": base.scenario.planner.margin})
                    why = (why + "; " if why else "") + f"adapted: {base.vehicle.name}"
        if why is None:
            misses = 0          # a period that asked for no re-plan: a next failed one starts a new row


def _run_horizon(world: WO.World, cost: str, truth: TT.Truth, out: RunResult, deadline: float) -> RunResult:
    """:func:`run` with receding-horizon plans (``planner.horizon_s``): the controller a
    robot calls (:class:`sbmpc.robot.Controller`, its policy in its module doc) against
    the simulated truth. Every ``run.control_period_s`` the truth's state is measured
    (pose, wheel speeds, currents: :func:`measured`), the controller answers with wheel
    speeds, and the truth drives them for that period at its controller rate. The
    controller waits for its plans (``lockstep``: the simulated clock stands still while
    it plans); every plan's wall-clock time is kept (``horizon`` in the run JSON). The
    truth's stall protection restarts a stalled drive (:func:`_protected`) and tells the
    controller (``Measurement.stalled``). The truth's odometry error is in the measured
    pose, and a dropped command leaves the drive at the last it received."""
    import time
    from .robot.controller import Controller
    rs = out.settings
    twin = truth.world
    ctrl = Controller(world, cost, period_s=rs.control_period_s, lockstep=True, settings=rs)
    out.horizon = ctrl.horizon
    real = _Executor(twin, cost, twin.vehicle.delay)
    odo, drop = truth.odometer(), truth.dropper()
    X = WO.start_state(twin)
    pieces = []
    every = max(1, round(TR.RECORD_EVERY / real.dt))
    g = world.scenario.goal
    # no whole-route plan to scale from: the straight line at a third of the top speed
    v_top = world.vehicle.v_max / world.vehicle.torque_constant * world.vehicle.wheel_radius
    t_limit = rs.max_time_factor * 3.0 * math.hypot(g["x"] - X[K.S_X], g["y"] - X[K.S_Y]) / max(v_top, 1e-6) + 30.0
    stalled = False

    def finish(status, reason, end=None):
        nonlocal X
        X, status, reason, end = _at_rest(real, X, drop, ctrl.period_s, pieces, status, reason, end)
        ctrl.ended_at(float(X[K.S_T]))
        ctrl.close()
        out.plans, out.guarded, out.stalls = ctrl.plans, ctrl.guarded, ctrl.stalls
        out.inferred, out.adapted = ctrl.inferred, ctrl.adapted
        if ctrl.planned_as is not None:
            out.planned_as, out.weaker_from = ctrl.planned_as, ctrl.weaker_from
        out.periods, out.driven, out.dropped = ctrl.periods, ctrl.driven, drop.count
        if end is None and status != "reached":
            end = ("stopped" if (reason or "").startswith("stopped at") else
                   "no_path" if (reason or "").startswith(("no way on", "no path")) else None)
        return _finish(out, pieces, every, status, reason, end, X)

    while True:
        if time.perf_counter() > deadline:
            return finish("failed", f"wall-clock limit reached at t = {X[K.S_T]:.1f} s, "
                                    f"({X[K.S_X]:.2f}, {X[K.S_Y]:.2f})", "timeout")
        cmd = ctrl.step(float(X[K.S_T]), _attitude(measured(odo.observe(X), twin.vehicle, stalled), truth, X))
        if cmd.done:
            return finish("reached" if cmd.status == "reached" else "failed", cmd.reason)
        rec, end, X = real.step(X, drop.applied(X, (cmd.wl, cmd.wr, ctrl.period_s)))
        pieces.append(rec if not pieces else rec[1:])
        odo.advance(X)
        stalled = end == -SS.STALL
        if end == SS.IN_GOAL:
            return finish("reached", None)
        if X[K.S_T] > t_limit:
            return finish("failed", f"took longer than {t_limit:.0f} s without reaching the goal")
        if stalled:
            _protected(X, real)
        elif end < 0:
            return finish("failed", f"the vehicle {SS.CODES[-end - 1]} at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}), "
                                    f"t = {X[K.S_T]:.1f} s", LOST.get(end))


REST_LIMIT_S = 60.0   # s: how long a vehicle the controller stopped is followed braking to rest (_to_rest)


def _to_rest(real: "_Executor", X: np.ndarray, drop, period_s: float, pieces: list) -> tuple:
    """The truth at X driven with its wheels commanded to rest (what a stopped
    controller commands), period by period, until it comes to rest (no wheel faster than
    ``execution.MOVING``), tips over, leaves the map or REST_LIMIT_S has passed; the
    recorded rows appended to ``pieces``. Returns (state, end code of the last period)."""
    end, t_end = 0, X[K.S_T] + REST_LIMIT_S
    while EX.moving(X) and X[K.S_T] < t_end:
        rec, end, X = real.step(X, drop.applied(X, (0.0, 0.0, period_s)))
        pieces.append(rec if not pieces else rec[1:])
        if end == -SS.STALL:
            _protected(X, real)
        elif end != 0:
            break
    return X, end


def _at_rest(real: "_Executor", X: np.ndarray, drop, period_s: float, pieces: list, status: str,
             reason: str | None, end: str | None) -> tuple:
    """A run that ends short of the goal with the truth still moving (the controller
    stopped a vehicle it could not brake to rest, a descent steeper than its drive holds;
    a last stall rolling back) ends where the truth comes to rest at the command it is
    left with, the wheels at rest (:func:`_to_rest`), or where it tips over or leaves the
    map on the way: (state, status, reason, end) for the run's finish (both kinds of run
    call it); as they are where the run reached the goal, tipped over or left the map."""
    if (status == "reached" or end in LOST.values() or not EX.moving(X) or end == "timeout"
            or (reason or "").startswith("the controller stopped:")):
        return X, status, reason, end       # (a run out of its wall clock, or an error: as it ended)
    X0, (X, code) = X, _to_rest(real, X, drop, period_s, pieces)
    if code < 0 and code != -SS.STALL:
        return X, "failed", (f"the vehicle {SS.CODES[-code - 1]} at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}), "
                             f"t = {X[K.S_T]:.1f} s, braking after the run ended: {reason}"), \
            LOST.get(code)
    return X, status, f"{reason}{_rolled(X0, X, code)}", end


def _rolled(X0: np.ndarray, X: np.ndarray, code: int = 0) -> str:
    """What a reason adds where a stopped vehicle rolled on from X0 to X (:func:`_to_rest`,
    whose last end ``code`` says whether it rolled into the goal disc)."""
    d = math.hypot(X[K.S_X] - X0[K.S_X], X[K.S_Y] - X0[K.S_Y])
    at = f"{d:.2f} m on, at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}), t = {X[K.S_T]:.1f} s"
    if code == SS.IN_GOAL:
        return f"; the vehicle, moving when it stopped, rolled on into the goal disc {at}"
    if EX.moving(X):
        return f"; the vehicle, moving when it stopped, was still moving {REST_LIMIT_S:g} s later, {at}"
    return f"; the vehicle, moving when it stopped, came to rest {at}" if d > 0.01 else ""


def horizon_plan(world: WO.World, cost: str | None = None) -> PL.Plan:
    """``sbmpc plan --horizon`` and ``compare --horizon``: the receding-horizon run of
    ``world`` (``planner.horizon_s`` > 0) driven by the planning vehicle itself, at its
    controller rate, reported as a plan: its controls are those driven period by
    period, its trajectory the drive, its planning time that of every plan made
    (``found_by`` gives the plans' count and latencies)."""
    cost = WO.checked_cost(world, cost)
    res = run(world, cost)
    hz = res.horizon.to_json()
    n = sum(r.plan.nodes_expanded for r in res.plans)
    by = (f"receding horizon: {hz['plans']} plans {hz['horizon_s']:g} s ahead (first {hz['first_s'] * 1e3:.0f} ms, "
          f"95th percentile {hz['replan_p95_s'] * 1e3:.0f} ms)"
          + (f", {hz['fallbacks']} whole-route plans where the horizon saw no way on" if hz["fallbacks"] else ""))
    if res.status != "reached":
        return PL.Plan(world.scenario.name, cost, "no_path", res.reason, planning_time_s=res.planning_time_s,
                       nodes_expanded=n, found_by=by, failure="exhausted")
    return PL.Plan(world.scenario.name, cost, "found", None, list(res.driven), res.trajectory,
                   planning_time_s=res.planning_time_s, nodes_expanded=n, found_by=by)
