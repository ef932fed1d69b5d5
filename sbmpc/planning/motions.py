"""What the vehicle's own steady motions cost, per terrain and grade: the tables the
value (:mod:`sbmpc.planning.value`) is built from.

Each table row is one steady manoeuvre of the closed-loop model (``dynamics.kernels``:
the PID wheel-speed loops, the current and voltage limits of eqs. 26-27, the
shear-displacement friction, gravity on the grade, eqs. 24-25) under a constant pair of
desired wheel speeds: straight ahead at four speeds, straight back at two, arcs of ten
radii and pivots at two speeds, all within the planner's sampled wheel-speed range. Each
is driven on a constant grade from the model's steady state at its commands
(``Model.state``) for SETTLE_S, then measured over MEASURE_S: its speed [m/s], its yaw
rate [rad/s], its battery power [W] (no regeneration where the vehicle has none), and
whether the drive holds it (no stall, its wheel speeds no longer drifting, eq. 27's window kept within ``planner.margin_turn``
of its reach on turns, as the search's edges judge it) for the planning vehicle and for
the margin's pessimistic twin (:func:`sbmpc.planning.world.pessimistic`), which meets
each grade ``planner.margin_grade_deg`` steeper, as on the edges. The model
takes the grade along the heading only (cross-slope enters its tip-over check, which the
value makes per lattice state), so the tables run over one grade: -GRADE_MAX to
+GRADE_MAX [deg] in GRADE_STEP steps.

From these the per-metre and per-radian costs of the value's lattice motions
(:func:`motion_costs`): straight, reverse, arc and pivot, for time [s] or energy [J].
The tables are made once per (vehicle, terrains, margin, wheel-speed range, dt) and
cached in memory (the model is the same for every goal and map).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from dynamics import kernels as K
from dynamics.drive import window_share
from dynamics.resistance import friction_table
from dynamics.simulate import Model

from .heuristics import RUNUP_DEG    # straight climbs this much past the steepest held: a run-up (the grid's rule)
from .world import World, pessimistic, wheel_speed_range

GRADE_MAX = 30.0     # deg: the tables' grades, either way (beyond the tip-over limit of 30 deg no state is open)
GRADE_STEP = 1.25    # deg
SETTLE_S = 1.5       # s: driven before measuring (from the steady state the command would have on level ground)
MEASURE_S = 1.0      # s: measured
STEADY = 0.03        # of the larger command: the most a held manoeuvre's wheel speeds drift while measured

ARC_OUTER = (1.0, 0.7, 0.4)                          # of hi: the outer wheel of an arc
ARC_INNER = (0.9, 0.8, 0.65, 0.5, 0.3, 0.1, -0.1)    # of the outer: the inner wheel
PIVOT_SPEEDS = (0.1, 0.2, 0.3, 0.5, 1.0)            # of |lo|: a pivot's wheels, either way
# (the drive saturates in a fast skid turn and stalls: the P3-AT on asphalt turns at
# 0.14 rad/s at rest, 0.2 rad/s at 0.5 m/s, docs/research-log.md)

# command kinds
STRAIGHT, REVERSE, ARC, PIVOT = 0, 1, 2, 3


def commands(world: World) -> tuple:
    """(cmds (C, 2) [rad/s], kinds (C,)): the manoeuvres tabulated, within the planner's
    sampled wheel-speed range [lo, hi]: straight at 1/4 to 1 of hi, reverse at 1/2 and 1
    of lo, left arcs (right wheel the outer at ARC_OUTER of hi, the inner at ARC_INNER of
    it, no lower than lo) and left pivots at PIVOT_SPEEDS of |lo| (the vehicle is taken
    symmetric: a right turn costs what the left one does)."""
    lo, hi = wheel_speed_range(world)
    rows, kinds = [], []
    for f in (0.25, 0.5, 0.75, 1.0):
        rows.append((f * hi, f * hi))
        kinds.append(STRAIGHT)
    if lo < 0.0:
        for f in (0.5, 1.0):
            rows.append((f * lo, f * lo))
            kinds.append(REVERSE)
    for outer in ARC_OUTER:
        for inner in ARC_INNER:
            rows.append((max(lo, inner * outer * hi), outer * hi))
            kinds.append(ARC)
    if lo < 0.0:
        for f in PIVOT_SPEEDS:
            w = min(-f * lo, hi)
            rows.append((-w, w))
            kinds.append(PIVOT)
    return np.array(rows, float), np.array(kinds, np.int64)


def grades() -> np.ndarray:
    """The tables' grades [rad] (pitch along the heading, nose up positive)."""
    n = int(round(2 * GRADE_MAX / GRADE_STEP))
    return np.radians(np.linspace(-GRADE_MAX, GRADE_MAX, n + 1))


@njit(cache=True, error_model="numpy", parallel=True)
def _steady(P, T, S0, which, cmd, pitch, dt, n_settle, n_meas, reserve, out):
    """Every row r: model block which[r] (rows of P, T), start state S0[r], commands
    cmd[r] held on pitch[r] [rad] for n_settle then n_meas steps of dt [s]; out[r]: speed
    [m/s], yaw rate [rad/s], battery power [W] over the measured steps, 1 where the drive
    held it (no stall, the wheel speeds steady within STEADY of the larger command over
    the measured steps; with ``reserve`` > 0 and a turning command, eq. 27's window used
    beyond 1 - reserve of its reach at most 0.5 s at a time, skidsteer.MARGIN_TIME)."""
    for r in prange(S0.shape[0]):
        S = S0[r].copy()
        O = np.zeros(K.NO)
        Pk = P[which[r]]
        Tk = T[which[r]]
        sp = math.sin(pitch[r])
        cp = math.cos(pitch[r])
        turning = cmd[r, 0] != cmd[r, 1]
        ok = 1.0
        timer = 0.0
        x0 = 0.0
        y0 = 0.0
        yaw0 = 0.0
        e0 = 0.0
        wl0 = 0.0
        wr0 = 0.0
        for i in range(n_settle + n_meas):
            if i == n_settle:
                x0 = S[K.S_X]
                y0 = S[K.S_Y]
                yaw0 = S[K.S_YAW]
                e0 = S[K.S_E]
                wl0 = S[K.S_WL]
                wr0 = S[K.S_WR]
            K.step_slope(Pk, Tk, S, cmd[r, 0], cmd[r, 1], sp, cp, dt, K.CLOSED_LOOP, O)
            if S[K.S_STALLED] > 0.0:
                ok = 0.0
                break
            if reserve > 0.0 and turning:
                vm = max(Pk[K.P_VMAX] - Pk[K.P_SAG] * S[K.S_E], 0.0)
                sl = window_share(O[K.O_IL], S[K.S_WL], vm, Pk[K.P_K] * Pk[K.P_KSL], Pk[K.P_RA], Pk[K.P_IMAX])
                sr = window_share(O[K.O_IR], S[K.S_WR], vm, Pk[K.P_K] * Pk[K.P_KSR], Pk[K.P_RA], Pk[K.P_IMAX])
                if sl > 1.0 - reserve or sr > 1.0 - reserve:
                    timer += dt
                    if timer > 0.5:
                        ok = 0.0
                        break
                else:
                    timer = max(0.0, timer - dt)
        tm = n_meas * dt
        # steady: the wheels' speeds no longer drifting (a drive losing speed on a grade
        # it cannot hold stalls later)
        top = max(abs(cmd[r, 0]), abs(cmd[r, 1]))
        if ok > 0.0 and (abs(S[K.S_WL] - wl0) > STEADY * top or abs(S[K.S_WR] - wr0) > STEADY * top):
            ok = 0.0
        if ok > 0.0:
            dx = S[K.S_X] - x0
            dy = S[K.S_Y] - y0
            # signed along the heading at the window's middle
            ym = 0.5 * (S[K.S_YAW] + yaw0)
            out[r, 0] = (dx * math.cos(ym) + dy * math.sin(ym)) / tm
            out[r, 1] = (S[K.S_YAW] - yaw0) / tm
            out[r, 2] = (S[K.S_E] - e0) / tm
        else:
            out[r, 0] = 0.0
            out[r, 1] = 0.0
            out[r, 2] = 0.0
        out[r, 3] = ok


def _blocks(world: World):
    return [np.concatenate([K.pack(world.vehicle, t), friction_table(world.vehicle, t)]) for t in world.terrains]


_TABLES: dict = {}     # settings key (tables()) -> tables: a world's map plays no part


def tables(world: World) -> dict:
    """The steady manoeuvres of ``world``'s vehicle on its terrains (module doc), made
    once per (vehicle, terrains, margin settings, wheel-speed range, dt) and kept (not per
    world: every world of a run, a sweep or a corridor shares them): a dict of ``grades``
    (G,) [rad], ``cmds`` (C, 2) [rad/s], ``kinds`` (C,), and (n_terrains, G, C) arrays
    ``v`` [m/s], ``w`` [rad/s], ``p`` [W], ``ok`` and ``ok_twin`` (1 where the planning
    vehicle, and the margin's twin, hold the manoeuvre)."""
    ps = world.scenario.planner
    key = (world.vehicle, world.terrains, ps.margin, ps.margin_turn, ps.margin_grade_deg, wheel_speed_range(world),
           ps.dt)
    if key not in _TABLES:
        if len(_TABLES) >= 16:
            _TABLES.pop(next(iter(_TABLES)))
        _TABLES[key] = _make_tables(world)
    return _TABLES[key]


def _make_tables(world: World) -> dict:
    ps = world.scenario.planner
    cmds, kinds = commands(world)
    g = grades()
    worlds = [world]
    if ps.margin > 0.0:
        worlds.append(pessimistic(world))
    nt, ng, nc = len(world.terrains), g.size, cmds.shape[0]
    blocks = [b for w in worlds for b in _blocks(w)]
    P = np.ascontiguousarray(np.array([b[:K.NP] for b in blocks]))
    T = np.ascontiguousarray(np.array([b[K.NP:] for b in blocks]))
    rows_which, rows_S, rows_cmd, rows_pitch = [], [], [], []
    allow = math.radians(ps.margin_grade_deg)   # the twin meets each grade this much steeper (as the edges:
    # in the direction it drives, nose-down reversing)
    for wi, w in enumerate(worlds):
        for ti, terr in enumerate(w.terrains):
            m = Model(w.vehicle, terr, ps.dt)
            v = w.vehicle
            # the steady state of each command on level ground (the same for every grade)
            starts = [m.state(wl / v.radius_scale_left, wr / v.radius_scale_right, 0.0) for wl, wr in cmds]
            for pitch in g:
                for ci in range(nc):
                    rows_which.append(wi * nt + ti)
                    rows_S.append(starts[ci])
                    rows_cmd.append(tuple(cmds[ci]))
                    rows_pitch.append(pitch + (math.copysign(allow, cmds[ci][0] + cmds[ci][1] + 0.0) if wi else 0.0))
    out = np.zeros((len(rows_S), 4))
    dt = ps.dt
    _steady(P, T, np.ascontiguousarray(np.array(rows_S)), np.array(rows_which, np.int64),
            np.ascontiguousarray(np.array(rows_cmd)), np.array(rows_pitch), dt,
            int(round(SETTLE_S / dt)), int(round(MEASURE_S / dt)), ps.margin_turn, out)
    out = out.reshape(len(worlds), nt, ng, nc, 4)
    veh = out[0]
    twin_ok = out[1, ..., 3] if len(worlds) > 1 else veh[..., 3]
    res = dict(grades=g, cmds=cmds, kinds=kinds, v=veh[..., 0].copy(), w=veh[..., 1].copy(),
               p=np.maximum(veh[..., 2], 0.0), ok=veh[..., 3] > 0.5, ok_twin=twin_ok > 0.5)
    for a in res.values():
        a.setflags(write=False)
    return res


def _runup(cost: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Straight costs (n_terrains, G) with the grades up to RUNUP_DEG beyond the steepest
    climb held costed as that climb (a run-up; the grid's rule)."""
    out = cost.copy()
    steps = int(round(RUNUP_DEG / GRADE_STEP))
    for t in range(cost.shape[0]):
        held = np.flatnonzero(np.isfinite(cost[t]) & (g >= 0.0))
        if held.size == 0:
            continue
        top = held[-1]
        out[t, top + 1:top + 1 + steps] = np.where(np.isfinite(out[t, top + 1:top + 1 + steps]),
                                                   out[t, top + 1:top + 1 + steps], cost[t, top])
    return out


def motion_costs(world: World, cost: str, chords: np.ndarray, turns: np.ndarray) -> dict:
    """Per terrain and grade (n_terrains, G), what the value's motions cost [s or J],
    inf where no tabulated manoeuvre of that kind is held there by the vehicle and its
    twin:

    * ``straight``, ``reverse``: per metre, the best held straight manoeuvre (time:
      1 / speed; energy: power / speed); straight climbs RUNUP_DEG past the steepest held
      cost what that one does;
    * ``pivot``: per radian, the best pivot held there and on level ground, at its
      level-ground rate (1 / yaw rate, or power / yaw rate);
    * an arc, a chord of ``chords[a]`` [m] driven while the heading turns by
      ``turns[b]`` [rad]: ``arc_turn`` (n_terrains, G, len(chords), len(turns)), among
      the arc commands held at that grade (and on level ground) by the vehicle and its
      twin (inf where none is), for time the best one's level max(chord / speed, turn /
      yaw rate) [s] (the arc takes at least that and at least the chord straight at its
      grades), for energy what the best one costs on the level beyond the chord straight
      there [J] (added to the chord's straight cost at its grades).

    Turns are costed on level ground because the model takes the grade along the
    heading only: a steady turn on a constant pitch has no counterpart on a real slope
    (the pitch changes with the heading; on a descent the tables' pivot rolls downhill
    and costs nothing). Where a turn is held on a grade still comes from the grade's
    rows (a turn on a flank stalls the drive).
    """
    tb = tables(world)
    kinds = tb["kinds"]
    held = tb["ok"] & tb["ok_twin"]
    v, w, p = tb["v"], tb["w"], tb["p"]
    g = tb["grades"]
    lvl = int(np.argmin(np.abs(g)))
    energy = cost == "energy"
    with np.errstate(divide="ignore", invalid="ignore"):
        def per(kind, rate, where):
            m = kinds == kind
            if not m.any():
                return np.full(v.shape[:2], np.inf)
            r = np.abs(rate[:, lvl:lvl + 1, m] if where == "level" else rate[..., m])
            pw = p[:, lvl:lvl + 1, m] if where == "level" else p[..., m]
            c = (pw if energy else 1.0) / r
            ok = held[..., m] & (held[:, lvl:lvl + 1, m] if where == "level" else True)
            c = np.where(ok & (r > 1e-3), c, np.inf)
            return c.min(axis=-1)
        straight = _runup(per(STRAIGHT, v, "grade"), g)
        reverse = per(REVERSE, v, "grade")
        pivot = per(PIVOT, w, "level")
        m = kinds == ARC
        va, wa, pa = v[:, lvl, m], w[:, lvl, m], p[:, lvl, m]           # (n_terrains, A) on the level
        ha = held[..., m] & held[:, lvl:lvl + 1, m]                      # (n_terrains, G, A)
        arc_turn = np.full(v.shape[:2] + (len(chords), len(turns)), np.inf)
        for a, L in enumerate(chords):
            flat = L * straight[:, lvl]
            for b, dpsi in enumerate(turns):
                t = np.maximum(L / np.where(va > 1e-3, va, np.nan), dpsi / np.where(wa > 1e-3, wa, np.nan))
                c = pa * t if energy else t                               # (n_terrains, A)
                good = ha & np.isfinite(c)[:, None, :]                     # (n_terrains, G, A)
                best = np.where(good, c[:, None, :], np.inf).min(axis=-1)  # among the arcs held at each grade
                arc_turn[..., a, b] = np.maximum(best - flat[:, None], 0.0) if energy else best
    return dict(straight=straight, reverse=reverse, pivot=pivot, arc_turn=arc_turn)
