"""A value that knows the vehicle: V(x, y, heading), the cost [s or J] of the rest of the
way to the goal disc for this vehicle, with the margin, from every pose of a lattice.

Lattice: the map's ground every ``planner.value_cell`` metres (0.5; coarser past
MAX_STATES states, :func:`lattice_cell`) x 16 headings,
those of the grid vectors (1, 0), (2, 1), (1, 1), (1, 2), ... (Pivtoraiko and Kelly's
and Smac's choice: a straight step along a heading ends on a lattice point).

Motions from a state (i, j, k), the vehicle's own (:mod:`sbmpc.planning.motions`):

* straight: one step of heading k's vector, at the best steady speed the drive holds on
  the grade along heading k there (time) or its least energy per metre (energy);
* reverse: the same vector backwards (where the planner samples reverse wheel speeds);
* arc: 1, 2 or 4 steps of that vector ending at heading k +- 1 (a chord of 1 to 6.3
  cells turning 18-27 deg), at the best held steady arc;
* pivot: heading k +- 1 in place.

Each costs what the tables of the closed-loop model say for the terrain under the state
and the grade along its heading (the tables' grade axis, linear between its nodes), and
is closed where neither the vehicle nor the margin's twin holds it there. A state is
closed where the vehicle's footprint, at that heading, pitches or rolls beyond the
tip-over limit less its margin (``planner.margin_tip_deg``, as the search's edges), or
does so with the vehicle ``planner.margin_aside_m`` to its left or right (as the edges
judge the margin: :func:`maps.grid.aside_tilts`), or lies closer to the map's edge than the footprint's half-diagonal.

One backward Dijkstra from the goal disc's lattice states (value 0) over the reversed
motions (compiled, :func:`_dijkstra`) gives V up to REACH times the start's value;
beyond that, and outside the cost-to-go grid's window (``heuristics.ctg_window``), V is
infinite and the search reads the grid.

V is no lower bound: the tables are steady (a transient costs more, a climb's kinetic
energy less), the 16 headings make the lattice's paths up to 8 % longer than the
straight line, and a coarse lattice cell may close a pass the vehicle fits through.
So the search keeps the admissible grid as its anchor (:mod:`sbmpc.problems.skidsteer`'s
heuristic, ``planner.value_w2`` and ``value_energy_w2``) and the horizon takes V as its
terminal cost.

Made once per (map, terrains, vehicle, margin, goal, start, cost) and kept in memory (every
re-plan and horizon plan of a run, every seed of a sweep, reads the same) and on disk by
content (``$SBMPC_CACHE_DIR``, as the friction tables: :func:`_cache_path`).
"""
from __future__ import annotations

import functools
import hashlib
import inspect
import math
import os
from dataclasses import dataclass

import numpy as np
from numba import njit

from dynamics.resistance import _cache_dir
from maps.grid import aside_tilts, height_at, slope_grades_at

from ..problems import lattice as LA
from . import motions as MO
from .heuristics import ctg_window
from .world import World, wheel_speed_range

VECTORS = np.array(LA.VECTORS, np.int64)
NH = LA.NH
ANGLES = np.array(LA.ANGLES_T)                                     # ascending from 0
CHORDS = np.array([1.0, math.sqrt(5.0), math.sqrt(2.0)])            # a vector's length [cells]: its chord kind
TURNS = np.array([math.atan2(1, 2), math.pi / 4 - math.atan2(1, 2)])  # 26.57 and 18.43 deg: the two turn kinds


def _kinds():
    """Per heading k: its chord kind (index into CHORDS) and, per k -> k + 1, the turn
    kind (index into TURNS)."""
    chord = np.array([0 if abs(a) + abs(b) == 1 else (2 if abs(a) == abs(b) else 1) for a, b in VECTORS], np.int64)
    turn = np.empty(NH, np.int64)
    for k in range(NH):
        d = (ANGLES[(k + 1) % NH] - ANGLES[k]) % (2 * np.pi)
        turn[k] = int(np.argmin(np.abs(TURNS - d)))
    return chord, turn


CHORD_KIND, TURN_KIND = _kinds()
DPSI = np.array([(ANGLES[(k + 1) % NH] - ANGLES[k]) % (2 * np.pi) for k in range(NH)])   # k -> k + 1 [rad]


@dataclass(frozen=True, eq=False)
class Value:
    """V over a lattice (module doc): ``V`` (ny, nx, NH) [s or J], lattice point (j, i)
    at (ox + i cell, oy + j cell), heading k at ANGLES[k]; ``seconds`` the build's wall
    time (0 when read from the disk cache), ``cached`` where it came from."""

    V: np.ndarray
    cell: float
    ox: float
    oy: float
    cost: str
    seconds: float = 0.0
    cached: bool = False

    @property
    def shape(self) -> tuple:
        return self.V.shape

    def at(self, x: float, y: float, yaw: float) -> float:
        """V at a pose (x, y [m], yaw [rad]): :func:`sbmpc.problems.lattice.read`'s interpolation."""
        return float(LA.read(self.V.ravel(), self.V.shape[1], self.V.shape[0], self.cell, self.ox, self.oy,
                          x, y, yaw))


@njit(cache=True, error_model="numpy", nogil=True)
def _states(H, res, ox, oy, hl, hw, tan_tip, aside, margin, lox, loy, nxv, nyv, cell, terrain):
    """Per lattice state (j, i, k), the lattice point (lox + i cell, loy + j cell) on the
    map H (origin (ox, oy), resolution res): the grade along heading k (tan; nan where
    closed: tip-over at that heading, also with the vehicle ``aside`` [m] to its left or
    right as the edges judge the margin, or too near the map's edge), the height [m] of
    each lattice point and its terrain index (terrain: the map's layer, flat, or empty
    for one terrain)."""
    ny, nx = H.shape
    x_hi = ox + (nx - 1) * res - margin
    y_hi = oy + (ny - 1) * res - margin
    G = np.full((nyv, nxv, 16), np.nan)
    Z = np.zeros((nyv, nxv))
    Tr = np.zeros((nyv, nxv), np.int64)
    for j in range(nyv):
        y = loy + j * cell
        for i in range(nxv):
            x = lox + i * cell
            Z[j, i] = height_at(H, res, ox, oy, min(max(x, ox), ox + (nx - 1) * res), min(max(y, oy), oy + (ny - 1) * res))
            if x < ox + margin or x > x_hi or y < oy + margin or y > y_hi:
                continue
            if terrain.shape[0] > 0:
                ti = min(max(int(math.floor((x - ox) / res + 0.5)), 0), nx - 1)
                tj = min(max(int(math.floor((y - oy) / res + 0.5)), 0), ny - 1)
                Tr[j, i] = terrain[tj * nx + ti]
            for k in range(16):
                along, across = slope_grades_at(H, res, ox, oy, x, y, ANGLES_T[k], hl, hw)
                if abs(along) <= tan_tip and abs(across) <= tan_tip and (
                        aside <= 0.0 or aside_tilts(H, res, ox, oy, x, y, ANGLES_T[k], hl, hw, aside) <= tan_tip):
                    G[j, i, k] = along
    return G, Z, Tr


ANGLES_T = LA.ANGLES_T
CHORDS_T = tuple(float(c) for c in CHORDS)
ARC_STEPS = (1, 2, 4)     # an arc turns by one heading over this many steps of its vector
VX_T = tuple(int(v) for v in VECTORS[:, 0])
VY_T = tuple(int(v) for v in VECTORS[:, 1])


def arc_chords(cell: float) -> np.ndarray:
    """The arcs' chords [m], indexed chord kind x len(ARC_STEPS) + step index."""
    return np.array([c * m * cell for c in CHORDS for m in ARC_STEPS])


@njit(cache=True, error_model="numpy", inline="always")
def _lookup(table, t, g, g0, gstep, ng):
    """table[t, .] at grade g (tan) on the tables' axis (angle g0 + n gstep [rad]):
    linear between the two nodes, the finite one where only one is, inf where none or
    where g is not finite (a closed state's grade is nan: a goal state may be closed)."""
    if not math.isfinite(g):          # a closed state (nan): no motion from or into it
        return np.inf
    u = (math.atan(g) - g0) / gstep
    if u <= 0.0:
        return table[t, 0]
    if u >= ng - 1:
        return table[t, ng - 1]
    n = int(u)
    f = u - n
    a = table[t, n]
    b = table[t, n + 1]
    if math.isinf(a) or math.isinf(b):
        return a if f < 0.5 else b
    return a + f * (b - a)


@njit(cache=True, error_model="numpy", inline="always")
def _sift_up(hk, hv, c):
    """Binary min-heap on keys hk (ids hv): the entry at c moved up to its place."""
    while c > 0:
        p = (c - 1) // 2
        if hk[p] <= hk[c]:
            break
        hk[p], hk[c] = hk[c], hk[p]
        hv[p], hv[c] = hv[c], hv[p]
        c = p


@njit(cache=True, error_model="numpy", inline="always")
def _sift_down(hk, hv, c, n):
    """The same heap of n entries: the entry at c moved down to its place."""
    while True:
        l = 2 * c + 1
        if l >= n:
            break
        r = l + 1
        m = r if r < n and hk[r] < hk[l] else l
        if hk[c] <= hk[m]:
            break
        hk[m], hk[c] = hk[c], hk[m]
        hv[m], hv[c] = hv[c], hv[m]
        c = m


@njit(cache=True, error_model="numpy", nogil=True)
def _dijkstra(G, Z, Tr, goal, straight, reverse, pivot, arc_turn, energy, chord_kind, turn_kind, dpsi,
              cell, g0, gstep, start, reach):
    """Backward Dijkstra from the ``goal`` states (flat indices) over the reversed
    motions (module doc); G, Z, Tr from :func:`_states`, the motions' costs from
    :func:`sbmpc.planning.motions.motion_costs`. Returns V (nyv, nxv, 16). Focused: once
    every ``start`` state (flat indices) is settled, the search goes on only to ``reach``
    times the largest of their values, and states not settled by then are left at inf
    (the search reads the grid there)."""
    nyv, nxv, nh = G.shape
    N = nyv * nxv * nh
    V = np.full(N, np.inf)
    done = np.zeros(N, np.uint8)
    cap = 4 * N + 16
    hk = np.empty(cap)
    hv = np.empty(cap, np.int64)
    n = 0
    ng = straight.shape[1]
    is_start = np.zeros(N, np.uint8)
    for q in range(start.shape[0]):
        is_start[start[q]] = 1
    left = start.shape[0]
    top = 0.0
    stop = np.inf
    for s in goal:
        V[s] = 0.0
        # push
        hk[n] = 0.0
        hv[n] = s
        n += 1
        _sift_up(hk, hv, n - 1)
    while n > 0:
        key = hk[0]
        s = hv[0]
        n -= 1
        hk[0] = hk[n]
        hv[0] = hv[n]
        _sift_down(hk, hv, 0, n)
        if done[s] or key > V[s]:
            continue
        if key > stop:
            break
        done[s] = 1
        if is_start[s]:
            left -= 1
            top = max(top, key)
            if left == 0:
                stop = reach * top
        k2 = s % nh
        ij = s // nh
        i2 = ij % nxv
        j2 = ij // nxv
        # the predecessors of s: straight, reverse, two pivots, arcs (left and right, each
        # of ARC_STEPS lengths)
        for mtype in range(4 + 2 * len(ARC_STEPS)):
            m = 1
            if mtype == 0:        # straight along k2 into s
                k = k2
                i = i2 - VX_T[k]
                j = j2 - VY_T[k]
            elif mtype == 1:      # reverse along k2 into s
                k = k2
                i = i2 + VX_T[k]
                j = j2 + VY_T[k]
            elif mtype == 2:      # pivot from k2 - 1
                k = (k2 - 1) % nh
                i = i2
                j = j2
            elif mtype == 3:      # pivot from k2 + 1
                k = (k2 + 1) % nh
                i = i2
                j = j2
            else:                 # an arc of m steps along k, from k2 -+ 1 (turning left, right)
                a = mtype - 4
                m = ARC_STEPS[a // 2]
                k = (k2 - 1) % nh if a % 2 == 0 else (k2 + 1) % nh
                i = i2 - m * VX_T[k]
                j = j2 - m * VY_T[k]
            if i < 0 or i >= nxv or j < 0 or j >= nyv:
                continue
            g = G[j, i, k]
            if math.isnan(g):
                continue
            p = (j * nxv + i) * nh + k
            if done[p]:
                continue
            if m > 1:
                # the lattice points an arc passes must be open too
                open_way = True
                for q in range(1, m):
                    if math.isnan(G[j + q * VY_T[k], i + q * VX_T[k], k]):
                        open_way = False
                if not open_way:
                    continue
            t = Tr[j, i]
            if mtype <= 1:
                # straight or reverse: the step at its mean grade (lattice heights)
                L = cell * CHORDS_T[chord_kind[k]]
                ge = (Z[j2, i2] - Z[j, i]) / L
                if mtype == 0:
                    cst = L * _lookup(straight, t, ge, g0, gstep, ng)
                else:
                    cst = L * _lookup(reverse, t, -ge, g0, gstep, ng)
            elif mtype <= 3:
                turn = dpsi[k] if mtype == 2 else dpsi[k2]
                a = _lookup(pivot, t, g, g0, gstep, ng)
                b = _lookup(pivot, Tr[j2, i2], G[j2, i2, k2], g0, gstep, ng)
                cst = turn * max(a, b)
            else:
                # an arc: held where it starts (the grade along its first heading), its
                # steps straight at their mean grades, plus the turn (motions.motion_costs)
                a = mtype - 4
                tk = turn_kind[k] if a % 2 == 0 else turn_kind[k2]
                ak = chord_kind[k] * len(ARC_STEPS) + a // 2
                u = (math.atan(g) - g0) / gstep
                n0 = min(max(int(math.floor(u + 0.5)), 0), ng - 1)
                turn_c = arc_turn[t, n0, ak, tk]
                if math.isinf(turn_c):
                    continue
                L = cell * CHORDS_T[chord_kind[k]]
                run = 0.0
                for q in range(m):
                    ja = j + q * VY_T[k]
                    ia = i + q * VX_T[k]
                    ge = (Z[ja + VY_T[k], ia + VX_T[k]] - Z[ja, ia]) / L
                    run += L * _lookup(straight, Tr[ja, ia], ge, g0, gstep, ng)
                cst = run + turn_c if energy else max(run, turn_c)
            if math.isinf(cst):
                continue
            v = key + cst
            if v < V[p]:
                V[p] = v
                if n >= cap:
                    # compact: drop stale entries (rare: 4 pushes per state on average)
                    m2 = 0
                    for e in range(n):
                        if not done[hv[e]] and hk[e] <= V[hv[e]]:
                            hk[m2] = hk[e]
                            hv[m2] = hv[e]
                            m2 += 1
                    n = m2
                    for c0 in range(n // 2 - 1, -1, -1):     # re-heapify
                        _sift_down(hk, hv, c0, n)
                hk[n] = v
                hv[n] = p
                n += 1
                _sift_up(hk, hv, n - 1)
    for s in range(N):
        if not done[s]:
            V[s] = np.inf
    return V.reshape((nyv, nxv, nh))


MAX_STATES = 1_200_000   # a larger lattice is made coarser (lattice_cell): the build stays near a second
REACH = 1.5    # the Dijkstra settles states up to this many times the start's largest value (_dijkstra)


def lattice_cell(world: World) -> float:
    """The lattice's spacing [m]: ``planner.value_cell``, or coarser where the window
    (the cost-to-go grid's) would hold more than MAX_STATES states at it (a 250 m
    square: 0.96 m; the build grows with the states, about 1 us each on one core)."""
    cell = float(world.scenario.planner.value_cell)
    e = world.emap
    j0, j1, i0, i1 = ctg_window(world)
    area = (i1 - 1 - i0) * (j1 - 1 - j0) * e.resolution ** 2
    return max(cell, math.sqrt(area * NH / MAX_STATES))


def _window(world: World, cell: float) -> tuple:
    """(ox, oy, nxv, nyv) of the lattice: the cost-to-go grid's window, every ``cell``."""
    e = world.emap
    j0, j1, i0, i1 = ctg_window(world)
    ox, oy = e.origin[0] + i0 * e.resolution, e.origin[1] + j0 * e.resolution
    nxv = int(math.floor((i1 - 1 - i0) * e.resolution / cell + 1e-9)) + 1
    nyv = int(math.floor((j1 - 1 - j0) * e.resolution / cell + 1e-9)) + 1
    return ox, oy, nxv, nyv


def _goal_states(world: World, ox, oy, nxv, nyv, cell, G) -> np.ndarray:
    """Flat indices of the lattice states in the goal disc (every heading, open ones);
    where no lattice point lies in it, the open ones of the nearest four."""
    g = world.scenario.goal
    I, J = np.meshgrid(np.arange(nxv), np.arange(nyv))
    d = np.hypot(ox + I * cell - g["x"], oy + J * cell - g["y"])
    inside = d <= g["radius"]
    if not inside.any():
        inside = d <= np.sort(d.ravel())[min(3, d.size - 1)]
    js, is_ = np.nonzero(inside)
    idx = ((js[:, None] * nxv + is_[:, None]) * NH + np.arange(NH)[None, :]).ravel()
    ok = ~np.isnan(G.reshape(-1)[idx])
    return np.ascontiguousarray(idx[ok] if ok.any() else idx)


def _start_states(world: World, ox, oy, nxv, nyv, cell, G) -> np.ndarray:
    """Flat indices of the open lattice states at the four lattice points around the
    scenario's start (every heading): the Dijkstra's focus (:func:`_dijkstra`)."""
    s = world.scenario.start
    i = min(max(int(math.floor((s["x"] - ox) / cell)), 0), nxv - 2)
    j = min(max(int(math.floor((s["y"] - oy) / cell)), 0), nyv - 2)
    idx = np.array([((j + dj) * nxv + i + di) * NH + k for dj in (0, 1) for di in (0, 1) for k in range(NH)])
    return np.ascontiguousarray(idx[~np.isnan(G.reshape(-1)[idx])], dtype=np.int64)


@functools.lru_cache(maxsize=1)
def _code_hash() -> str:
    """The source the value is made from: every compiled source (``dynamics``, ``maps``,
    the search, the problems, the grid, the tables, this module: the numba cache's own
    list) and the worlds' (the margin's twin): a change makes new cache files."""
    from dynamics import _jitcache
    from . import world as WO_mod
    return hashlib.sha256((_jitcache.digest(_jitcache.sources()) + inspect.getsource(WO_mod)).encode()).hexdigest()[:16]


def _content_key(world: World, cost: str, cell: float) -> str:
    e, ps, scn = world.emap, world.scenario.planner, world.scenario
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(e.heights).tobytes())
    if e.terrain_layer is not None:
        h.update(np.ascontiguousarray(e.terrain_layer).tobytes())
    h.update(repr((e.resolution, tuple(e.origin), world.vehicle, world.terrains, ps.margin, ps.margin_turn,
                   ps.margin_grade_deg, ps.margin_tip_deg, ps.margin_aside_m, ps.tip_over_deg, ps.dt, wheel_speed_range(world), cost, cell,
                   (scn.goal["x"], scn.goal["y"], scn.goal["radius"]), (scn.start["x"], scn.start["y"]),
                   ctg_window(world), REACH,
                   _code_hash())).encode())
    return h.hexdigest()[:24]


def _cache_path(key: str):
    return _cache_dir() / f"value-{key}.npy"


def build(world: World, cost: str, cell: float | None = None) -> Value:
    """V of ``world`` for ``cost`` ('time' or 'energy') over a lattice every ``cell``
    metres (default :func:`lattice_cell`), computed (module doc)."""
    import time
    t0 = time.perf_counter()
    ps = world.scenario.planner
    cell = float(cell or lattice_cell(world))
    e = world.emap
    ox, oy, nxv, nyv = _window(world, cell)
    tan_tip = math.tan(math.radians(ps.tip_over_deg - ps.margin_tip_deg))
    layer = (e.terrain_layer.astype(np.int64).ravel() if e.terrain_layer is not None and len(world.terrains) > 1
             else np.zeros(0, np.int64))
    G, Z, Tr = _states(e.heights, e.resolution, e.origin[0], e.origin[1], world.half_length, world.half_width,
                    tan_tip, float(ps.margin_aside_m), world.margin, ox, oy, nxv, nyv, cell, layer)
    mc = MO.motion_costs(world, cost, arc_chords(cell), TURNS)
    g = MO.grades()
    goal = _goal_states(world, ox, oy, nxv, nyv, cell, G)
    start = _start_states(world, ox, oy, nxv, nyv, cell, G)
    V = _dijkstra(G, Z, Tr, goal, mc["straight"], mc["reverse"], mc["pivot"], mc["arc_turn"],
                  cost == "energy", CHORD_KIND, TURN_KIND, DPSI, cell, float(g[0]), float(g[1] - g[0]),
                  start, REACH)
    return Value(V, cell, ox, oy, cost, time.perf_counter() - t0)


@functools.lru_cache(maxsize=8)
def value(world: World, cost: str) -> Value:
    """V of ``world`` for ``cost`` (:func:`build`), kept per (world, cost) in memory and
    on disk by content (:func:`_cache_path`; best effort: a cache that cannot be
    written is skipped)."""
    cell = lattice_cell(world)
    ox, oy, nxv, nyv = _window(world, cell)
    key = _content_key(world, cost, cell)
    path = _cache_path(key)
    try:
        V = np.load(path)
        if V.shape == (nyv, nxv, NH) and V.dtype == np.float64:
            V.setflags(write=False)
            return Value(V, cell, ox, oy, cost, 0.0, True)
    except (OSError, ValueError):
        pass
    val = build(world, cost, cell)
    val.V.setflags(write=False)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
        np.save(tmp, val.V)
        os.replace(tmp, path)
    except OSError:
        pass
    return val
