"""How close a plan runs to the vehicle's limits: the report of ``planner.margin``.

The search keeps the margin on every edge (:mod:`sbmpc.problems.skidsteer`, docs/planner.md#margin):

* **drive reserve** (``planner.margin`` = m): while the commands turn, the drive keeps a
  share m of its reach (eq. 27's current window at the wheel's speed) unused, except
  for ``MARGIN_TIME`` at a time; there the PID holds the commanded wheel speeds for a
  vehicle that needs up to 1 / (1 - m) times the torque, which then turns on the same path;
* **pessimistic twin**: a vehicle with mass, inertia, mu_sa and mu_op raised by m steps
  along every edge from its own drive state, on the steeper of the grades it meets with
  its heading ``margin_heading_deg`` off, each grade ``margin_grade_deg`` steeper
  in the direction it drives (the map's slopes that far off), and must not stall;
* **tip margin**: pitch and roll stay ``margin_tip_deg`` below ``tip_over_deg``.

:func:`report` reads from a plan's controller-rate trajectory where it comes closest to
each limit: the least *sustained* drive headroom (the share of the drive's reach left
unused, held for at least ``MARGIN_TIME``: a start from rest saturates the PID for a
moment by design) and the least tip-over margin, each with where and when.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import replace

import numpy as np

from dynamics.drive import window_share

from .check import check
from ..errors import InputError
from ..problems import skidsteer as SS
from ..problems.skidsteer import MARGIN_TIME


def _sustained_max(t: np.ndarray, x: np.ndarray, span: float) -> tuple:
    """(value, index): the largest level that x stays at or above for at least ``span``
    seconds of the times t (the largest over windows of that length of the window's
    least value); the whole run's least where it is shorter."""
    n = len(t)
    if n == 0:
        return 0.0, 0
    best, at = -math.inf, 0
    j = 0
    q: deque = deque()             # indices of a sliding-window minimum
    for i in range(n):
        while q and x[q[-1]] >= x[i]:
            q.pop()
        q.append(i)
        while t[i] - t[j] > span:
            j += 1
        while q[0] < j:
            q.popleft()
        if t[i] - t[j] >= span * (1.0 - 1e-9) and x[q[0]] > best:
            best, at = float(x[q[0]]), j
    if best == -math.inf:
        return float(np.min(x)), int(np.argmin(x))
    return best, at


def drive_shares(vehicle, traj: dict) -> np.ndarray:
    """The larger of the two sides' shares of the drive's reach (:func:`dynamics.drive.window_share`)
    at every sample of a trajectory (channels i_l, i_r, wl, wr, energy_J)."""
    v = vehicle
    out = np.zeros(len(traj["t"]))
    for k in range(len(out)):
        vm = max(v.v_max - v.sag * traj["energy_J"][k], 0.0)
        out[k] = max(window_share(float(traj["i_l"][k]), float(traj["wl"][k]), vm,
                                  v.torque_constant * v.torque_scale_left, v.armature_resistance, v.current_limit),
                     window_share(float(traj["i_r"][k]), float(traj["wr"][k]), vm,
                                  v.torque_constant * v.torque_scale_right, v.armature_resistance, v.current_limit))
    return out


def report(world, traj: dict) -> dict | None:
    """Where a plan's controller-rate trajectory comes closest to the limits (module doc):
    {"margin", "margin_turn", "tip_margin_deg", "heading_deg", "grade_deg", "drive_headroom": {"least",
    "t", "x", "y"}, "turn_headroom": the same while the wheel-speed references turn (None:
    no turn), "tip": {"least_deg", "t", "x", "y"}}; None for an empty trajectory. A share of
    0 held for MARGIN_TIME is the drive at its limit: at top speed (the voltage bound) or
    on a climb it barely holds."""
    t = np.asarray(traj.get("t", ()), float)
    if t.size == 0:
        return None
    ps = world.scenario.planner
    share = drive_shares(world.vehicle, traj)
    level, k = _sustained_max(t, share, MARGIN_TIME)
    turning = np.abs(np.asarray(traj["ref_l"]) - np.asarray(traj["ref_r"])) > 1e-9
    turn = None
    if turning.any():
        tl, tk = _sustained_max(t, np.where(turning, share, 0.0), MARGIN_TIME)
        turn = {"least": round(1.0 - tl, 4), "t": round(float(t[tk]), 3), "x": round(float(traj["x"][tk]), 3),
                "y": round(float(traj["y"][tk]), 3)}
    e = world.emap
    tilt = np.array([max(abs(a) for a in e.pitch_roll(x, y, yaw, world.half_length, world.half_width))
                     for x, y, yaw in zip(traj["x"], traj["y"], traj["yaw"])])
    j = int(np.argmax(tilt))
    return {"margin": ps.margin, "margin_turn": ps.margin_turn, "tip_margin_deg": ps.margin_tip_deg,
            "heading_deg": ps.margin_heading_deg, "grade_deg": ps.margin_grade_deg,
            "drive_headroom": {"least": round(1.0 - level, 4), "t": round(float(t[k]), 3),
                               "x": round(float(traj["x"][k]), 3), "y": round(float(traj["y"][k]), 3)},
            "turn_headroom": turn,
            "tip": {"least_deg": round(ps.tip_over_deg - math.degrees(float(tilt[j])), 3),
                    "t": round(float(t[j]), 3), "x": round(float(traj["x"][j]), 3),
                    "y": round(float(traj["y"][j]), 3)}}


def summary_line(rep: dict | None, kept: bool = True) -> str:
    """One line of the plan summary on how close the plan runs."""
    if rep is None:
        return ""
    d, tp, tu = rep["drive_headroom"], rep["tip"], rep.get("turn_headroom")
    grade = f", grades +{rep['grade_deg']:g} deg" if rep.get("grade_deg") else ""
    head = (f"margin {rep['margin']:g} (turns {rep.get('margin_turn', 0):g}, tip {rep['tip_margin_deg']:g} deg{grade})"
            if kept else "no margin kept")
    turn = (f", in turns {100 * tu['least']:.0f} % (t = {tu['t']:.1f} s)" if tu else "")
    return (f"{head}: least drive headroom held {MARGIN_TIME:g} s {100 * d['least']:.0f} % (t = {d['t']:.1f} s, "
            f"({d['x']:.1f}, {d['y']:.1f})){turn}; least tip-over margin {tp['least_deg']:.1f} deg "
            f"(t = {tp['t']:.1f} s, ({tp['x']:.1f}, {tp['y']:.1f}))")


# ---- robustness: a plan replayed open loop by drawn vehicles -------------------------
def drawn_worlds(world, rob: dict, task_id: str):
    """``samples`` worlds with vehicle and terrain parameters drawn from normal
    distributions (relative standard deviation ``vary[name]``) around ``world``'s
    (``rob``: {"samples", "seed", "vary"} of ``sbmpc sweep``'s robustness; ``task_id``:
    a hex string that, with the seed, seeds the draw)."""
    rng = np.random.default_rng([int(rob.get("seed", 0)), int(task_id[:8], 16)])
    return [drawn_world(world, rob.get("vary", {}) or {}, rng) for _ in range(int(rob["samples"]))]


def drawn_world(world, vary: dict, rng: np.random.Generator):
    """One world with the vehicle and terrain parameters named in ``vary`` drawn from
    normal distributions around ``world``'s, ``vary[name]`` their relative standard
    deviations (each factor at least 0.05; a draw that leaves a parameter's range is
    drawn again, at most DRAW_TRIES times, then an InputError)."""
    from dynamics import ParameterError
    for _ in range(DRAW_TRIES):
        v, ts = world.vehicle, world.terrains
        vk = {k: getattr(v, k) * max(0.05, 1.0 + s * rng.standard_normal()) for k, s in vary.items() if hasattr(v, k)}
        tk = {k: s * rng.standard_normal() for k, s in vary.items() if not hasattr(v, k)}
        try:
            ts = tuple(t.replace(**{k: getattr(t, k) * max(0.05, 1.0 + e) for k, e in tk.items()}) for t in ts)
            return replace(world, vehicle=v.replace(**vk), terrains=ts)
        except ParameterError as exc:
            last = str(exc).replace("<replace>: ", "")
    raise InputError(f"no draw of {', '.join(sorted(vary))} within the parameters' ranges in {DRAW_TRIES} "
                     f"tries (the last: {last}); lower the relative standard deviations")


DRAW_TRIES = 100      # draws per robustness sample before its parameters are said to leave their ranges


def robustness(world, cost: str, controls, samples: int, sd: float = 0.05, seed: int = 0) -> dict:
    """A plan's controls replayed open loop at the controller rate by ``samples``
    vehicles whose mass, mu_sa and mu_op are drawn around ``world``'s with relative
    standard deviation ``sd`` (the draw of ``sbmpc sweep``'s robustness): the shares
    that stall (p_stall), tip over (p_tip) and do not reach the goal (p_miss)."""
    drawn = drawn_worlds(world, {"samples": samples, "seed": seed, "vary": {"mass": sd, "mu_sa": sd, "mu_op": sd}},
                         "5eed0000")
    chks = [check(w, cost, controls) for w in drawn]
    return {"samples": samples, "relative_sd": sd, "seed": seed,
            "p_stall": float(np.mean([c.end == -SS.STALL for c in chks])),
            "p_tip": float(np.mean([c.end == -SS.TIP for c in chks])),
            "p_miss": float(np.mean([not c.reached for c in chks]))}
