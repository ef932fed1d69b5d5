"""The skid-steered vehicle on an elevation map, as a search problem for :mod:`sbmpc.search.astar`.

State: the closed-loop model's state vector (``dynamics.kernels``: wheel speeds, PID
references and integrals, currents, pose, time, energy, stall timer) plus two entries
for the grid, the wrapped heading and the speed at the end of the edge. So a child
carries its speed and controller state: the entry speed into a hill matters.

An edge holds a pair of desired wheel speeds (wl, wr) [rad/s] for one planning period
(a control's third column, where there is one, holds it that many periods: a held
control, ``planner.hold_periods``), stepping ``dynamics.kernels.step_slope`` every ``dt`` with the slope under the vehicle from
``maps.slope_grades_at`` and the terrain under its centre from the map's terrain layer.
Each step integrates against the grade at its midpoint, extrapolated linearly from the
grades at its start and at the last step's start (the first step of an edge takes its
start's): with the grade held from the step's start, the step was first order where
the grade changes along the way (a 1 s turn up a hill's skirt turned 1.4 % more at
20 ms than at 1 ms; now 0.05 %); the validity checks stay at each step's start.
It is invalid (codes below) when the vehicle leaves the map, pitches or rolls beyond the
tip-over limit, or stalls (drive saturated, commanded motion not achieved for
``STALL_TIME``). An edge that enters the goal disc ends there, so the last control of a
plan may be shorter than the period.

Edge cost: the edge's travel time [s] or battery energy [J] (no regeneration).
Heuristics, both lower bounds of the cost to go over the remaining straight-line
distance d to the goal disc:

* time: d / v_bound, v_bound the wheel radius times the largest sampled wheel speed
  plus 5 % (the PID holds the wheels to their commands; overshoot downhill is smaller);
* energy: what the wheels must at least do, with no regeneration counted:
  max(0, mu_roll,min m g cos(tip) d + m g (z_goal - z) - KE), where KE is the kinetic
  energy the vehicle carries (eq. 5's mass matrix) and z_goal the lowest height of the
  goal disc; electrical energy is at least the mechanical work of the motors.

Both are raised by a cost-to-go grid over the map (``sbmpc.planning.heuristics.cost_to_go``): Dijkstra
from the goal over the map's cells, with 8-neighbour steps that cost d / v_bound (time)
or the least battery energy of the step (energy, ``sbmpc.planning.heuristics.least_step_energy``:
rolling resistance and the climb's potential energy plus the least copper loss the
motors' currents must dissipate for them; a descent at most pays for its own rolling,
none is banked), scaled down by the octile-to-Euclidean ratio, and avoiding cells where
the vehicle tips over at every heading. It knows the shape of the ground that the
straight-line bounds cannot see: the hill to be climbed or gone around. A pose between
the grid's nodes reads the least over its cell's four corners of the corner's value less
the most the way from that corner to the pose may cost (``_node_to_pose``: the cell's
diagonal over v_bound, or the energy step bound for the distance and the climb from the
corner's height to the pose's; the map is bilinear, so the cell's highest corner is never below the pose and
its way costs no climb). The KE a node
carries is credited there times KEGRID, the largest slope dE/dW of the grid's step
bounds (``sbmpc.planning.heuristics.ke_factor``: KE spent on a step saves at most that much of
its bound). Its
one approximation: kinetic energy gained in a dip and spent on the next rise is not
credited beyond the KE the node carries now.

The heuristic is the larger of the two less the goal's gap
(``sbmpc.planning.heuristics._goal_gap``): the grid reaches the disc at its nodes inside, a path
ends at its edge, up to a cell before. Subtracted from every value alike, also near
the goal where that makes it negative, it leaves the weighted search's order as it
was; subtracted from the grid's read alone, or clamped at 0, it moved the energy plans
over seeds by +-3 % (ties are fragile, docs/performance.md).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from dynamics import kernels as K
from dynamics.drive import window_share
from maps.grid import aside_tilts, cell_value, height_at, pitch_roll_at, slope_grades_at, steepest_at

from ..search.astar import EXPAND, GOAL, HEURISTIC
from . import lattice as LA

# ---- extra state entries after the model's ------------------------------------------
X_YAWW = K.NS          # heading wrapped to (-pi, pi] [rad]
X_V = K.NS + 1         # speed at the end of the edge [m/s]
X_MT = K.NS + 2        # margin timer [s]: how long the drive has run within its margin (leaks as it fills)
X_TW = K.NS + 3        # the margin's pessimistic twin: its model state (K.NS entries) from here on
NX = 2 * K.NS + 3

# ---- invalid-edge codes (returned negated by propagate) -----------------------------
CODES = ("left the map", "stalled (drive saturated, commanded motion not achieved)", "tipped over (pitch or roll beyond the limit)",
         "ran out of margin (the drive within its reserve of its limits, or pitch or roll within the tip-over margin)")
OFF_MAP, STALL, TIP, MARGIN = 1, 2, 3, 4
# ---- edge ends ---------------------------------------------------------------------
IN_GOAL = 1
NO_ROWS = np.int64(0)   # no record rows written yet, as an int64: a literal 0 made numba compile edge
                        # and edge_cost a second time (a minute of a fresh clone's first compile)

# ---- params vector ---------------------------------------------------------------
(Q_DT, Q_NSTEP, Q_GX, Q_GY, Q_GR, Q_HL, Q_HW, Q_TIP, Q_RES, Q_OX, Q_OY, Q_NX, Q_NY,
 Q_COST, Q_VBOUND, Q_FROLL, Q_MG, Q_MKE, Q_ZG, Q_MARGIN, Q_OFFL, Q_OFFT, Q_BLOCK, Q_OFFD,
 Q_FRMAX, Q_KEGRID, Q_COPPER, Q_GOALGAP, Q_RESERVE, Q_TIPM, Q_OFFTW, Q_TWHEAD, Q_TWLAG,
 Q_HORIZON, Q_TURNCOST, Q_OFFV, Q_VNX, Q_VNY, Q_VCELL, Q_VOX, Q_VOY, Q_VW2, Q_TWGRADE, Q_ASIDE, Q_OFFS) = range(45)
NQ = 45
MARGIN_TIME = 0.5     # s: the drive may use more than 1 - reserve of its reach this long (the
                      # margin timer leaks at the rate it fills): a start from rest or a
                      # change of command saturates the PID for a moment by design
SQRT2 = math.sqrt(2.0)
COST_TIME, COST_ENERGY = 0.0, 1.0


@njit(cache=True, error_model="numpy")
def edge(params, data, S, cmd_l, cmd_r, nsteps, rec, rows, O):
    """Simulate one edge in place on S for up to ``nsteps`` steps (module doc). Every
    step is recorded into the rows of ``rec`` from row ``rows`` on, while there are any.
    ``O``: scratch for the model's outputs (K.NO). With a margin (``planner.margin``,
    module doc) the pessimistic twin in S[X_TW:] steps along. Returns (end, rows): end is 0 (full
    period), IN_GOAL (stopped in the goal disc) or a negative code. Allocates nothing:
    the same code runs as a CUDA device function (:mod:`sbmpc.problems.skidsteer_cuda`)."""
    dt = params[Q_DT]
    res = params[Q_RES]
    ox = params[Q_OX]
    oy = params[Q_OY]
    nx = int(params[Q_NX])
    ny = int(params[Q_NY])
    H = data[:nx * ny].reshape((ny, nx))
    offl = int(params[Q_OFFL])
    has_layer = offl >= 0
    L = data[max(offl, 0):max(offl, 0) + nx * ny].reshape((ny, nx))
    offt = int(params[Q_OFFT])
    block = int(params[Q_BLOCK])
    tip = params[Q_TIP]
    tan_tip = math.tan(tip)         # the tip-over limit as a grade (no arctangent per step)
    # the margin (module doc): the tip limit less its margin (= tip: none), the share of
    # the drive's reach kept in reserve while turning (0: none), the pessimistic twin
    tan_tipm = math.tan(min(params[Q_TIPM], tip))
    aside = params[Q_ASIDE]         # the margin (or the limit, without one) also judged this far aside [m]
    offs = int(params[Q_OFFS])      # the map's steepest slope near each cell (maps.grid.steepest_near; -1: none)
    Sn = data[max(offs, 0):max(offs, 0) + (nx - 1) * (ny - 1)].reshape((ny - 1, nx - 1))
    reserve = params[Q_RESERVE]
    full = 1.0 - reserve
    offw = int(params[Q_OFFTW])
    twin = offw >= 0
    T = S[X_TW:X_TW + K.NS] if twin else S[:0]
    Pw = data[max(offw, 0):max(offw, 0) + K.NP]
    c_head = math.cos(params[Q_TWHEAD])     # the twin's heading error (margin_heading_deg)
    s_head = math.sin(params[Q_TWHEAD])
    a_grade = params[Q_TWGRADE]             # the twin's grade allowance (margin_grade_deg) [rad]
    if cmd_l + cmd_r < 0.0:
        a_grade = -a_grade                  # reversing: the climb is nose-down, steeper downwards
    prev_w = 0.0
    lag_cap = params[Q_TWLAG]
    v_end = 0.0
    margin = params[Q_MARGIN]
    x_lo = ox + margin
    y_lo = oy + margin
    x_hi = ox + (nx - 1) * res - margin
    y_hi = oy + (ny - 1) * res - margin
    gx = params[Q_GX]
    gy = params[Q_GY]
    gr2 = params[Q_GR] * params[Q_GR]
    for d in range(O.shape[0]):
        O[d] = 0.0
    record = rec.shape[0] > 0
    end = 0
    stepped = False
    kp = 0                              # the terrain (index into the layer's terrains) ...
    Pk = data[offt:offt + K.NP]         # ... its model parameters and friction table
    Tk = data[offt + K.NP:offt + block]
    prev = 0.0
    for i in range(nsteps + 1):
        x = S[K.S_X]
        y = S[K.S_Y]
        if x < x_lo or x > x_hi or y < y_lo or y > y_hi:
            end = -OFF_MAP
            break
        yaw_i = S[K.S_YAW]
        along, across = slope_grades_at(H, res, ox, oy, x, y, yaw_i, params[Q_HL], params[Q_HW])
        if abs(along) > tan_tip or abs(across) > tan_tip:
            end = -TIP
            break
        if abs(along) > tan_tipm or abs(across) > tan_tipm:
            end = -MARGIN
            break
        if (aside > 0.0 and (offs < 0 or steepest_at(Sn, res, ox, oy, x, y) > tan_tipm)
                and aside_tilts(H, res, ox, oy, x, y, yaw_i, params[Q_HL], params[Q_HW], aside) > tan_tipm):
            # (where no slope near the vehicle passes the limit, no footprint aside can)
            end = -MARGIN
            break
        if i > 0 and (x - gx) * (x - gx) + (y - gy) * (y - gy) <= gr2:
            end = IN_GOAL
            break
        if i == nsteps:
            break
        if has_layer:
            k = int(cell_value(L, res, ox, oy, x, y))
            if k != kp:                 # the terrain under the vehicle changed
                a = offt + k * block
                Pk = data[a:a + K.NP]
                Tk = data[a + K.NP:a + block]
                kp = k
                if twin:
                    a = offw + k * block
                    Pw = data[a:a + K.NP]
        # the step integrates against the grade at its midpoint, extrapolated from the
        # grades at this step's start and the last one's (at the start alone the step
        # was first order on a changing grade)
        g = along + 0.5 * (along - prev) if i > 0 else along
        prev = along
        cp = 1.0 / math.sqrt(1.0 + g * g)     # the pitch's cosine and sine
        K.step_slope(Pk, Tk, S, cmd_l, cmd_r, g * cp, cp, dt, K.CLOSED_LOOP, O)
        v_end = O[K.O_V]
        stepped = True
        if record and rows < rec.shape[0]:
            S[K.S_Z] = height_at(H, res, ox, oy, S[K.S_X], S[K.S_Y])
            K.record(S, O, math.atan(along), rec[rows])
            rows += 1
        if S[K.S_STALLED] > 0.0:
            end = -STALL
            break
        if reserve > 0.0 and cmd_l != cmd_r:
            # the margin, while the commands turn: the drive keeps ``reserve`` of its
            # reach (eq. 27's window at the wheel's speed) unused, except for MARGIN_TIME
            # at a time. While it does, the PID holds the commanded wheel speeds for a
            # vehicle that needs up to 1 / (1 - reserve) times the torque (heavier, more
            # grip, a weaker supply), and such a vehicle turns on the same path; a turn
            # at the drive's limit has the radius its friction and mass allow, and a
            # heading error never closes in open loop. (Straight commands drive a
            # symmetric vehicle straight whatever it weighs: there the twin judges.)
            vm = max(Pk[K.P_VMAX] - Pk[K.P_SAG] * S[K.S_E], 0.0)
            sl = window_share(O[K.O_IL], S[K.S_WL], vm, Pk[K.P_K] * Pk[K.P_KSL], Pk[K.P_RA], Pk[K.P_IMAX])
            sr = window_share(O[K.O_IR], S[K.S_WR], vm, Pk[K.P_K] * Pk[K.P_KSR], Pk[K.P_RA], Pk[K.P_IMAX])
            if sl > full or sr > full:
                S[X_MT] += dt
                if S[X_MT] > MARGIN_TIME:
                    end = -MARGIN
                    break
            else:
                S[X_MT] = max(0.0, S[X_MT] - dt)
        if twin:
            # the pessimistic twin, under the same commands from its own drive state: it
            # loses speed on a climb at the drive's limit and carries less into the next.
            # It drives with the vehicle's heading from its own position, so it meets the
            # grade where it is (behind, on the steep part of a ramp the vehicle has
            # topped); it falls at most Q_TWLAG behind (a run re-plans beyond its
            # position tolerance). Its heading may be off by up to the margin's heading
            # error, and it takes the steeper of the two grades it would then meet (a
            # plane: along cos e +- across sin e); with a grade allowance (the map's
            # slopes that far off) it meets each grade that much steeper uphill in the
            # direction it drives (forwards nose-up, reversing nose-down; the pitch
            # kept within +-86 deg). The edge fails where it stalls
            tx = T[K.S_X]
            ty = T[K.S_Y]
            if x_lo <= tx <= x_hi and y_lo <= ty <= y_hi:
                al_t, ac_t = slope_grades_at(H, res, ox, oy, tx, ty, yaw_i, params[Q_HL], params[Q_HW])
            else:
                al_t = along
                ac_t = across
            gw = al_t * c_head + (s_head * abs(ac_t) if al_t >= 0.0 else -s_head * abs(ac_t))
            if a_grade != 0.0:
                gw = math.tan(max(-1.5, min(1.5, math.atan(gw) + a_grade)))
            gm = gw + 0.5 * (gw - prev_w) if i > 0 else gw
            prev_w = gw
            cw = 1.0 / math.sqrt(1.0 + gm * gm)
            T[K.S_YAW] = yaw_i
            K.step_slope(Pw, Tk, T, cmd_l, cmd_r, gm * cw, cw, dt, K.CLOSED_LOOP, O)
            lx = S[K.S_X] - T[K.S_X]
            ly = S[K.S_Y] - T[K.S_Y]
            lag = math.sqrt(lx * lx + ly * ly)
            if lag > lag_cap:
                T[K.S_X] = S[K.S_X] - lx * (lag_cap / lag)
                T[K.S_Y] = S[K.S_Y] - ly * (lag_cap / lag)
            if T[K.S_STALLED] > 0.0:
                end = -MARGIN
                break
    if stepped:
        # the height under the vehicle: the model's own z (integrated along the pitch)
        # is replaced by the map's; nothing within the edge reads it
        S[K.S_Z] = height_at(H, res, ox, oy, S[K.S_X], S[K.S_Y])
    yaw = S[K.S_YAW]
    S[X_YAWW] = yaw - 2.0 * math.pi * math.floor((yaw + math.pi) / (2.0 * math.pi))
    S[X_V] = v_end if i > 0 else S[X_V]
    return end, rows


@njit(cache=True, error_model="numpy")
def edge_cost(params, data, state, control, out, rec, rows, O):
    """One SBMPC edge from ``state`` into ``out``: its cost (time [s] or energy [J]) or
    a negative invalid code (``rec``, ``rows``, ``O``: as :func:`edge`; no allocation)."""
    for d in range(out.shape[0]):
        out[d] = state[d]
    n = int(params[Q_NSTEP])
    if control.shape[0] > 2:            # (wl, wr, periods): a control held over several periods
        n = int(round(n * control[2]))
    end, _ = edge(params, data, out, control[0], control[1], n, rec, rows, O)
    if end < 0:
        return float(end)
    if params[Q_COST] == COST_TIME:
        return out[K.S_T] - state[K.S_T]
    return out[K.S_E] - state[K.S_E]


@njit(cache=True, error_model="numpy")
def propagate(params, data, state, control, out):
    """One SBMPC edge: cost (time [s] or energy [J]) or a negative invalid code."""
    return edge_cost(params, data, state, control, out, np.empty((0, K.NR)), NO_ROWS, np.empty(K.NO))


@njit(EXPAND.signature, cache=True, error_model="numpy", parallel=True)
def expand(params, data, work, state, controls, children, costs):
    """The edges of one expansion (:mod:`sbmpc.search.astar`), one :func:`propagate` per
    control, over numba's current threads (the serial search sets them to 1). A prange
    loop even on one thread: numba compiles a parallel loop's body into code about a
    third faster per edge than the same loop without it (on hill_tradeoff's search
    nodes 11.3 against 17.1 us per edge, the same results to the bit; 2026-11-30)."""
    for b in prange(controls.shape[0]):
        costs[b] = propagate(params, data, state, controls[b], children[b])


@njit(cache=True, error_model="numpy", parallel=True)
def expand_batch(params, data, parents, owner, controls, children, costs):
    """The edges of a batch of nodes (``Problem.expand_batch``), in parallel over numba's
    threads: edge e from ``parents[owner[e]]`` under ``controls[e]``."""
    for e in prange(owner.shape[0]):
        costs[e] = propagate(params, data, parents[owner[e]], controls[e], children[e])


@njit(cache=True, error_model="numpy")
def step_work(f_roll, rise, d, c):
    """Per side (W [J], L [m]) of :func:`step_energy`'s minimum: the work and the rolled
    distance L >= d at which W + c W^2 / L is least (L* = rise sqrt(c / (f_roll (2 + c
    f_roll))) when that exceeds d)."""
    a = max(0.5 * f_roll, 1e-12)
    b = 0.5 * rise
    L = d
    if b > 0.0:
        L = max(d, b * math.sqrt(c / (a * (1.0 + c * a))))
    return a * L + b, L


@njit(cache=True, error_model="numpy")
def step_energy(f_roll, rise, d, c):
    """Least battery energy [J] of a step of length d [m] rising by ``rise`` = m g dz [J]
    against a rolling force f_roll [N], c [1/N] the copper coefficient: 2 (W + c W^2 / L)
    at :func:`step_work`'s minimum, 0 with nothing to climb against (the derivation:
    ``sbmpc.planning.heuristics.least_step_energy``, its array form for the cost-to-go grid)."""
    if f_roll * d + rise <= 0.0:
        return 0.0
    W, L = step_work(f_roll, rise, d, c)
    return 2.0 * (W + c * W * W / max(L, 1e-12))


@njit(cache=True, error_model="numpy", inline="always")
def _node_to_pose(params, dx, dy, dz):
    """The most the way from a cost-to-go node to a pose (dx, dy, dz) [m] away may
    cost [s or J], which the grid's value at the node may exceed the pose's cost to go
    by: for energy the step bound (:func:`step_energy`) at the map's largest rolling
    force, for the distance and the pose's height above the node (the map is bilinear:
    the highest corner of a cell is never below the pose). For time the cell's diagonal
    over v_bound, not the distance: the tighter read made the weighted time search
    greedier (steep_hill's time plan 36.3 -> 37.5 s, narrow_pass's 49.1 -> 52.1 s), and
    the energy read's gain is the blocked flanks' climbs, which time never had."""
    if params[Q_COST] == COST_TIME:
        return SQRT2 * params[Q_RES] / params[Q_VBOUND]
    return step_energy(params[Q_FRMAX], params[Q_MG] * dz, math.sqrt(dx * dx + dy * dy), params[Q_COPPER])


@njit(cache=True, error_model="numpy", inline="always")
def _heading_error(params, data, state, dx, dy):
    """|angle| [rad] between the heading of ``state`` and the way on: down the cost-to-go
    grid's slope where there is one (bilinear over the surrounding nodes), else towards
    the goal (dx, dy). The horizon search's terminal cost charges a turn it leaves to
    after the horizon (:mod:`sbmpc.planning.horizon`); the grid knows no heading."""
    gx = dx
    gy = dy
    offd = int(params[Q_OFFD])
    if offd >= 0:
        nx = int(params[Q_NX])
        ny = int(params[Q_NY])
        res = params[Q_RES]
        u = (state[K.S_X] - params[Q_OX]) / res
        v = (state[K.S_Y] - params[Q_OY]) / res
        i = min(max(int(math.floor(u)), 0), nx - 2)
        j = min(max(int(math.floor(v)), 0), ny - 2)
        fu = min(max(u - i, 0.0), 1.0)
        fv = min(max(v - j, 0.0), 1.0)
        a = offd + j * nx + i
        c00, c10, c01, c11 = data[a], data[a + 1], data[a + nx], data[a + nx + 1]
        sx = -((c10 - c00) * (1.0 - fv) + (c11 - c01) * fv)
        sy = -((c01 - c00) * (1.0 - fu) + (c11 - c10) * fu)
        if sx * sx + sy * sy > 0.0:
            gx = sx
            gy = sy
    e = (state[K.S_YAW] - math.atan2(gy, gx) + math.pi) % (2.0 * math.pi) - math.pi
    return abs(e)


@njit(HEURISTIC.signature, cache=True, error_model="numpy")
def heuristic(params, data, state):
    """Lower bound of the time [s] or energy [J] to the goal disc (module doc): the larger
    of the straight-line bound and the map's cost-to-go grid (when present)."""
    x = state[K.S_X]
    y = state[K.S_Y]
    dx = params[Q_GX] - x
    dy = params[Q_GY] - y
    d = math.sqrt(dx * dx + dy * dy) - params[Q_GR]
    if d < 0.0:
        d = 0.0
    ke = 0.0
    if params[Q_COST] == COST_TIME:
        h = d / params[Q_VBOUND]
    else:
        wl = state[K.S_WL]
        wr = state[K.S_WR]
        ke = 0.5 * params[Q_MKE] * (wl * wl + wr * wr)
        h = params[Q_FROLL] * d + params[Q_MG] * (params[Q_ZG] - state[K.S_Z]) - ke
    offd = int(params[Q_OFFD])
    if offd >= 0:
        # cost-to-go grid: the least over the four surrounding nodes of the node's cost
        # less the most the way from that node to (x, y) can cost (_node_to_pose)
        nx = int(params[Q_NX])
        ny = int(params[Q_NY])
        res = params[Q_RES]
        u = (x - params[Q_OX]) / res
        v = (y - params[Q_OY]) / res
        i = min(max(int(math.floor(u)), 0), nx - 2)
        j = min(max(int(math.floor(v)), 0), ny - 2)
        c = math.inf
        for dj in range(2):
            for di in range(2):
                a = (j + dj) * nx + i + di
                way = _node_to_pose(params, (u - i - di) * res, (v - j - dj) * res, state[K.S_Z] - data[a])
                c = min(c, data[offd + a] - way)
        hd = c - params[Q_KEGRID] * ke
        if hd > h:
            h = hd
    offv = int(params[Q_OFFV])
    known = False
    if offv >= 0:
        # the value over position and heading (sbmpc.planning.value): the horizon's
        # terminal cost; in a whole-route search raised towards it, at most to w2 times
        # the admissible value (the answer within about w w2 of the optimum over the search's
        # grid: docs/planner.md)
        nxv = int(params[Q_VNX])
        nyv = int(params[Q_VNY])
        vv = LA.read(data[offv:offv + nxv * nyv * LA.NH], nxv, nyv, params[Q_VCELL], params[Q_VOX], params[Q_VOY],
                     x, y, state[K.S_YAW])
        if not math.isinf(vv):
            known = True
            vv -= ke
            if params[Q_HORIZON] > 0.0:
                if vv > h:
                    h = vv
            elif vv > h:
                h = min(vv, params[Q_VW2] * h) if h > 0.0 else h
    if not known and params[Q_HORIZON] > 0.0 and params[Q_TURNCOST] > 0.0 and d > 0.0:
        # the grid alone (no value, or none where the pose is): the turn it knows nothing of
        h += params[Q_TURNCOST] * _heading_error(params, data, state, dx, dy)
    # less the goal's gap, after the clamp: every value moves by the same constant (may
    # go below 0 near the goal), so the weighted search's order stays as without it
    return (h if h > 0.0 else 0.0) - params[Q_GOALGAP]


@njit(GOAL.signature, cache=True, error_model="numpy")
def is_goal(params, data, state):
    """In the goal disc; or, with a horizon (params[Q_HORIZON] > 0: the end of a
    receding-horizon search's look-ahead, a planner time [s]), at or past it: the search
    then ends at the horizon node of least g + w h, the heuristic its terminal cost."""
    dx = params[Q_GX] - state[K.S_X]
    dy = params[Q_GY] - state[K.S_Y]
    if dx * dx + dy * dy <= params[Q_GR] * params[Q_GR]:
        return True
    return params[Q_HORIZON] > 0.0 and state[K.S_T] >= params[Q_HORIZON]


@njit(cache=True, error_model="numpy")
def replay(params, data, start, cmd_l, cmd_r, nsteps, rec):
    """Replay controls (cmd_l[i], cmd_r[i]) each for nsteps[i] steps from ``start``,
    recording every step into ``rec`` (row 0 the start) while it has rows (none: nothing
    recorded). Returns (rows, end state, end code of the last edge, index of the edge
    that ended the replay early or -1)."""
    S = start.copy()
    O = np.zeros(K.NO)
    a = int(params[Q_OFFT])
    K.state_outputs(data[a:a + K.NP], S, O)
    nx = int(params[Q_NX])
    ny = int(params[Q_NY])
    H = data[:nx * ny].reshape((ny, nx))
    pitch, _ = pitch_roll_at(H, params[Q_RES], params[Q_OX], params[Q_OY], S[K.S_X], S[K.S_Y],
                             S[K.S_YAW], params[Q_HL], params[Q_HW])
    rows = 0
    if rec.shape[0] > 0:            # (numba checks no bounds: an empty rec is written nowhere)
        K.record(S, O, pitch, rec[0])
        rows = 1
    end = 0
    for e in range(cmd_l.shape[0]):
        end, rows = edge(params, data, S, cmd_l[e], cmd_r[e], nsteps[e], rec, rows, O)
        if end < 0 or (end == IN_GOAL and e < cmd_l.shape[0] - 1):
            return rows, S, end, e
    return rows, S, end, -1


# ---- control sequences (the polish of a found plan: sbmpc.planning.polish) -----------------
NOT_REACHED = 5.0     # returned negated: the sequence ended outside the goal disc
PRUNED = np.inf       # returned when the cost so far already reaches the bound


@njit(cache=True, error_model="numpy")
def sequence_cost(params, data, state, ctrl, first, extra, bound, out):
    """Drive the controls ``ctrl[first:]`` ((n, 3): desired wheel speeds [rad/s] and
    durations [s]) from ``state``, the last one held up to ``extra`` steps longer, until
    the vehicle enters the goal disc; ``out`` receives the end state. Returns (cost,
    controls used, duration of the last one [s]): the time [s] or energy [J] spent from
    ``state``; a negative code when an edge fails or the sequence ends outside the goal
    (-NOT_REACHED); PRUNED when the cost reaches ``bound`` on the way (time and energy
    never decrease along a drive, so such a sequence cannot beat it)."""
    for d in range(out.shape[0]):
        out[d] = state[d]
    O = np.empty(K.NO)
    rec = np.empty((0, K.NR))
    dt = params[Q_DT]
    energy = params[Q_COST] != COST_TIME
    n = ctrl.shape[0]
    for k in range(first, n):
        steps = max(1, int(round(ctrl[k, 2] / dt)))
        if k == n - 1:
            steps += extra
        t0 = out[K.S_T]
        end, _ = edge(params, data, out, ctrl[k, 0], ctrl[k, 1], steps, rec, NO_ROWS, O)
        if end < 0:
            return float(end), k - first + 1, out[K.S_T] - t0
        c = out[K.S_E] - state[K.S_E] if energy else out[K.S_T] - state[K.S_T]
        if end == IN_GOAL:
            return c, k - first + 1, out[K.S_T] - t0
        if c >= bound:
            return PRUNED, k - first + 1, out[K.S_T] - t0
    return -NOT_REACHED, n - first, 0.0


@njit(cache=True, error_model="numpy", parallel=True)
def sequence_costs(params, data, state, ctrl, first, moves, extra, bound, costs, used, last):
    """:func:`sequence_cost` of many variants of ``ctrl`` from ``state`` at control
    ``first``, in parallel over numba's threads: variant m replaces the wheel speeds of
    controls ``first`` and ``first + 1`` by ``moves[m]`` (wl, wr, wl', wr')."""
    for m in prange(moves.shape[0]):
        seq = ctrl.copy()
        seq[first, 0] = moves[m, 0]
        seq[first, 1] = moves[m, 1]
        if first + 1 < seq.shape[0]:
            seq[first + 1, 0] = moves[m, 2]
            seq[first + 1, 1] = moves[m, 3]
        out = np.empty(state.shape[0])
        costs[m], used[m], last[m] = sequence_cost(params, data, state, seq, first, extra, bound, out)


@njit(cache=True, error_model="numpy")
def sequence_states(params, data, state, ctrl, states):
    """The states (n, NX) at the starts of the controls ``ctrl`` (n, 3) driven from
    ``state`` (each for its duration; no goal test): states[k] before control k."""
    O = np.empty(K.NO)
    rec = np.empty((0, K.NR))
    S = state.copy()
    dt = params[Q_DT]
    for k in range(ctrl.shape[0]):
        for d in range(S.shape[0]):
            states[k, d] = S[d]
        if k < ctrl.shape[0] - 1:
            edge(params, data, S, ctrl[k, 0], ctrl[k, 1], max(1, int(round(ctrl[k, 2] / dt))), rec, NO_ROWS, O)
