"""Executing controls on a world, and the pieces every run shares (``sbmpc run``'s
whole-route loop in :mod:`sbmpc.receding`, the robot's controller in :mod:`sbmpc.robot`):

* :class:`Executor`: a world's closed-loop model stepped through controls at its
  vehicle's controller rate (the paper's 1 kHz), with the vehicle's command delay;
* the guard of a run's periods (:func:`guards`, :func:`held`, :func:`stopped`): no period
  whose 1 kHz prediction comes within half the tip-over margin or leaves the map;
* what a run records of its plans (:class:`Replan`, :class:`HorizonStats`), how far a
  measured state is off a predicted one (:func:`deviation`), a saturated drive to settle
  (:func:`settles`), a stalled drive restarted (:func:`protected`).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from dynamics import kernels as K

from .planning import plan as PL
from .planning import problem as PB
from .planning import world as WO
from .problems import skidsteer as SS


@dataclass
class Replan:
    """One plan of a run: when and why it was made, what it predicted."""

    t: float                 # run time at which it was made [s]
    x: float
    y: float
    why: str
    plan: PL.Plan
    warm: bool               # an incumbent (the rest of the previous plan) was handed to the search
    goal_radius: float       # the radius of the goal disc the plan aimed at [m] (re-plans: AIM_MARGIN inside)

    def to_json(self) -> dict:
        p = self.plan
        return {"t": self.t, "x": self.x, "y": self.y, "why": self.why, "status": p.status, "reason": p.reason, "failure": p.failure,
                "planning_time_s": p.planning_time_s, "nodes_expanded": p.nodes_expanded,
                "predicted_travel_time_s": p.travel_time_s, "predicted_energy_J": p.energy_J,
                "controls": len(p.controls), "warm_start": self.warm, "goal_radius_m": self.goal_radius,
                "found_by": p.found_by or ("search" if p.found else None), "rival": p.rival}


@dataclass
class HorizonStats:
    """The horizon plans of a receding-horizon run (``planner.horizon_s``): how long each
    took [s], how many the search made and how many kept the previous plan, why the run
    re-planned from the measured state instead of the predicted one, how often the wheels
    were held at rest for a period before a plan was made again (``settled``)."""

    horizon_s: float
    seconds: list = field(default_factory=list)
    expansions: list = field(default_factory=list)
    kept_previous: int = 0
    from_measured: int = 0
    fallbacks: int = 0
    fallback_s: list = field(default_factory=list)
    settled: int = 0
    rejoined: int = 0        # hand-overs onto the whole-route plan made beside (planning.rejoin)
    shortened: int = 0       # held periods driven in part from rest (shortened)
    beside_s: list = field(default_factory=list)    # per plan made beside taken up: robot time [s] from asking to taking it up

    def to_json(self) -> dict:
        s = np.array(self.seconds) if self.seconds else np.zeros(1)
        later = s[1:] if len(s) > 1 else s
        return {"horizon_s": self.horizon_s, "plans": len(self.seconds),
                "first_s": float(s[0]), "replan_median_s": float(np.median(later)),
                "replan_p95_s": float(np.percentile(later, 95)), "replan_max_s": float(later.max()),
                "expansions_median": float(np.median(self.expansions)) if self.expansions else 0.0,
                "kept_previous": self.kept_previous, "from_measured": self.from_measured,
                "fallbacks": self.fallbacks, "fallback_s": [round(x, 4) for x in self.fallback_s],
                "settled": self.settled, "rejoined": self.rejoined, "shortened": self.shortened,
                "beside_made": len(self.beside_s),
                "beside_median_s": float(np.median(self.beside_s)) if self.beside_s else 0.0}



def deviation(X: np.ndarray, P: np.ndarray) -> tuple:
    """(position [m], heading [rad], speed [m/s]) differences of a measured state X from
    a predicted state P (planner states, :mod:`sbmpc.problems.skidsteer`)."""
    dxy = math.hypot(X[K.S_X] - P[K.S_X], X[K.S_Y] - P[K.S_Y])
    dyaw = abs(math.remainder(X[K.S_YAW] - P[K.S_YAW], 2.0 * math.pi))
    dv = abs(X[SS.X_V] - P[SS.X_V])
    return dxy, dyaw, dv


FASTEST = 3.0        # the guard's fastest twin: battery voltage times 1 + FASTEST x planner.margin
# m: a prediction that closes in on the map's edge (by more than CLOSING) and comes to
# rest within this of it holds its period back: issue 62's hills_field horizon run with
# 13 % less voltage ended a period 3 cm beyond where every one of the guard's predictions
# did, 0.09 m from the east edge at 0.6 m/s, and braking from there left the map
# (the predictions' braking had stopped 4 cm inside it), 2026-12-07
EDGE_CLEARANCE = 0.15
CLOSING = 0.01
STANDING = math.radians(0.1)   # rad: how much steeper than where it stands a period from inside the guard's band may go (holder)
RUN_ON = 0.05       # m: how much further than a guard's prediction a truth may come to rest (holder, _runs_on)


def guard_aside(world: WO.World) -> float:
    """How far [m] to either side of a prediction's pose the guard judges its band: half
    the planner's allowance (``planner.margin_aside_m``), as its band is half the
    planner's tip-over margin."""
    return 0.5 * world.scenario.planner.margin_aside_m


class Executor:
    """Steps one world's closed-loop model through controls, period by period, at its
    vehicle's controller period (the paper's 1 kHz digital PID). ``delay_s``: the
    vehicle's command delay: each command reaches the wheel loops that much later (the
    commands issued still in the pipe are kept across periods, so a delay longer than a
    period is executed in full; before the first command arrives the loops hold the
    start state's wheel-speed references: a vehicle that starts at speed keeps it)."""

    def __init__(self, world: WO.World, cost: str, delay_s: float = 0.0, tip_guard: bool = False):
        self.dt = 1.0 / world.vehicle.controller_rate
        self.Q, self.data = PB.pack_world(world, cost, self.dt, grid=False)
        if tip_guard:
            # half the tip-over margin alone (planner.margin_tip_deg): the guard of a run's
            # periods. Half: a plan keeps the whole margin at the planner's step, and its
            # 1 kHz drive may graze it (with the whole, hills_field's energy run held back
            # its own fresh plans' periods 50 times)
            ps = world.scenario.planner
            self.Q[SS.Q_TIPM] = math.radians(ps.tip_over_deg - 0.5 * ps.margin_tip_deg)
            # and half its allowance aside (planner.margin_aside_m): a truth that drifted
            # off its plan's pose by less than the other half is not held back for it
            self.Q[SS.Q_ASIDE] = guard_aside(world)
        self.world = world
        self.lag = int(round(delay_s / self.dt))
        self.pipe = None            # [[wl, wr, steps]]: commands issued, not yet applied

    def _applied(self, X: np.ndarray, wl: float, wr: float, n: int) -> list:
        """The commands [[wl, wr, steps]] that reach the loops over the next n steps."""
        if self.pipe is None:
            self.pipe = [[float(X[K.S_REFL]), float(X[K.S_REFR]), self.lag]]
        self.pipe.append([wl, wr, n])
        out, need = [], n
        while need > 0:
            seg = self.pipe[0]
            take = min(seg[2], need)
            if take > 0:
                out.append([seg[0], seg[1], take])
            seg[2] -= take
            need -= take
            if seg[2] == 0:
                self.pipe.pop(0)
        return out

    def step(self, X: np.ndarray, control, record: bool = True, tilt_error: float = 0.0,
             floor: float = 0.0) -> tuple:
        """Apply (wl, wr, duration_s) from state X. Returns (recorded rows (n, NR) from X
        on, end code, new state). ``tilt_error`` [rad]: the tip-over limit and margin
        taken that much lower (a guard's prediction on a map whose tilt is off by it).
        ``floor`` [rad]: the margin's limit taken no lower than this (a guard's prediction
        from a state already inside the margin: :func:`holder`)."""
        wl, wr, d = control
        Q = self.Q
        if tilt_error > 0.0 or floor > Q[SS.Q_TIPM]:
            Q = Q.copy()
            Q[SS.Q_TIP] -= tilt_error
            Q[SS.Q_TIPM] = max(Q[SS.Q_TIPM] - tilt_error, floor)
        n = max(1, int(round(d / self.dt)))
        segs = self._applied(X, wl, wr, n) if self.lag > 0 else [[wl, wr, n]]
        rec = np.zeros((n + 1 if record else 1, K.NR))
        rows, S, end, _ = SS.replay(Q, self.data, np.ascontiguousarray(X), np.array([g[0] for g in segs], float),
                                    np.array([g[1] for g in segs], float), np.array([g[2] for g in segs], np.int64), rec)
        if self.lag > 0:
            # a drive cut short (a stall, the goal) applied fewer steps: what it did not
            # apply is still in the pipe, in order
            left = n - int(round((S[K.S_T] - X[K.S_T]) / self.dt))
            for g in reversed(segs):
                if left <= 0:
                    break
                back = min(left, g[2])
                if self.pipe and self.pipe[0][:2] == g[:2]:
                    self.pipe[0][2] += back
                else:
                    self.pipe.insert(0, [g[0], g[1], back])
                left -= back
        return rec[:rows], int(end), S


STUCK_HORIZONS = 2   # a horizon run falls back to whole-route plans where its terminal cost did not fall for this many horizons
HELD = "the next period would come within half the tip-over margin or leave the map"   # a re-plan's why after the guard
SETTLED = "after the wheels were held at rest for a period (the horizon plan found no way on from a saturated drive)"   # a plan's why

def guards(world: WO.World, cost: str) -> list:
    """The tip-over guard of a run's periods (``planner.margin_tip_deg`` > 0; else none):
    controller-rate executors of the planning vehicle and, with a margin
    (``planner.margin`` = m), of its pessimistic twin (:func:`sbmpc.planning.world.pessimistic`)
    and of an optimistic one (mass, inertia, mu_sa and mu_op divided by 1 + m and the
    battery voltage times 1 + m: a vehicle lighter or faster than planned drives further
    into a period; a 14 % lighter one rolled over on `narrow_pass`'s flank where both
    other predictions stopped short of the margin, and one 13 % lighter with 14 % more
    voltage drove a whole-route plan's periods off `flat`'s map, 2026-12-06), each with
    half the tip-over margin (:class:`Executor`); and, for the map's edge alone, that
    twin with FASTEST times the margin in battery voltage (x1.3 at the default 0.1): a
    truth 22 % faster than planned (2.2 sd of issue 62's draws) drove a whole-route plan's
    period, commanded past what the planning drive holds, off `hills_field`'s map along
    its edge where the optimistic twin's prediction stayed on it (2026-12-06). A band at
    the edge kept by the guard alone held back re-plans that run along the edge, and one
    kept by the plans too changed the shipped energy plans (`narrow_pass` +7 %)."""
    ps = world.scenario.planner
    if ps.margin_tip_deg <= 0.0:
        return []
    out = [Executor(world, cost, tip_guard=True)]
    if ps.margin > 0.0:
        out.append(Executor(WO.pessimistic(world), cost, tip_guard=True))
        f = 1.0 / (1.0 + ps.margin)
        fast = WO.heavier(world.vehicle, f)
        fast = fast.replace(v_max=fast.v_max * (1.0 + ps.margin))
        light = replace(world, vehicle=fast, terrains=WO.gripped(world.terrains, f))
        out.append(Executor(light, cost, tip_guard=True))
        # the map's edge only: the optimistic twin with FASTEST times the margin's voltage
        out.append(Executor(replace(light, vehicle=fast.replace(v_max=world.vehicle.v_max * (1.0 + FASTEST * ps.margin))),
                            cost, tip_guard=True))
    return out


def held(guards: list, X: np.ndarray, control, kept: bool, tilt_error: float = 0.0,
         brake_s: float | None = None) -> bool:
    """Whether the guards hold back the period (:func:`holder`)."""
    return holder(guards, X, control, kept, tilt_error, brake_s) > 0


SHORTER = (0.5, 0.25)   # the parts of a held period tried before it is braked through (shortened), rounded down to whole control periods


def shortened(guards: list, X: np.ndarray, control, kept: bool, tilt_error: float, tick: float) -> tuple | None:
    """The longest first part of a held period ``control`` (wl, wr, d) of SHORTER (rounded
    down to a whole number of the robot's control periods ``tick`` [s], at least one,
    shorter than d: half and a quarter of 1 s at 0.1 s are 0.5 and 0.2 s) that the guards let through with braking for the whole of d after it: the
    command driven for less time, the vehicle slower and nearer where it can still brake.
    None where none is. A 1 s period at speed and the second of braking after it commit
    the vehicle to about 2 m; near `hills_field`'s goal, on its 21-27 deg flank, the
    optimistic twin's prediction of every such period ran 0.7 m on into ground steeper
    than the guard's band while the plan's next periods turned along the slope, and the
    runs stopped 0.6-1.3 m outside the goal disc (2026-12-07). The controller asks this
    of a vehicle at rest only (:class:`sbmpc.robot.Controller`)."""
    wl, wr, d = control
    for f in SHORTER:
        part = max(tick, math.floor(d * f / tick + 1e-9) * tick)
        if part < d - 1e-9 and not held(guards, X, (wl, wr, part), kept, tilt_error, brake_s=d):
            return (wl, wr, part)
    return None


def holder(guards: list, X: np.ndarray, control, kept: bool, tilt_error: float = 0.0,
           brake_s: float | None = None) -> int:
    """Which of the guards holds back the period ``control`` from the measured state X
    (:func:`_holder`, the rules), 1-based, 0: none; and where the vehicle is moving and
    braking to rest is held back too (a descent steeper than its drive holds: braking
    with the wheels commanded to rest, the drive at its current limit, the vehicle still
    gathers speed), the lesser evil: the period is driven where every prediction of it
    stays out of the band that braking's predictions need (:func:`braking_floor`): it
    goes no steeper than braking would. Holding such a period back brakes the vehicle
    into the steeper ground: a drawn `hills_field` horizon truth, its plan's period held
    on an 18 deg descent the map made 1.6-2.6 deg too gentle, braked with its wheels
    at rest commanded from 7.6 to 10.9 rad/s and the run stopped it rolling at 1.2 m/s,
    on 27 deg (2026-12-07). A hold the brake's own floor does not lift stays a hold.
    ``brake_s`` [s]: how long the predictions brake after the period (default: the
    period's own length)."""
    who = _holder(guards, X, control, kept, tilt_error, brake_s=brake_s)
    if who == 0 or X is None or not moving(X) or (control[0] == 0.0 and control[1] == 0.0):
        return who
    floor = braking_floor(guards, X, tilt_error)
    if floor is None or _holder(guards, X, control, kept, tilt_error, floor, brake_s) > 0:
        return who
    return 0


BRAKING_TOL = math.radians(0.05)    # rad: how closely braking_floor finds the limit braking needs


def braking_floor(guards: list, X: np.ndarray, tilt_error: float = 0.0) -> float | None:
    """Where the guards hold back braking itself from X (the wheels commanded to rest for
    a period, a moving vehicle's only other choice: :func:`holder`): the lowest limit
    [rad] of the guard's band under which every prediction of braking stays (bisection to
    BRAKING_TOL, up to the tip-over limit less ``tilt_error``); None where braking is not
    held back, or would tip over or leave the map whatever the band."""
    world = guards[0].world if guards else None
    if world is None:
        return None
    ps = world.scenario.planner
    brake = (0.0, 0.0, ps.period_s)
    if _holder(guards, X, brake, True, tilt_error) == 0:
        return None
    lo = math.radians(ps.tip_over_deg - 0.5 * ps.margin_tip_deg) - tilt_error     # the band (Executor)
    hi = math.radians(ps.tip_over_deg) - tilt_error - BRAKING_TOL
    if _holder(guards, X, brake, True, tilt_error, hi) > 0:
        return None
    while hi - lo > BRAKING_TOL:
        mid = 0.5 * (lo + hi)
        if _holder(guards, X, brake, True, tilt_error, mid) > 0:
            lo = mid
        else:
            hi = mid
    return hi


def _holder(guards: list, X: np.ndarray, control, kept: bool, tilt_error: float = 0.0,
            floor: float = 0.0, brake_s: float | None = None) -> int:
    """Which of the guards (:func:`guards`: the world's vehicle, then its twins) holds back
    the period ``control`` from the measured state X, the band's limit taken no lower than
    ``floor`` [rad] (:func:`braking_floor`). The world's vehicle's prediction holds it back where it tips over, or, for a plan
    that keeps the margin (``kept``), where it comes within half the tip-over margin; a
    plan made without the margin (none kept it: it says so) rides within the margin by
    design, and its drive would be held back at every period. The pessimistic twin's
    prediction (a vehicle weaker than the planning one: it falls behind, and meets the
    flank of a pass where the plan has passed it) holds it back where it comes within
    half the margin: the one prediction of a fallback plan's periods on a vehicle the
    plan did not allow for; so does the optimistic twin's (a lighter vehicle drives
    further into the period). Once the twin plans (the vehicle proved weaker), the run
    passes ``kept`` False. Every prediction also holds a period back where it leaves the
    map: the optimistic twin's (a faster vehicle drives further) and the pessimistic
    one's (a heavier vehicle braking or reversing towards the edge runs further on: a
    `hills_field` horizon run reversing 0.1 m from its east edge left the map exactly
    where the heavier twin's prediction did, while the planning vehicle's stopped 6 mm
    short, 2026-12-06): a run never drives off its map (a horizon run with 10 % less grip left
    `hills_field` at (48.4, 59.7), 2026-12-06); and where its braking comes to rest closer
    to the edge than EDGE_CLEARANCE, having closed in on it (:func:`_approaches_edge`), or stalls
    there (a `hills_field` horizon run reversing towards its north edge left the map 0.4 s
    into a period whose four predictions all stalled within 1 cm of the edge, the
    truth's drive stronger than theirs, 2026-12-07). ``tilt_error`` [rad]: how
    far the map's tilt is off where the vehicle stands (:func:`tilt_error`): the limits
    are taken that much lower (the map's heights off by 5 cm at 2 m correlation put
    `narrow_pass`'s flank 1.6 deg steeper than it says). A vehicle that already stands
    inside the band (the period before drove it further up a flank than predicted) is let
    drive a period that goes no steeper than where it stands (within STANDING, on the
    map): standing still there is no safer, and the plans from there lead out of it
    (:func:`sbmpc.planning.problem.from_inside`); with the band's limit alone every
    period, holding the wheels at rest too, was held back and the run stopped on the
    flank (`hills_field` energy, a 9 % heavier truth, at (34.45, 24.51) with 26.4 deg of
    roll on the map and 1.3 deg more measured, 2026-12-06). Each prediction goes on
    past the period with the wheels commanded to rest for as long again, and is held to
    the same rules there: a period is driven only where the vehicle can still brake
    safely after it, since a period held back is braked through (a moving vehicle cannot
    wait for the plan from where it stands). Without that, four `narrow_pass` runs of 28
    tipped over braking on the pass's flank after a hold, 2026-12-06 (before the brake
    was driven, such runs "stopped" with the vehicle at speed). Returns which guard holds the
    period back, 1-based (1: the planning vehicle, 2: the pessimistic twin, 3: the
    optimistic one, 4: the fastest, which holds a period that leaves the map or closes in on
    its edge only), 0: none."""
    where = guards[0].world if guards else None
    floor = max(floor, PB.standing_tilt(where, X, guard_aside(where)) + STANDING if where is not None else 0.0)
    brake = (0.0, 0.0, control[2] if brake_s is None else brake_s)
    for j, g in enumerate(guards):
        edge = j == 3           # the fastest twin: the map's edge alone (guards)
        limits = {} if edge else {"tilt_error": tilt_error, "floor": floor}
        S = X
        for c in (control, brake):     # the period, then braking to rest after it
            _, end, S = g.step(S, c, record=False, **limits)
            if end == -SS.OFF_MAP or (not edge and (end == -SS.TIP or (end == -SS.MARGIN and (kept or j > 0)))):
                return j + 1
            if end == -SS.STALL and _approaches_edge(g.world, X, S):
                return j + 1           # stalled closing in on the edge: a truth that does not stall drives on
            if end != 0:
                break                  # (in the goal, or stalled: the stall test's)
        else:
            if _approaches_edge(g.world, X, S):
                return j + 1
            if not edge and (kept or j > 0) and _runs_on(g, X, S, tilt_error, floor):
                return j + 1
    return 0


def _runs_on(g: "Executor", X: np.ndarray, S: np.ndarray, tilt_error: float, floor: float) -> bool:
    """Whether a prediction from X that comes to rest at S would be within half the
    tip-over margin (the guard's band, ``tilt_error`` lower, no lower than ``floor``) had
    the vehicle come to rest RUN_ON further along the way it came, or there and the
    guard's allowance aside (:func:`guard_aside`) to either side, as the kernel judges
    every step: a truth a few centimetres beyond or beside every prediction is then
    still out of the band.
    At the foot of a flank the map's tilt rises by degrees a centimetre (`narrow_pass`'s
    pass: 26 to 30 deg in 5 cm); a drawn `narrow_pass` truth 24 % lighter, braking at
    full speed towards the pass's flank, came to rest 4 cm beyond the optimistic twin's
    prediction and rolled over (2026-12-07)."""
    if g.world is None:
        return False
    d = np.array([S[K.S_X] - X[K.S_X], S[K.S_Y] - X[K.S_Y]])
    n = float(np.hypot(d[0], d[1]))
    if n < 1e-6:
        return False
    S2 = S.copy()
    S2[K.S_X] += RUN_ON * d[0] / n
    S2[K.S_Y] += RUN_ON * d[1] / n
    band = max(g.Q[SS.Q_TIPM] - tilt_error, floor)
    return PB.standing_tilt(g.world, S2, g.Q[SS.Q_ASIDE]) > band


def _approaches_edge(world, X: np.ndarray, S: np.ndarray) -> bool:
    """Whether a prediction from X that comes to rest at S closes in on one of the map's
    edges (by more than CLOSING) and stops within EDGE_CLEARANCE of it (the footprint's
    limit): a truth off every prediction by a few centimetres is then still kept on the
    map. A period along the edge, or away from it, is not held back by it (a band the
    guard kept at the edge whatever the heading held back re-plans that ran along it);
    nor is one towards a goal whose disc reaches into the clearance (the last periods
    must be driven there)."""
    if world is None:
        return False
    x0, x1, y0, y1 = world.emap.extent
    m = world.margin

    def gaps(x, y):
        return np.array([x - x0, x1 - x, y - y0, y1 - y]) - m
    g0 = gaps(float(X[K.S_X]), float(X[K.S_Y]))
    g1 = gaps(float(S[K.S_X]), float(S[K.S_Y]))
    close = (g1 < EDGE_CLEARANCE) & (g1 < g0 - CLOSING)
    goal = world.scenario.goal
    towards_goal = gaps(goal["x"], goal["y"]) - goal["radius"] < EDGE_CLEARANCE
    return bool(np.any(close & ~towards_goal))


MOVING = 0.3   # rad/s: a wheel turning faster than this moves the vehicle (about 3 cm/s on a P3-AT)


def moving(X: np.ndarray) -> bool:
    """Whether the vehicle at planner state X is moving (a wheel turning faster than
    MOVING): a period the guard holds back is then braked through, not waited out."""
    return max(abs(X[K.S_WL]), abs(X[K.S_WR])) > MOVING


def tilt_error(world: WO.World, X: np.ndarray, pitch: float, roll: float) -> float:
    """How far the map's tilt is off [rad] where the vehicle stands: the larger of the
    measured pitch's and roll's (an IMU's, ``pitch``, ``roll`` [rad]) excess over the
    planning map's at the measured pose X (0 where the map is as steep or steeper).
    The guard takes its limits that much lower for the next period: a map's error is
    smooth, and a metre on it is much the same (at 2 m correlation, 0.88)."""
    e = world.emap
    if not e.contains(X[K.S_X], X[K.S_Y]):
        return 0.0
    mp, mr = e.pitch_roll(float(X[K.S_X]), float(X[K.S_Y]), float(X[K.S_YAW]), world.half_length, world.half_width)
    return max(0.0, abs(pitch) - abs(mp), abs(roll) - abs(mr))


def stopped(X: np.ndarray, ps, failed: tuple | None = None) -> str:
    """Why a run stopped at the measured state X rather than tip over (``ps``: the planner
    settings): the guard held back the first period of every plan from there, or, with
    ``failed`` (what re-planned, its reason), the period it held back left no plan."""
    at = f"stopped at ({X[K.S_X]:.2f}, {X[K.S_Y]:.2f}), t = {X[K.S_T]:.1f} s: "
    if failed is not None:
        return (f"{at}the next period would come within half the tip-over margin or leave the map and no "
                f"{failed[0]} from there "
                f"found a way on ({failed[1]}); the run stops rather than tip over")
    return (f"{at}every way on that the planner found comes within half the tip-over margin "
            f"({0.5 * ps.margin_tip_deg:g} deg below {ps.tip_over_deg:g} deg) or leaves the map from the measured "
            f"state; the run stops rather than tip over")



def keeps_margin(plan: PL.Plan) -> bool:
    """Whether a plan keeps the planner's margin (a fallback made without it says so)."""
    return bool((plan.margin or {}).get("kept", True))



def settles(X: np.ndarray) -> bool:
    """Whether a vehicle from whose state X a horizon plan found no way on is first to be
    held at rest for a period (:func:`_run_horizon`): its stall timer runs (the drive
    saturated short of its command within the last moments: the timer leaks at the rate
    it fills), not yet a stall. A moving vehicle is braked to rest. The wheel-speed
    references, rate-limited, then keep the drive saturated whatever the next plan
    commands, and every edge from there stalls: on ``hills_field`` (energy, seed 4) a
    vehicle braking into a pivot on a 5 deg slope stopped at t = 50 s with 0.12 s on its
    stall timer, every edge of the horizon and of the whole-route search stalled, and the
    run failed; after one period with the wheels held at rest the horizon plan found a way
    on in 19 ms."""
    return bool(X[K.S_STALLT] > 0.0 and X[K.S_STALLED] == 0.0)


def weaker(stalls: list, name: str) -> str:
    """The failure of a run whose vehicle stalled at ``stalls`` [(x, y)] where every plan
    of the planning model ``name`` predicted it would get through."""
    where = ", ".join(f"({a:.1f}, {b:.1f})" for a, b in stalls)
    return (f"the vehicle stalled {len(stalls)} time{'s' if len(stalls) > 1 else ''}, at {where}, where every "
            f"plan predicted it would get through: it is weaker there than the planning model ({name}); plan "
            f"with a model of this vehicle (sbmpc diagnose on a run of it writes one)")



def protected(X: np.ndarray, real: "Executor") -> None:
    """The drive's stall protection on the simulated truth: its references set to the
    measured speeds, commands still in the pipe dropped (:func:`_stalled`)."""
    X[K.S_STALLT] = 0.0
    X[K.S_STALLED] = 0.0
    X[K.S_REFL] = X[K.S_WL]
    X[K.S_REFR] = X[K.S_WR]
    real.pipe = None


# ---- planning as a weaker vehicle after a stall (whole-route runs and the controller) ----
MARK_NEAR = 1.5      # m: a stall this close to an earlier one marks the slope ahead impassable
MARK_RADIUS = 0.6    # m: the radius of such a mark


def ahead(world: WO.World, X: np.ndarray, control: tuple) -> tuple:
    """(x, y, radius) [m] of the slope a stalled vehicle at X was climbing: a disc of
    MARK_RADIUS ahead in the direction it was commanded (``control``), two map cells clear of its
    footprint at any heading (the vehicle turns where it stands)."""
    d = world.margin + 2.0 * world.emap.resolution + MARK_RADIUS
    sign = -1.0 if control[0] + control[1] < 0.0 else 1.0      # (the wheels may roll back at the stall)
    yaw = float(X[K.S_YAW])
    return (round(float(X[K.S_X]) + sign * d * math.cos(yaw), 3), round(float(X[K.S_Y]) + sign * d * math.sin(yaw), 3),
            MARK_RADIUS)


@functools.lru_cache(maxsize=16)
def marked(world: WO.World, marks: tuple) -> WO.World:
    """``world`` with each mark (x, y, radius) a wall (100 m above the highest cell, as a
    map's ``nodata: wall``): no plan crosses it. Cached per world and marks."""
    e = world.emap
    H = e.heights.copy()
    Xg, Yg = WO.centres(e)
    top = float(H.max()) + 100.0
    for x, y, r in marks:
        H[(Xg - x) ** 2 + (Yg - y) ** 2 <= r * r] = top
    return replace(world, emap=replace(e, heights=H))


@functools.lru_cache(maxsize=16)
def twin_planner(world: WO.World, tip: bool = False) -> WO.World:
    """The margin's pessimistic twin as a run's planning model. It is the margin, so it
    plans with no twin or turn reserve of its own, and, unless ``tip``, without the
    tip-over margin, which the run's guard keeps at 1 kHz: with it, hills_field's energy
    search took 174 000 expansions (98 s) for the plan the search without it finds in
    24 000 (10 s). A re-plan after the guard held a period back plans with it (``tip``).
    Cached per world, so that the re-plans share its cost-to-go grids."""
    tw = WO.pessimistic(world)
    ps = replace(tw.scenario.planner, margin=0.0, margin_turn=0.0,
                 margin_tip_deg=world.scenario.planner.margin_tip_deg if tip else 0.0)
    return replace(tw, scenario=replace(tw.scenario, planner=ps))


TURNING = 0.5    # share of the current limit each side's current exceeds, in opposite directions, in a turning stall


def turning_stall(currents: tuple, vehicle) -> bool:
    """Whether a drive that stalled with the sides' ``currents`` (il, ir) [A] stalled in a
    turn: the currents in opposite directions, each beyond ``TURNING`` of the current limit (a skid-steered vehicle held
    by its turning resistance: on hills_field half the stalls of drawn vehicles were pivots
    and tight turns on gentle ground, 0-5 deg of pitch, at +-3.6 A; a stall on a climb has
    both sides at the limit the same way)."""
    lim = TURNING * vehicle.current_limit
    il, ir = float(currents[0]), float(currents[1])
    return il * ir < 0.0 and min(abs(il), abs(ir)) > lim


RETRACE_PERIODS = (2, 4)   # periods driven back along the way it came before a held run stops (retrace)


def retrace(guards: list, X: np.ndarray, driven: list, n: int, tilt: float = 0.0) -> list | None:
    """A stop (wheel speeds 0 for the last period's length), then the last ``n`` driven
    periods ``driven`` [(wl, wr, duration_s)] backwards: each period's wheel speeds
    negated, the latest first (from rest a skid-steered vehicle backs along the way it
    came, up to its slip); where every one of them, predicted from the measured state X
    by the guards, stays out of half the tip-over margin; else None (too few periods
    driven, or one held back)."""
    if len(driven) < n:
        return None
    back = [(0.0, 0.0, driven[-1][2])] + [(-wl, -wr, d) for wl, wr, d in reversed(driven[-n:])]
    S = X
    for c in back if guards else ():     # (a run without a tip-over margin has no guard)
        if held(guards, S, c, True, tilt):
            return None
        _, _, S = guards[0].step(S, c, record=False)
    return back


def back_along(guards: list, X: np.ndarray, way: list, tried: int, tilt: float = 0.0) -> tuple:
    """The next of RETRACE_PERIODS[tried:] that the guards let the vehicle drive back
    (:func:`retrace`): (its periods, the retraces tried since), the periods it retraces
    taken off ``way`` (the periods driven along the way it came, not the ones driven
    back: a second retrace goes further back along it, never forward again); (None,
    len(RETRACE_PERIODS)) where none is let through."""
    while tried < len(RETRACE_PERIODS):
        n = RETRACE_PERIODS[tried]
        tried += 1
        back = retrace(guards, X, way, n, tilt)
        if back is not None:
            del way[-n:]
            return back, tried
    return None, tried


def stalls_near(stalls: list, X: np.ndarray) -> int:
    """How many earlier stalls of ``stalls`` [(x, y)] (the last of them is this one, the
    vehicle stalled at X) lie within MARK_NEAR of X."""
    return sum(math.hypot(a - X[K.S_X], b - X[K.S_Y]) < MARK_NEAR for a, b in stalls[:-1])


def past_stall_limit(stalls: list, X: np.ndarray, settings) -> bool:
    """Whether a run whose vehicle stalled at X (the last of ``stalls`` [(x, y)]) has
    stalled more than ``run.max_stalls`` times in all, or more than
    ``run.max_stalls_near`` times within MARK_NEAR of X (stuck there)."""
    return len(stalls) > settings.max_stalls or stalls_near(stalls, X) + 1 > settings.max_stalls_near


def stalled_again(stalls: list, X: np.ndarray) -> bool:
    """Whether the vehicle at X, stalled, is within MARK_NEAR of an earlier stall of
    ``stalls`` [(x, y)] (the last of them is this one): the slope ahead is to be marked."""
    return stalls_near(stalls, X) > 0


GROW_MAX = 3.0      # the twin's margin grows after repeated turning stalls to at most this many times the file's


def twin_grows(stalls: list, X: np.ndarray, currents: tuple, vehicle) -> int:
    """How many times a stall at X (the last of ``stalls`` [(x, y)]) in a turn
    (:func:`turning_stall` of the sides' ``currents`` (il, ir) [A]) repeats earlier stalls
    within MARK_NEAR: 0 for a first stall there or one not in a turn (a straight one marks
    the slope ahead instead, :func:`marks_wall`). A vehicle that stalls again in a turn
    where the twin's plans turned it is weaker in turns than that twin (on `steep_hill` two
    drawn vehicles stalled four times in the same turn from rest, the twin's re-plans
    starting with the same turn each time): :func:`grown`."""
    return stalls_near(stalls, X) if turning_stall(currents, vehicle) else 0


def grown(base: WO.World, world: WO.World, repeats: int) -> WO.World:
    """``base`` with the margin its twin is made with (:func:`twin_planner`) the file's
    times 1 + ``repeats`` (at most GROW_MAX times): the twin after a turning stall that
    repeats earlier ones (:func:`twin_grows`) heavier and gripping harder by that much
    more, so that its plans turn more gently. ``base`` itself where ``repeats`` is 0."""
    if repeats <= 0:
        return base
    m = world.scenario.planner.margin * min(1.0 + repeats, GROW_MAX)
    return replace(base, scenario=replace(base.scenario, planner=replace(base.scenario.planner, margin=m)))


def marks_wall(stalls: list, X: np.ndarray, currents: tuple, vehicle) -> bool:
    """Whether a stall at X (the last of ``stalls`` [(x, y)]) makes the slope ahead a wall
    in the plans' map (:func:`marked`): stalled again within MARK_NEAR of an earlier stall
    (:func:`stalled_again`), and not in a turn (:func:`turning_stall` of each side's
    ``currents`` (il, ir) [A] at the stall): the ground ahead did not hold a vehicle that
    could not make a turn. The controller's rule and the whole-route runs'."""
    return stalled_again(stalls, X) and not turning_stall(currents, vehicle)


__all__ = ["FASTEST", "Executor", "HELD", "MOVING", "STANDING", "holder", "moving", "tilt_error", "HorizonStats", "Replan", "SETTLED", "STUCK_HORIZONS", "deviation", "guards",
           "held", "keeps_margin", "protected", "settles", "stopped", "weaker", "MARK_NEAR", "MARK_RADIUS", "ahead",
           "marked", "twin_planner", "turning_stall", "RETRACE_PERIODS", "retrace", "back_along", "stalled_again", "stalls_near",
           "marks_wall", "twin_grows", "grown", "GROW_MAX"]
