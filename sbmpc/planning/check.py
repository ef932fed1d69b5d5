"""Every plan is checked where the vehicle lives: its controls replayed through the
closed-loop model over the map, at the planner's step (:func:`replay`) and at the
vehicle's controller rate (:func:`check`, the paper's 1 kHz digital PID), and where
that replay parts from the search's prediction (:func:`parting`)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dynamics import ParameterError, kernels as K
from dynamics.simulate import check_step

from ..errors import InputError
from .problem import pack_world
from ..problems import skidsteer as SS
from .world import MAX_REPLAY_STEPS, World, _start, checked_controls, checked_cost


def boundaries(controls, dt: float) -> np.ndarray:
    """The step [int] at which each of ``controls`` [(wl, wr, duration_s)] starts, and the
    last one ends, replayed at step ``dt`` [s] (len(controls) + 1): :func:`replay`'s count,
    each duration rounded to whole steps."""
    n = np.array([max(0, round(c[2] / dt)) for c in controls], np.int64)
    return np.concatenate([np.zeros(1, np.int64), np.cumsum(n)])


def replay(world: World, cost: str, controls, every: int = 1, start: np.ndarray | None = None,
           dt: float | None = None, hold_last: float = 0.0) -> tuple:
    """Replay controls [(wl, wr, duration_s)] through the closed-loop model over the map
    from ``start`` (a planner state; default the scenario's start) at step ``dt`` [s]
    (default the planner's). Returns (trajectory dict sampled every ``every`` steps plus
    the last step, end code (0 or IN_GOAL, negative if invalid), final state, number of
    controls used: a replay stops at the first control that enters the goal or fails).
    ``hold_last`` [s] holds the last control that much longer (it stops in the goal)."""
    cost = checked_cost(world, cost)
    controls = checked_controls(controls)
    try:
        dt = world.scenario.planner.dt if dt is None else check_step(dt)
    except ParameterError as exc:
        raise InputError(str(exc)) from None
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise InputError(f"every: expected a whole number of steps >= 1, found {every!r:.40}")
    cl = np.array([c[0] for c in controls], float)
    cr = np.array([c[1] for c in controls], float)
    n = np.diff(boundaries(controls, dt))
    if len(n) and hold_last > 0:
        n[-1] += int(round(hold_last / dt))
    if n.sum() > MAX_REPLAY_STEPS:
        raise InputError(f"controls: expected at most {MAX_REPLAY_STEPS:,} steps of {dt:g} s in all, found "
                         f"{int(n.sum()):,} ({sum(c[2] for c in controls):.6g} s)")
    Q, data = pack_world(world, cost, dt)
    rec = np.empty((int(n.sum()) + 1, K.NR))
    X0 = _start(world, start)
    rows, S, end, early = SS.replay(Q, data, X0, cl, cr, n, rec)
    if every == 1:                  # every step: one transposed copy, a contiguous row per channel
        cols = np.ascontiguousarray(rec[:rows].T)
        traj = {name: cols[i] for i, name in enumerate(K.CHANNELS)}
    else:
        idx = np.unique(np.r_[np.arange(0, rows, every), rows - 1])
        traj = {name: rec[idx, i].copy() for i, name in enumerate(K.CHANNELS)}
    return traj, int(end), S, (len(controls) if early < 0 else int(early) + 1)


@dataclass(frozen=True)
class Check:
    """A plan's controls replayed at the vehicle's controller rate (the paper's 1 kHz
    digital PID): does the vehicle really get there, and at what cost? ``miss_m`` [m]:
    how far outside the goal disc the replay's closest approach stays (0 when it enters);
    ``drift_m`` [m]: the allowance for that (DRIFT_PER_M of the distance driven);
    ``end``: how the replay ended (the replay's end code: ``skidsteer.IN_GOAL``, 0, or
    minus ``skidsteer.OFF_MAP``, ``STALL``, ``TIP``)."""

    dt: float
    reached: bool
    travel_time_s: float | None
    energy_J: float | None
    reason: str | None
    miss_m: float = 0.0
    drift_m: float = 0.0
    end: int = 0

    def to_json(self) -> dict:
        return {"dt": self.dt, "reached": self.reached, "travel_time_s": self.travel_time_s,
                "energy_J": self.energy_J, "reason": self.reason, "miss_m": self.miss_m,
                "drift_allowance_m": self.drift_m}


HOLD_LAST_S = 0.25   # s: the last control is held this much longer at the controller rate
DRIFT_PER_M = 0.005  # of the distance driven: how far the controller-rate replay of a plan,
                     # driven open loop, may miss the goal disc and still count as reaching
                     # it (a vehicle that closes the loop, sbmpc run, corrects such drift).
                     # A stall or a tip-over is never allowed.
PART_M = 0.05        # m: a plan's controller-rate replay has parted from the search's
PART_DEG = 2.0       # prediction once its pose differs by this much (dynamics.convergence)


def check_cost(chk: "Check", cost: str) -> float:
    return chk.travel_time_s if cost == "time" else chk.energy_J


def controller_rate(world: World, cost: str, controls, X0: np.ndarray, known: tuple | None = None) -> tuple:
    """The controls replayed at the controller period from X0, every step recorded.
    Returns (Check, trajectory dict, controls as driven: cut where the replay enters the
    goal disc or passes closest to it, the last one held up to HOLD_LAST_S longer).
    ``known``: (j, trajectory, state): the drive of the first j controls is known, a
    trajectory of this function's (every step from X0, at least to the end of control j)
    and the planner state after them (:func:`fine_state`); only the rest is replayed,
    from that state (a repaired plan keeps the controls before where it parted)."""
    dt = 1.0 / world.vehicle.controller_rate
    b = -1
    if known is not None:
        j, prev, Sj = known
        b = int(boundaries(controls[:j], dt)[-1]) if 0 < j < len(controls) else -1
        if b >= len(prev["t"]):
            b = -1
    if b < 0:
        traj, end, S, used = replay(world, cost, controls, every=1, start=X0, dt=dt, hold_last=HOLD_LAST_S)
    else:
        traj, end, S, used = replay(world, cost, controls[j:], every=1, start=Sj, dt=dt, hold_last=HOLD_LAST_S)
        traj = {name: np.concatenate([prev[name][:b + 1], v[1:]]) for name, v in traj.items()}
        used += j
    g = world.scenario.goal
    d = np.hypot(traj["x"] - g["x"], traj["y"] - g["y"]) - g["radius"]
    if end == SS.IN_GOAL:
        i, miss = len(d) - 1, 0.0
    else:
        i = int(np.argmin(d))
        miss = max(0.0, float(d[i]))
    drift = DRIFT_PER_M * float(np.sum(np.hypot(np.diff(traj["x"][:i + 1]), np.diff(traj["y"][:i + 1]))))
    t = float(traj["t"][i] - X0[K.S_T])
    e = float(traj["energy_J"][i] - X0[K.S_E])
    if end == SS.IN_GOAL or (end >= 0 and miss <= drift):
        # the controls as driven: cumulative ends, the one running at sample i cut there
        ends = np.cumsum([c[2] for c in controls])
        k = min(int(np.searchsorted(ends, t - 1e-9)), len(controls) - 1)
        done = float(ends[k - 1]) if k else 0.0
        kept = [tuple(c) for c in controls[:k]] + [(controls[k][0], controls[k][1], round(t - done, 9))]
        traj = {name: v[:i + 1] for name, v in traj.items()}
        return Check(dt, True, t, e, None, miss, drift, int(end)), traj, kept
    tt = float(S[K.S_T] - X0[K.S_T])
    where = f"at ({S[K.S_X]:.2f}, {S[K.S_Y]:.2f}), t = {tt:.2f} s, control {used} of {len(controls)}"
    if end < 0:
        why = f"the vehicle {SS.CODES[-end - 1].split(' (')[0]} {where}"
    else:
        why = (f"the controls pass {miss:.2f} m outside the goal disc (allowed: {drift:.2f} m of "
               f"open-loop drift), ending {where}")
    return Check(dt, False, tt, float(S[K.S_E] - X0[K.S_E]), why, miss, drift, int(end)), traj, list(controls)


def check(world: World, cost: str, controls, start: np.ndarray | None = None) -> Check:
    """Replay ``controls`` at the controller period from ``start`` (the check of every
    plan before it is reported). Reached when the vehicle enters the goal disc, holding
    the last control up to HOLD_LAST_S longer than planned (the planner cut it where its
    coarser step entered the goal), or when it passes within the open-loop drift
    allowance (DRIFT_PER_M of the distance driven) of the disc without stalling."""
    return controller_rate(world, cost, controls, _start(world, start))[0]


def parting(pred: np.ndarray, controls, fine: dict, rate: float) -> tuple:
    """(j, parted): j the first control whose start the controller-rate replay (``fine``,
    every step recorded) reaches with a pose PART_M / PART_DEG away from the search's
    prediction ``pred`` (poses (x, y, yaw) at the control boundaries), parted True; else
    j the control where the replay stopped (a stall or tip-over) or the number of
    controls, parted False."""
    n_f = boundaries(controls, 1.0 / rate)
    last = min(len(controls), int(np.searchsorted(n_f, len(fine["t"]) - 1, "left")) - 1)
    for j in range(1, max(last, 0) + 1):
        b = n_f[j]
        dpos = math.hypot(pred[j, 0] - fine["x"][b], pred[j, 1] - fine["y"][b])
        dyaw = abs(math.remainder(pred[j, 2] - fine["yaw"][b], 2 * math.pi))
        if dpos > PART_M or dyaw > math.radians(PART_DEG):
            return j, True
    return max(last, 0), False


def fine_state(world: World, cost: str, controls, X0: np.ndarray) -> np.ndarray:
    """The planner state after ``controls`` driven at the controller period from X0."""
    _, _, S, _ = replay(world, cost, controls, every=1 << 30, start=X0, dt=1.0 / world.vehicle.controller_rate)
    return S


def predicted(world: World, cost: str, controls, X0: np.ndarray) -> np.ndarray:
    """Poses (len(controls) + 1, 3) [m, m, rad] at the control boundaries, replayed at the
    planner's step from X0 (for controls that did not come from a search)."""
    dt = world.scenario.planner.dt
    traj, *_ = replay(world, cost, controls, every=1, start=X0)
    b = boundaries(controls, dt)
    b = np.minimum(b, len(traj["t"]) - 1)
    return np.column_stack([traj["x"][b], traj["y"][b], traj["yaw"][b]])
