"""The reference C++ SBMPO's unicycle benchmark (sbmpc.problems.unicycle) on the generic search."""
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

BENCH = Path(__file__).resolve().parents[2] / "shared" / "data" / "bench" / "sbmpo_unicycle"


@pytest.mark.skipif(not BENCH.is_dir(), reason="benchmark inputs ../shared/data/bench absent")
def test_unicycle_main_map_matches_the_reference_cpp():
    from sbmpc.problems.unicycle import Benchmark, read_obstacle_maps, solve
    bench = Benchmark.read(BENCH / "config.csv")
    res = solve(bench, read_obstacle_maps(BENCH / "obstacles_main.csv")[0])
    assert res.status == "found"
    assert res.cost == pytest.approx(8.2448, rel=0.01)
    assert abs(res.iterations - 410) <= 41


def _edge_float32(state, v, w, obstacles, nsub=10, dt=0.05):
    """One benchmark edge as the spec words it: float32 explicit Euler sub-steps with the
    heading's cosine and sine each sub-step, theta wrapped once at the end."""
    f = np.float32
    x, y, th, v, w, dt = f(state[0]), f(state[1]), f(state[2]), f(v), f(w), f(dt)
    for _ in range(nsub):
        x = f(x + f(np.cos(th)) * v * dt)
        y = f(y + f(np.sin(th)) * v * dt)
        th = f(th + w * dt)
    if th > f(np.pi):
        th = f(th - f(2) * f(np.pi))
    elif th <= -f(np.pi):
        th = f(th + f(2) * f(np.pi))
    lim = 10.0 - 0.125
    if abs(x) > lim or abs(y) > lim:
        return (x, y, th), -1.0
    for ox, oy, r in obstacles:
        dx, dy, rr = f(x - f(ox)), f(y - f(oy)), f(f(r) + f(0.125))
        if dx * dx + dy * dy < rr * rr:
            return (x, y, th), -2.0
    return (x, y, th), None


@pytest.mark.skipif(not BENCH.is_dir(), reason="benchmark inputs ../shared/data/bench absent")
@settings(max_examples=200, deadline=None)
@given(st.integers(-95, 95), st.integers(-95, 95), st.integers(-35, 36), st.sampled_from([0.0, 0.0123]))
def test_unicycle_expansion_equals_the_straightforward_float32_edges(i, j, k, off):
    """The expansion's rotation tables and obstacle culling against ten float32 sub-steps
    with their own cos/sin per control: the same headings bit for bit, positions within
    float32 rounding (2e-6 m), the same validity, and the cost is the distance between
    snapped cells. Headings on the grid (nodes) read tabulated sines and cosines, others
    (``off``) compute them."""
    from sbmpc.problems.unicycle import Benchmark, problem, read_obstacle_maps
    bench = Benchmark.read(BENCH / "config.csv")
    obstacles = read_obstacle_maps(BENCH / "obstacles_main.csv")[0]
    p = problem(bench, obstacles)
    state = np.array([i * 0.1, j * 0.1, k * math.pi / 36 + off])
    m = p.controls.shape[0]
    children, costs = np.empty((m, 3)), np.empty(m)
    p.expand(p.params, p.data, np.zeros(p.work_size), state, p.controls, children, costs)
    for b, (v, w) in enumerate(p.controls):
        ref, code = _edge_float32(state, v, w, obstacles)
        assert children[b, 2] == ref[2]
        assert np.allclose(children[b, :2], ref[:2], rtol=0, atol=2e-6)
        # validity, unless the end lies within rounding of a border or an obstacle's edge
        x, y = float(ref[0]), float(ref[1])
        margin = min(abs(abs(x) - 9.875), abs(abs(y) - 9.875),
                     *(abs(math.hypot(x - ox, y - oy) - r - 0.125) for ox, oy, r in obstacles))
        if margin > 1e-5:
            assert (costs[b] < 0) == (code is not None) and (code is None or costs[b] == code)
        if costs[b] >= 0:
            snapped = np.floor(np.abs(children[b, :2]) / 0.1 + 0.5) * 0.1 * np.sign(children[b, :2])
            assert costs[b] == pytest.approx(np.hypot(*(snapped - state[:2])), abs=1e-9)


@pytest.mark.skipif(not BENCH.is_dir(), reason="benchmark inputs ../shared/data/bench absent")
@settings(max_examples=300, deadline=None)
@given(st.integers(-110, 110), st.integers(-110, 110), st.integers(-36, 36),
       st.sampled_from([0.0, 1e-12, 0.037]))
def test_unicycle_heuristic_equals_its_formula_on_and_off_the_grid(i, j, k, off):
    """Distance to the goal plus the wrapped bearing error, the bearing from the goal
    table for cell centres within the border and from atan2 elsewhere (off the grid, or
    beyond the table): bit for bit the formula with atan2."""
    from sbmpc.problems.unicycle import Benchmark, problem, read_obstacle_maps
    bench = Benchmark.read(BENCH / "config.csv")
    p = problem(bench, read_obstacle_maps(BENCH / "obstacles_main.csv")[0])
    state = np.array([i * 0.1 + off, j * 0.1, k * math.pi / 36])
    dx, dy = bench.goal[0] - state[0], bench.goal[1] - state[1]
    e = (math.atan2(dy, dx) - state[2] + math.pi) % (2 * math.pi) - math.pi
    assert p.heuristic(p.params, p.data, state) == math.sqrt(dx * dx + dy * dy) + abs(e)
