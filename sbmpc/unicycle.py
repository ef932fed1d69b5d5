"""The reference C++ SBMPO's unicycle problem with circular obstacles, as a search problem.

Specified in ``BENCH-SBMPO-UNICYCLE.md`` (the lab's public C++ SBMPO "steering" benchmark):
state (x, y, theta), control (v, omega); one edge is 10 explicit Euler sub-steps of
0.05 s in single precision, theta wrapped to (-pi, pi] at the end (the sub-steps'
cosines and sines by the angle-addition recurrence: the same iterations, nodes and
costs as ten float32 sincos calls on all 101 benchmark maps, at a fifth of the trig); grid (0.1, 0.1,
pi/36) with snapping; validity of the raw end state against the map border and the
obstacles (body radius 0.125 m); edge cost the xy distance between snapped states;
heuristic distance plus wrapped bearing error; goal when the heuristic is <= 0.5 or the
node is in the goal's cell. It shares :mod:`sbmpc.astar` with the skid-steer planner.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba import njit

from .astar import GOAL, HEURISTIC, PROPAGATE, Problem, cell_index, search

# params: grid resolution (3), goal (3), goal threshold, body radius, border half-size,
# sub-steps, sub-step dt
(U_RX, U_RY, U_RT, U_GX, U_GY, U_GT, U_THR, U_BODY, U_BORDER, U_NSUB, U_DT) = range(11)
CODES = ("outside the map border", "inside an obstacle")


@njit(cache=True, error_model="numpy", _nrt=False)
def _snap(x, res):
    """The centre of x's grid cell (the search's own rounding)."""
    return cell_index(x, res) * res


@njit(PROPAGATE.signature, cache=True, error_model="numpy", _nrt=False)
def propagate(params, data, state, control, out):
    """One edge in float32 as the C++ does; cost = xy distance between snapped states."""
    x = np.float32(state[0])
    y = np.float32(state[1])
    th = np.float32(state[2])
    v = np.float32(control[0])
    w = np.float32(control[1])
    dt = np.float32(params[U_DT])
    # the heading of sub-step k is th + k w dt: its cosine and sine by the angle-addition
    # recurrence (two sincos per edge instead of ten, in double precision, rounded to
    # float32 where the C++ uses cosf/sinf of the float32 heading)
    c = math.cos(float(th))
    s = math.sin(float(th))
    cw = math.cos(float(w * dt))
    sw = math.sin(float(w * dt))
    for _ in range(int(params[U_NSUB])):
        x = np.float32(x + np.float32(c) * v * dt)
        y = np.float32(y + np.float32(s) * v * dt)
        th = np.float32(th + w * dt)
        c, s = c * cw - s * sw, s * cw + c * sw
    pi = np.float32(math.pi)
    if th > pi:
        th = np.float32(th - np.float32(2.0) * pi)
    elif th <= -pi:
        th = np.float32(th + np.float32(2.0) * pi)
    out[0] = x
    out[1] = y
    out[2] = th
    body = params[U_BODY]
    lim = params[U_BORDER] - body
    if x < -lim or x > lim or y < -lim or y > lim:
        return -1.0
    for k in range(data.shape[0] // 3):
        dx = np.float32(x - np.float32(data[3 * k]))
        dy = np.float32(y - np.float32(data[3 * k + 1]))
        rr = np.float32(np.float32(data[3 * k + 2]) + np.float32(body))
        if dx * dx + dy * dy < rr * rr:
            return -2.0
    sx = _snap(out[0], params[U_RX]) - state[0]
    sy = _snap(out[1], params[U_RY]) - state[1]
    return math.sqrt(sx * sx + sy * sy)


@njit(HEURISTIC.signature, cache=True, error_model="numpy", _nrt=False)
def heuristic(params, data, state):
    """Distance to the goal plus the wrapped bearing error (not admissible, as in the C++)."""
    dx = params[U_GX] - state[0]
    dy = params[U_GY] - state[1]
    e = math.atan2(dy, dx) - state[2] + math.pi
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
    if heuristic(params, data, state) <= params[U_THR]:
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
        return cls(int(row[0]), int(row[1]), res, start, goal, controls)


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
    params = np.zeros(11)
    params[U_RX:U_RT + 1] = bench.res
    params[U_GX:U_GT + 1] = bench.goal
    params[U_THR] = 0.5
    params[U_BODY] = 0.125
    params[U_BORDER] = 10.0
    params[U_NSUB] = 10
    params[U_DT] = 0.05
    return Problem(propagate, heuristic, is_goal, params, np.ascontiguousarray(obstacles, float).ravel(),
                   np.array(bench.start, float), np.ascontiguousarray(bench.controls, float),
                   np.arange(3, dtype=np.int64), np.array(bench.res, float), bench.controls.shape[0],
                   rotate=False, snap=True, max_depth=bench.max_generations, codes=CODES)


def solve(bench: Benchmark, obstacles: np.ndarray):
    """One benchmark solve; a :class:`sbmpc.astar.SearchResult`."""
    return search(problem(bench, obstacles), bench.max_iterations, chunk=1 << 30)
