"""The reference C++ SBMPO's unicycle problem with circular obstacles, as a search problem.

Specified in ``BENCH-SBMPO-UNICYCLE.md`` (the lab's public C++ SBMPO "steering" benchmark):
state (x, y, theta), control (v, omega); one edge is 10 explicit Euler sub-steps of
0.05 s in single precision, theta wrapped to (-pi, pi] at the end (the sub-steps'
cosines and sines tabulated per heading cell, see :func:`expand`: the same iterations,
nodes and costs as ten float32 sincos calls on all 101 benchmark maps); grid (0.1, 0.1,
pi/36) with snapping; validity of the raw end state against the map border and the
obstacles (body radius 0.125 m); edge cost the xy distance between snapped states;
heuristic distance plus wrapped bearing error; goal when the heuristic is <= 0.5 or the
node is in the goal's cell. It shares :mod:`sbmpc.search.astar` with the skid-steer planner.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from ..search import lanes
from ..search.astar import EXPAND, GOAL, HEURISTIC, Problem, search
from ..search.cells import cell_index

# params: grid resolution (3), goal (3), goal threshold, body radius, border half-size,
# sub-steps, sub-step dt, obstacle count, reach of an edge (its longest length, plus 10 %
# for float32 rounding), offset of the heading table in data, heading cells either side
# of 0, offset of the lanes' speeds and turns in data, offset of the goal bearing table,
# its cells either side of 0, 1 / res x, 1 / res y (offsets in float64 words); then the
# obstacles (x, y, r)
(U_RX, U_RY, U_RT, U_GX, U_GY, U_GT, U_THR, U_BODY, U_BORDER, U_NSUB, U_DT, U_NOBS, U_REACH, U_HOFF, U_NHEAD,
 U_COFF, U_BOFF, U_NB, U_IRX, U_IRY, U_OBST) = range(21)
CODES = ("outside the map border", "inside an obstacle")
LANES = lanes.WIDTH  # the most controls a problem may have (the tables' columns)
_DIMS = np.arange(3, dtype=np.int64)


@njit(cache=True, error_model="numpy", _nrt=False)
def _snap(x, res):
    """The centre of x's grid cell (the search's own rounding)."""
    return cell_index(x, res) * res


@njit(cache=True, error_model="numpy", _nrt=False)
def _turned(c0, s0, rot, nsub, out):
    """float32 cosines and sines of a heading (c0, s0) turned by each control's k omega dt
    (the rotations ``rot``: per sub-step k a row of cosines and one of sines, a column per
    control), into ``out`` in the same layout. In double, rounded once."""
    for j in range(nsub * LANES):
        k = j // LANES
        b = j - k * LANES
        ck = rot[2 * k * LANES + b]
        sk = rot[(2 * k + 1) * LANES + b]
        out[2 * k * LANES + b] = np.float32(c0 * ck - s0 * sk)
        out[(2 * k + 1) * LANES + b] = np.float32(s0 * ck + c0 * sk)


@njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def _snapped(v, res):
    """The cell centres of float64 lanes v: round(v / res) half away from zero, times res
    (as :func:`_snap`, up to the sign of a zero)."""
    q = lanes.div(v, lanes.splat(res))
    return lanes.mul(lanes.copysign(lanes.floor(lanes.add(lanes.absolute(q), lanes.splat(0.5))), q),
                     lanes.splat(res))


@njit(EXPAND.signature, cache=True, error_model="numpy", _nrt=False)
def expand(params, data, work, state, controls, children, costs):
    """The edges of one expansion, in float32 as the C++ does; cost = xy distance
    between the snapped states.

    All edges at once, edge b in lane b of 16 float32 lanes (:mod:`sbmpc.search.lanes`; each
    operation rounded to float32 as the scalar code rounds it). The heading of sub-step
    k, th + k omega dt, has its cosine and sine by one rotation of the node heading's by
    the control's k omega dt (:func:`_turned`; no trig in the edges). A node's heading
    is a cell centre (the search snaps), one of 73, so these float32 cosines and sines
    are tabulated per heading cell in ``data`` (a 58 kB table read instead of two sincos
    and four products per sub-step); a heading off the grid has them computed. Equal to
    ten float32 cosf/sinf per edge in iterations, nodes and costs on all 101 benchmark
    maps. Only the obstacles within reach of the node (the longest edge,
    ``params[U_REACH]``) are tested against the children; the others cannot touch them.
    Row b of ``controls`` must be control b of the benchmark (the tables' column b, the
    speeds and turns of the lanes are read from ``data``): every control at every
    expansion, in order, as :func:`problem` sets it up."""
    m = controls.shape[0]
    L = LANES
    nsub = int(params[U_NSUB])
    dt = np.float32(params[U_DT])
    th0 = np.float32(state[2])
    D = data.view(np.float32)
    # work: the children's x, y and heading in float32, the sub-step table of a heading
    # off the grid (float32), the edge distances (float64): (5 + 2 nsub) L / 2 words
    W = work.view(np.float32)
    block = 2 * nsub * L                 # the cosines and sines of one node heading
    hres = params[U_RT]
    i = cell_index(state[2], hres)
    if i * hres == state[2] and abs(i) <= params[U_NHEAD]:
        T = D[2 * int(params[U_HOFF]) + int(i + params[U_NHEAD]) * block:]
    else:
        T = W[3 * L:3 * L + block]
        _turned(math.cos(np.float64(th0)), math.sin(np.float64(th0)), data, nsub, T)
    c = 2 * int(params[U_COFF])
    v = lanes.load(D, c)                 # v and omega dt of each lane, float32
    wd = lanes.load(D, c + L)
    vdt = lanes.splat(dt)
    x = lanes.splat(np.float32(state[0]))
    y = lanes.splat(np.float32(state[1]))
    th = lanes.splat(th0)
    for k in range(nsub):
        x = lanes.add(x, lanes.mul(lanes.mul(lanes.load(T, 2 * k * L), v), vdt))
        y = lanes.add(y, lanes.mul(lanes.mul(lanes.load(T, (2 * k + 1) * L), v), vdt))
        th = lanes.add(th, wd)
    hit = 0                              # lanes inside an obstacle
    body = params[U_BODY]
    for j in range(int(params[U_NOBS])):
        ox = params[U_OBST + 3 * j]
        oy = params[U_OBST + 3 * j + 1]
        r = params[U_OBST + 3 * j + 2]
        far = params[U_REACH] + r + body
        if (state[0] - ox) ** 2 + (state[1] - oy) ** 2 > far * far:
            continue
        rr = np.float32(np.float32(r) + np.float32(body))
        dx = lanes.sub(x, lanes.splat(np.float32(ox)))
        dy = lanes.sub(y, lanes.splat(np.float32(oy)))
        hit |= lanes.less(lanes.add(lanes.mul(dx, dx), lanes.mul(dy, dy)), lanes.splat(np.float32(rr * rr)))
    # the distance between the snapped states (cell centres, the search's rounding:
    # round(x / res) half away from zero, as cell_index), and the border, in float64
    xd = lanes.widen(x)
    yd = lanes.widen(y)
    lim = params[U_BORDER] - body
    out = (lanes.less(xd, lanes.splat(-lim)) | lanes.less(lanes.splat(lim), xd)
           | lanes.less(yd, lanes.splat(-lim)) | lanes.less(lanes.splat(lim), yd))
    sx = lanes.sub(_snapped(xd, params[U_RX]), lanes.splat(state[0]))
    sy = lanes.sub(_snapped(yd, params[U_RY]), lanes.splat(state[1]))
    dist = work[(3 + 2 * nsub) * L // 2:]
    lanes.store(dist, 0, lanes.sqrt(lanes.add(lanes.mul(sx, sx), lanes.mul(sy, sy))))
    lanes.store(W, 0, x)
    lanes.store(W, L, y)
    lanes.store(W, 2 * L, th)
    pi = np.float32(math.pi)
    for b in range(m):
        if (out >> b) & 1:
            costs[b] = -1.0
        elif (hit >> b) & 1:
            costs[b] = -2.0
        else:
            costs[b] = dist[b]
        t = W[2 * L + b]
        if t > pi:
            t = np.float32(t - np.float32(2.0) * pi)
        elif t <= -pi:
            t = np.float32(t + np.float32(2.0) * pi)
        children[b, 0] = W[b]
        children[b, 1] = W[L + b]
        children[b, 2] = t


@njit(cache=True, error_model="numpy", _nrt=False)
def _bearings(params, n, out):
    """atan2(dy, dx) from every cell centre (i rx, j ry), |i|, |j| <= n, to the goal:
    out[(i + n) (2 n + 1) + j + n], computed as :func:`heuristic` computes it."""
    for i in range(-n, n + 1):
        for j in range(-n, n + 1):
            out[(i + n) * (2 * n + 1) + j + n] = math.atan2(params[U_GY] - j * params[U_RY],
                                                            params[U_GX] - i * params[U_RX])


@njit(cache=True, error_model="numpy", _nrt=False)
def _bearing(params, data, x, y, dx, dy):
    """atan2(dy, dx), the bearing of the goal (dx, dy) from (x, y): from the table of
    :func:`_bearings` when (x, y) is a cell centre within it (a snapped node), else by
    atan2. The cell is found by a multiplication with 1/res, not cell_index's division:
    a state whose cell centre is not exactly reproduced just takes the atan2."""
    n = int(params[U_NB])
    i = int(round(x * params[U_IRX]))
    j = int(round(y * params[U_IRY]))
    if abs(i) <= n and abs(j) <= n and i * params[U_RX] == x and j * params[U_RY] == y:
        return data[int(params[U_BOFF]) + (i + n) * (2 * n + 1) + j + n]
    return math.atan2(dy, dx)


@njit(HEURISTIC.signature, cache=True, error_model="numpy", _nrt=False)
def heuristic(params, data, state):
    """Distance to the goal plus the wrapped bearing error (not admissible, as in the C++)."""
    dx = params[U_GX] - state[0]
    dy = params[U_GY] - state[1]
    e = _bearing(params, data, state[0], state[1], dx, dy) - state[2] + math.pi
    # (e + pi) mod 2 pi - pi, with e in (-2 pi, 2 pi]: one correction, bit for bit what
    # Python's float modulo gives here (fmod is exact, and so is a - 2 pi for a in
    # [2 pi, 3 pi]), without its out-of-line helper call
    if e < 0.0:
        e += 2.0 * math.pi
    elif e >= 2.0 * math.pi:
        e -= 2.0 * math.pi
    e -= math.pi
    return math.sqrt(dx * dx + dy * dy) + abs(e)


@njit(GOAL.signature, cache=True, error_model="numpy", _nrt=False)
def is_goal(params, data, state):
    """The heuristic within the threshold, or the goal's cell. The heuristic is at least
    the distance, so its arctangent is only needed within the threshold's distance."""
    dx = params[U_GX] - state[0]
    dy = params[U_GY] - state[1]
    if dx * dx + dy * dy <= params[U_THR] * params[U_THR] and heuristic(params, data, state) <= params[U_THR]:
        return True
    for d in range(3):
        if _snap(state[d], params[U_RX + d]) != _snap(params[U_GX + d], params[U_RX + d]):
            return False
    return True


@dataclass(frozen=True)
class Benchmark:
    """The benchmark configuration (config.csv)."""

    max_iterations: int
    max_generations: int
    res: np.ndarray
    start: np.ndarray
    goal: np.ndarray
    controls: np.ndarray

    @classmethod
    def read(cls, path: Path | str) -> "Benchmark":
        row = np.loadtxt(path, delimiter=",", ndmin=1)
        nx, nu = int(row[2]), int(row[3])
        res = row[4:4 + nx]
        start = row[4 + nx:4 + 2 * nx]
        goal = row[4 + 2 * nx:4 + 3 * nx]
        m = int(row[4 + 3 * nx])
        controls = row[5 + 3 * nx:5 + 3 * nx + m * nu].reshape(m, nu)
        if nx != 3 or nu != 2:
            raise ValueError(f"{path}: expected a unicycle (3 state and 2 control dimensions), found {nx} and {nu}")
        if not 0 < m <= LANES:
            raise ValueError(f"{path}: expected 1 to {LANES} controls, found {m}")
        return cls(int(row[0]), int(row[1]), np.ascontiguousarray(res), np.ascontiguousarray(start),
                   np.ascontiguousarray(goal), np.ascontiguousarray(controls))

    @functools.cached_property
    def _tables(self) -> tuple[np.ndarray, np.ndarray]:
        """The parameter vector (all but the obstacles) and the data: the sub-step
        rotations (sub-step k of control b turns the heading by k (omega_b dt), omega dt
        in float32 as the C++ adds it; per sub-step a row of cosines and one of sines, a
        column per control) and, for every heading cell, the
        float32 cosines and sines of the turned headings (:func:`_turned`), then the
        lanes' v and omega dt (float32 pairs packed in float64), then the goal's bearing
        from every cell centre within the border (:func:`_bearings`, 323 kB)."""
        nsub, dt = 10, 0.05
        params = np.zeros(U_OBST)
        params[U_RX:U_RT + 1] = self.res
        params[U_GX:U_GT + 1] = self.goal
        params[U_THR] = 0.5
        params[U_BODY] = 0.125
        params[U_BORDER] = 10.0
        params[U_NSUB] = nsub
        params[U_DT] = dt
        params[U_REACH] = 1.1 * np.abs(self.controls[:, 0]).max() * nsub * dt
        wdt = np.zeros(LANES)
        wdt[:self.controls.shape[0]] = np.float32(self.controls[:, 1]) * np.float32(dt)
        turn = np.arange(nsub)[:, None] * wdt[None, :]
        rot = np.stack([np.cos(turn), np.sin(turn)], axis=1).ravel()
        nh = int(math.ceil(math.pi / self.res[2]))
        heads = np.empty((2 * nh + 1, 2 * nsub * LANES), np.float32)
        for i in range(-nh, nh + 1):
            th = np.float64(np.float32(i * self.res[2]))
            _turned(math.cos(th), math.sin(th), rot, nsub, heads[i + nh])
        lane = np.zeros((2, LANES), np.float32)          # v and omega dt of each lane
        lane[0, :self.controls.shape[0]] = self.controls[:, 0]
        lane[1] = wdt
        params[U_HOFF] = rot.size
        params[U_NHEAD] = nh
        params[U_COFF] = rot.size + heads.size // 2
        # the goal's bearing from every cell centre within the border
        params[U_NB] = nb = int(math.ceil(params[U_BORDER] / min(self.res[0], self.res[1])))
        params[U_IRX], params[U_IRY] = 1.0 / self.res[0], 1.0 / self.res[1]
        params[U_BOFF] = params[U_COFF] + lane.size // 2
        bearings = np.empty((2 * nb + 1) ** 2)
        _bearings(params, nb, bearings)
        return params, np.concatenate((rot, heads.ravel().view(np.float64), lane.ravel().view(np.float64),
                                       bearings))


def read_obstacle_maps(path: Path | str) -> list[np.ndarray]:
    """Obstacle maps, one per CSV row: count, then (x, y, r) triples -> (count, 3) arrays."""
    maps = []
    for line in Path(path).read_text().splitlines():
        if not line.strip():
            continue
        vals = np.array([float(a) for a in line.split(",")])
        n = int(vals[0])
        maps.append(vals[1:1 + 3 * n].reshape(n, 3))
    return maps


def problem(bench: Benchmark, obstacles: np.ndarray) -> Problem:
    """The benchmark on one obstacle map ((n, 3) array of x, y, r): the obstacles follow
    the parameters; ``data`` holds the configuration's tables, shared by every map."""
    params, tables = bench._tables
    obstacles = np.asarray(obstacles, float).reshape(-1, 3)
    params = np.concatenate((params, obstacles.ravel()))
    params[U_NOBS] = obstacles.shape[0]
    return Problem(expand, heuristic, is_goal, params, tables, bench.start, bench.controls, _DIMS, bench.res,
                   bench.controls.shape[0], snap=True, max_depth=bench.max_generations, codes=CODES,
                   work_size=(5 + 2 * int(params[U_NSUB])) * LANES // 2)


def solve(bench: Benchmark, obstacles: np.ndarray):
    """One benchmark solve; a :class:`sbmpc.search.astar.SearchResult`."""
    return search(problem(bench, obstacles), bench.max_iterations, chunk=1 << 30)
