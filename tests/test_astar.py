"""The generic search (sbmpc.search.astar) on problems with known answers, and its parts (cell
table, open set) against plain Python."""
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numba import njit
from scipy.sparse.csgraph import shortest_path

from sbmpc.search import cells, counters, heap
from sbmpc.search.astar import EXPAND, GOAL, HEURISTIC, Problem, search

# ---- a walker on an n x n map of cell weights: state (x, y), a control a move (dx, dy)
# costing its length times the weight of the cell it ends in (weight 0: blocked).
# params: [n, goal_x, goal_y]; data: the weights, row-major n x n. With unit moves and
# weights 0 or 1, a 4-connected grid walk of cost 1 a step (snap: the state is the cell)


@njit(EXPAND.signature, cache=True)
def walk(params, data, work, state, controls, children, costs):
    n = int(params[0])
    for b in range(controls.shape[0]):
        x = state[0] + controls[b, 0]
        y = state[1] + controls[b, 1]
        children[b, 0] = x
        children[b, 1] = y
        if x < 0 or y < 0 or x >= n or y >= n:
            costs[b] = -1.0
        else:
            weight = data[int(x) * n + int(y)]
            costs[b] = -2.0 if weight <= 0.0 else math.hypot(controls[b, 0], controls[b, 1]) * weight


@njit(HEURISTIC.signature, cache=True)
def manhattan(params, data, state):
    return abs(params[1] - state[0]) + abs(params[2] - state[1])


@njit(GOAL.signature, cache=True)
def at_goal(params, data, state):
    return state[0] == params[1] and state[1] == params[2]


MOVES = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


def grid_problem(blocked, goal):
    n = blocked.shape[0]
    return Problem(walk, manhattan, at_goal, np.array([n, goal[0], goal[1]], float),
                   (~blocked).astype(float).ravel(), np.zeros(2), MOVES, np.array([0, 1], np.int64),
                   np.ones(2), branching=4, snap=True, codes=("off the grid", "blocked"))


def bfs_distance(blocked, goal):
    n = blocked.shape[0]
    free = ~blocked.ravel()
    A = np.zeros((n * n, n * n))
    for i in range(n):
        for j in range(n):
            for di, dj in ((1, 0), (0, 1)):
                a, b = i + di, j + dj
                if a < n and b < n and free[i * n + j] and free[a * n + b]:
                    A[i * n + j, a * n + b] = A[a * n + b, i * n + j] = 1
    d = shortest_path(A, unweighted=True, indices=0)
    return d[goal[0] * n + goal[1]]


@settings(max_examples=25)
@given(st.integers(4, 12).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(st.booleans(), min_size=n * n, max_size=n * n))))
def test_astar_finds_the_shortest_path_of_a_grid(case):
    n, flags = case
    blocked = np.array(flags).reshape(n, n) & (np.random.default_rng(n).random((n, n)) < 0.35)
    blocked[0, 0] = blocked[n - 1, n - 1] = False
    goal = (n - 1, n - 1)
    res = search(grid_problem(blocked, goal), 10_000)
    d = bfs_distance(blocked, goal)
    if math.isinf(d):
        assert res.status == "no_path" and "explored" in res.reason
    else:
        assert res.status == "found"
        assert res.cost == d
        # the path is a chain of unit moves through free cells
        steps = np.abs(np.diff(res.states, axis=0)).sum(axis=1)
        assert np.all(steps == 1) and not blocked[tuple(res.states.astype(int).T)].any()


def test_budget_ends_the_search_with_the_reason():
    blocked = np.zeros((30, 30), bool)
    blocked[:, 15] = True                      # a wall: the goal is unreachable
    res = search(grid_problem(blocked, (29, 29)), 300)
    assert res.status == "no_path"
    assert res.iterations == 300 and "budget of 300 expansions" in res.reason and res.ended == "node_budget"
    assert "blocked" in res.reason            # the invalid edges are named
    res = search(grid_problem(blocked, (29, 29)), 100_000)
    assert res.status == "no_path" and "every state the search could reach" in res.reason and res.ended == "exhausted"
    assert res.iterations == 30 * 15          # the whole reachable half, each cell once


def test_arrays_grow_without_changing_the_answer():
    from sbmpc.search.astar import Search
    blocked = np.zeros((40, 40), bool)
    p = grid_problem(blocked, (39, 39))
    small = Search(p, capacity=8).run(100_000)
    big = Search(p, capacity=1 << 14).run(100_000)
    assert small.cost == big.cost == 78
    assert small.iterations == big.iterations


def test_batch_of_one_on_threads_expands_what_the_serial_search_expands():
    """With batch 1 the batched driver (here through the problem's serial expand, one
    node after another) takes the nodes the serial search takes: same path, same
    counts, including across array growth."""
    from sbmpc.search.astar import Search
    rng = np.random.default_rng(0)
    blocked = rng.random((25, 25)) < 0.2
    blocked[0, 0] = blocked[24, 24] = False
    p = grid_problem(blocked, (24, 24))
    serial = Search(p, capacity=8).run(100_000)
    batched = Search(p, capacity=8).run(100_000, threads=2)
    assert serial.status == batched.status == "found"
    assert np.array_equal(serial.path, batched.path)
    assert (serial.iterations, serial.nodes, serial.edges) == (batched.iterations, batched.nodes, batched.edges)


# ---- the walker with moves of random lengths and directions, exact states (no snap)


@njit(HEURISTIC.signature, cache=True)
def straight(params, data, state):
    return math.hypot(params[1] - state[0], params[2] - state[1])


@njit(GOAL.signature, cache=True)
def near_goal(params, data, state):
    return math.hypot(params[1] - state[0], params[2] - state[1]) < 1.0


def plane_problem(seed):
    """Steps of random lengths and directions (rotating windows of 60 rows), exact end
    states in 1 x 1 cells: cheaper arrivals replace open nodes by other states."""
    rng = np.random.default_rng(seed)
    n = 30
    weights = 1.0 + 3.0 * (rng.random((n, n)) < 0.3)
    ang = rng.uniform(0, 2 * np.pi, 60)
    rad = rng.uniform(0.7, 2.5, 60)
    controls = np.column_stack([rad * np.cos(ang), rad * np.sin(ang)])
    return Problem(walk, straight, near_goal, np.array([n, 27.5, 26.5]), weights.ravel(), np.array([0.5, 0.5]),
                   controls, np.array([0, 1], np.int64), np.ones(2), branching=9, rotate=True, fixed_controls=1,
                   snap=False, weight=1.3)


@pytest.mark.parametrize("size", [3, 16])
def test_batched_search_does_not_use_edges_of_a_replaced_state(size):
    """Without snapping, a node simulated ahead may be replaced by a cheaper arrival (a
    new state in the same cell) before it is expanded: its cached edges are then stale,
    and the batched search simulates it again, so that it still expands the serial
    search's nodes, to the bit."""
    from sbmpc.search.astar import Search
    stale = 0
    for seed in range(3):
        p = plane_problem(seed)
        serial = Search(p).run(20_000)
        batched = Search(p, capacity=8)
        res = batched.run(20_000, batch=size, ramp=0)     # (the whole batch from the start)
        assert serial.status == res.status == "found"
        assert np.array_equal(res.path, serial.path) and np.array_equal(res.states, serial.states)
        assert (res.iterations, res.nodes, res.cost) == (serial.iterations, serial.nodes, serial.cost)
        assert res.edges_simulated > res.edges
        stale += batched.cnt[counters.C_STALE]
    assert stale > 0                  # the case under test happened


@pytest.mark.parametrize("kw", [dict(refine=1.0), dict(max_depth=12), dict(weight=1.0), dict(hold=True)])
def test_batched_search_follows_the_serial_one_when_refining_or_cut_by_depth(kw):
    """Anytime refinement (goals reached become incumbents that prune), a depth limit,
    plain A* and held controls (a node's rows depend on the edge that reached it): the
    batched search still expands the serial search's nodes."""
    from dataclasses import replace
    from sbmpc.search.astar import Search
    p = replace(plane_problem(1), **kw)
    serial = Search(p).run(20_000)
    res = Search(p, capacity=8).run(20_000, batch=8, ramp=0)
    assert (res.status, res.iterations, res.nodes, res.cost) == (serial.status, serial.iterations, serial.nodes,
                                                                  serial.cost)
    assert np.array_equal(res.path, serial.path)


def test_a_batched_search_out_of_time_merges_the_node_it_took():
    """A time budget that ends a batched search between rounds: the node it had taken
    (counted as expanded) has its children merged, as the serial search's would be."""
    from sbmpc.search.astar import Search
    p = plane_problem(0)
    s = Search(p, capacity=8)
    res = s.run(20_000, time_budget_s=0.0, chunk=1, batch=4)
    assert res.iterations >= 1 and res.edges == res.iterations * p.branching


@pytest.mark.parametrize("size", [2, 5, 16])
def test_batched_search_expands_the_serial_searchs_nodes(size):
    """K nodes' edges at a time, simulated ahead of their expansion: the nodes expanded,
    in the same order (iterations, nodes), the path and its cost are the serial
    search's, at the price of edges simulated and never used; an unreachable goal is
    still reported as such. (Here a node's state is its cell: the next test has states
    that change.)"""
    from sbmpc.search.astar import Search
    for seed in range(4):
        rng = np.random.default_rng(seed)
        blocked = rng.random((30, 30)) < 0.25
        blocked[0, 0] = blocked[29, 29] = False
        p = grid_problem(blocked, (29, 29))
        d = bfs_distance(blocked, (29, 29))
        serial = Search(p).run(100_000)
        res = Search(p, capacity=8).run(100_000, batch=size, ramp=0)
        if math.isinf(d):
            assert serial.status == res.status == "no_path" and "explored" in res.reason
            assert (res.iterations, res.nodes) == (serial.iterations, serial.nodes)
            continue
        assert res.status == "found" and res.cost == d == serial.cost
        assert np.array_equal(res.path, serial.path)
        assert (res.iterations, res.nodes, res.edges) == (serial.iterations, serial.nodes, serial.edges)
        assert res.edges_simulated >= res.edges == serial.edges_simulated
        steps = np.abs(np.diff(res.states, axis=0)).sum(axis=1)
        assert np.all(steps == 1) and not blocked[tuple(res.states.astype(int).T)].any()
    blocked = np.zeros((20, 20), bool)
    blocked[:, 10] = True
    res = Search(grid_problem(blocked, (19, 19))).run(50, batch=size, ramp=0)
    assert res.status == "no_path" and "budget of 50 expansions" in res.reason


@pytest.mark.parametrize("ramp", [1, 4, 32])
def test_the_batch_grows_with_the_search(ramp):
    """By default the batch grows by one node every ``ramp`` expansions up to its size:
    a short search (here 57 expansions straight across an open grid, greedy with w = 2)
    simulates fewer edges ahead for open nodes it never expands than a batch of 16
    from the start, which simulates nearly twice the edges it uses. The nodes
    expanded and the path stay the serial search's."""
    from dataclasses import replace
    from sbmpc.search.astar import Search
    p = replace(grid_problem(np.zeros((30, 30), bool), (29, 28)), weight=2.0)
    serial = Search(p).run(100_000)
    full = Search(p).run(100_000, batch=16, ramp=0)
    grown = Search(p).run(100_000, batch=16, ramp=ramp)
    assert serial.iterations == full.iterations == grown.iterations == 57
    assert np.array_equal(grown.path, serial.path) and np.array_equal(full.path, serial.path)
    assert full.edges_simulated > 1.9 * serial.edges
    # rounds of k nodes while 1 + iterations // ramp = k: at most sum(min(16, 1 + i // ramp)) edges' nodes
    bound = sum(min(16, 1 + i // ramp) for i in range(57)) * p.branching
    assert serial.edges <= grown.edges_simulated <= bound
    if ramp == 32:
        assert grown.edges_simulated <= 1.5 * serial.edges


def test_a_problem_with_arrays_of_the_wrong_kind_is_refused_with_its_field():
    """The search calls its compiled entry points directly (no dispatcher typing), so it
    checks the problem's arrays itself."""
    from dataclasses import replace
    p = grid_problem(np.zeros((4, 4), bool), (3, 3))
    with pytest.raises(TypeError, match="Problem.params"):
        search(replace(p, params=p.params.astype(np.float32)), 100)
    with pytest.raises(TypeError, match="Problem.dims"):
        search(replace(p, dims=p.dims.astype(np.int32)), 100)
    assert search(p, 100).status == "found"


def test_a_problem_function_given_as_a_cfunc_is_called_through_its_wrapper():
    """The search takes a problem's functions as addresses: a numba dispatcher gives its
    compiled body, a cfunc only its C wrapper; both reach the same answer."""
    from dataclasses import replace
    from numba import cfunc
    p = grid_problem(np.zeros((6, 6), bool), (5, 5))
    wrapped = cfunc(HEURISTIC.signature, cache=False)(manhattan.py_func)
    a, b = search(p, 1000), search(replace(p, heuristic=wrapped), 1000)
    assert a.status == b.status == "found"
    assert a.cost == b.cost == 10 and a.iterations == b.iterations


@njit(cache=True)
def _table_ids(keys, slots):
    """Node id of each key row through the search's cell table (new keys get the next id)."""
    table = np.empty(2 * slots, np.int64)
    table[:] = -1
    shift = cells._shift(table)
    ids = np.empty(keys.shape[0], np.int64)
    stored = np.empty_like(keys)
    n = 0
    for r in range(keys.shape[0]):
        code = cells._code(keys[r])
        slot, j = cells._lookup(table, shift, stored, keys[r], code)
        if j < 0:
            j = n
            stored[n] = keys[r]
            cells._insert(table, slot, code, j)
            n += 1
        ids[r] = j
    return ids


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 5), st.sampled_from([3, 1 << 19, 1 << 21, 1 << 40]), st.integers(0, 2**32 - 1))
def test_cell_table_finds_each_key_again_packed_or_hashed(kd, span, seed):
    """Keys of up to 3 cells within +-2^20 are packed into the code, the others hashed
    (confirmed on the keys): either way equal keys get the same node and others not."""
    rng = np.random.default_rng(seed)
    keys = rng.integers(-span, span, size=(300, kd))
    keys = keys[rng.integers(0, 300, size=600)]          # every key seen several times
    ids = _table_ids(keys, 1024)
    first = {}
    want = np.array([first.setdefault(tuple(k), len(first)) for k in keys.tolist()])
    np.testing.assert_array_equal(ids, want)
    for k in keys[:50]:
        packed = kd <= 3 and all(-(1 << 20) <= x < 1 << 20 for x in k)
        assert (cells._code(k) >= 0) == packed


@njit(cache=True)
def _heap_order(f, renumber_at):
    H = np.empty(4 * f.shape[0] + 4, np.int64)
    cnt = np.zeros(counters.NC, np.int64)
    for i in range(f.shape[0]):
        if i == renumber_at:                  # as if 2^31 entries had been pushed before
            cnt[counters.C_SEQ] = heap.SEQ_LIMIT - 1
            heap._renumber(H, cnt)
        heap._push(H, cnt, f[i], i)
    out = np.empty(f.shape[0], np.int64)
    for i in range(f.shape[0]):
        out[i] = heap._pop(H, cnt)
    return out


@settings(max_examples=60, deadline=None)
@given(st.lists(st.sampled_from([0.0, -0.0, -0.5, 1.0, 2.5, 1e300, np.inf, -np.inf]) | st.floats(-1e6, 1e6),
                min_size=1, max_size=200), st.integers(0, 200))
def test_open_set_pops_by_f_then_push_order(fs, renumber_at):
    """The heap's monotone bits of f order like the floats (negative ones too), and
    entries of equal f come out in the order they were pushed, also when the push
    counter is renumbered on the way (near its 31 bits)."""
    f = np.array(fs, float)
    got = _heap_order(f, renumber_at)
    want = sorted(range(len(fs)), key=lambda i: (fs[i], i))
    np.testing.assert_array_equal(got, want)


def test_auto_threads_keep_the_faster_expander_and_measure_again():
    """threads "auto": the first rounds alternate parallel and serial expansion and keep
    the faster per edge, early where one is CLEAR times slower; every RECHECK rounds it
    measures again (a core taken by other work makes the parallel expander the slower
    one)."""
    import time as _time
    from sbmpc.search.astar import _Chooser
    calls = []
    slow = {"parallel": 0.002, "serial": 0.0}

    def parallel(k):
        calls.append("p")
        _time.sleep(slow["parallel"])

    def serial(k):
        calls.append("s")
        _time.sleep(slow["serial"])
    c = _Chooser(parallel, serial)
    for _ in range(2 * c.TRIES + 10):
        c(16)
    pairs = 1 + c.CLEAR_AFTER                     # a warm-up pair, then the measured ones
    assert c.choices == ["serial"] and calls[:2 * pairs] == ["p", "s"] * pairs
    assert calls[2 * pairs:] == ["s"] * (len(calls) - 2 * pairs)      # clear early: no more parallel rounds
    slow.update(parallel=0.0, serial=0.002)
    while len(c.choices) < 2:
        c(16)
    for _ in range(5):
        c(16)
    assert c.choices == ["serial", "parallel"] and calls[-5:] == ["p"] * 5


def test_auto_threads_measure_from_the_first_round_and_again_on_full_batches():
    """A short search on busy cores (a few hundred expansions, all in the growing batch)
    is not left parallel: the rounds are measured from the first. When the batch is
    full the choice is measured again, where it matters most (parallel rounds gain with
    the batch: here the parallel expander is slow on small rounds only). While serial is
    the choice, rounds hold one node (nothing simulated ahead for nothing)."""
    import time as _time
    from sbmpc.search.astar import _Chooser
    calls = []

    def parallel(k):
        calls.append(("p", k))
        _time.sleep(0.002 if k < 16 else 0.0)

    def serial(k):
        calls.append(("s", k))
        _time.sleep(0.0 if k < 16 else 0.002)
    c = _Chooser(parallel, serial, 16)
    for k in range(1, 16):                       # the batch the search would use grows
        for _ in range(4):
            c(c.request(k))
    assert c.choices == ["serial"] and calls[-20:] == [("s", 1)] * 20       # serial, one node a round
    while len(c.choices) < 2:
        c(c.request(16))
    assert c.choices == ["serial", "parallel"] and calls[60:62] == [("p", 16), ("s", 16)]
    c(c.request(16))
    assert calls[-1] == ("p", 16)


@pytest.mark.parametrize("kw", [dict(threads=1), dict(threads=2), dict(batch=4, threads=2), dict(threads="auto")])
def test_a_search_leaves_numbas_thread_count_as_it_found_it(kw):
    """Each mode sets numba's threads for its expander (one thread for the serial search,
    the asked count for the batched one); afterwards the caller's count is back (the
    polish after a search runs its trials on numba's threads)."""
    import numba
    from sbmpc import scenario as SC
    from sbmpc.planning import problem as PB, world as WO
    from sbmpc.search.astar import Search
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one numba thread: nothing to change")
    world = WO.resolve(SC.load(Path(__file__).resolve().parents[1] / "scenarios" / "flat.yaml"))
    prob = PB.problem(world, "time")
    before = numba.get_num_threads()
    numba.set_num_threads(1 if kw.get("threads") != 1 else 2)
    try:
        mine = numba.get_num_threads()
        Search(prob).run(30, **kw)
        assert numba.get_num_threads() == mine
    finally:
        numba.set_num_threads(before)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 10_000), st.integers(-1, 59), st.integers(4, 12), st.integers(0, 3), st.booleans())
def test_a_held_control_takes_the_last_row_of_the_window(n, reached_by, nbranch, nfixed, rotate):
    """With ``hold`` a node's expansion tries the row of the edge that reached it (CTL[n])
    in place of its window's last row, unless that row is a fixed one (tried anyway) or
    the node is the start (CTL = -1); the fixed rows and the rest of the window stay."""
    from sbmpc.search.loop import _pick
    controls = np.column_stack([np.arange(60.0), -np.arange(60.0)])
    CTL = np.full(n + 1, -7, np.int64)
    CTL[n] = reached_by
    rows = {}
    for hold in (False, True):
        U = np.zeros((nbranch, 2))
        crow = np.zeros(nbranch, np.int64)
        _pick(controls, nbranch, nfixed, rotate, hold, n, CTL, U, crow, 0)
        assert np.array_equal(U, controls[crow])
        rows[hold] = crow
    assert list(rows[False][:nfixed]) == list(range(nfixed))
    if reached_by >= nfixed:
        assert rows[True][-1] == reached_by
        assert np.array_equal(rows[True][:-1], rows[False][:-1])
    else:
        assert np.array_equal(rows[True], rows[False])
    # hold 2: the table's second half holds each row's variant over several periods; the
    # window samples the first half alone, and the held control is the variant of the
    # row that reached n, whichever half that row is in, fixed rows too
    table = np.vstack([controls, controls + 1000.0])
    CTL[n] = reached_by if reached_by < 0 else reached_by + (60 if reached_by % 2 else 0)
    U = np.zeros((nbranch, 2))
    crow = np.zeros(nbranch, np.int64)
    _pick(table, nbranch, nfixed, rotate, 2, n, CTL, U, crow, 0)
    assert np.array_equal(U, table[crow])
    if reached_by >= 0:
        assert crow[-1] == reached_by + 60
        assert np.array_equal(crow[:-1], rows[False][:-1]) and np.all(crow[:-1] < 60)
    else:
        assert np.array_equal(crow, rows[False])


@njit(HEURISTIC.signature, cache=True)
def zero(params, data, state):
    return 0.0


def test_a_held_control_lets_the_search_repeat_a_rare_row():
    """A walker whose only cheap move towards the goal is one Halton row, in a window of
    its own only at some nodes: with ``hold`` the path repeats it (cost 14 over 14 steps
    instead of 24 over 4 cells a step), without it the path takes the dear fixed moves."""
    from dataclasses import replace
    from sbmpc.search.astar import Search
    n = 16
    fixed = np.array([[1.0, 0.0], [0.0, 1.0]])          # 1 cell a move, on weight-4 ground
    rare = np.array([[1.0, 1.0]])                      # the diagonal: weight-1 ground
    filler = np.array([[-1.0, 0.0], [0.0, -1.0]] * 20)
    controls = np.vstack([fixed, rare, filler])
    w = np.full((n, n), 4.0)
    np.fill_diagonal(w, 1.0 / math.sqrt(2.0))
    p = Problem(walk, zero, at_goal, np.array([n, 14.0, 14.0]), w.ravel(), np.zeros(2), controls,
                np.array([0, 1], np.int64), np.ones(2), branching=4, rotate=True, fixed_controls=2, snap=True)
    held = Search(replace(p, hold=True)).run(100_000)
    plain = Search(p).run(100_000)
    assert held.status == plain.status == "found"
    assert held.cost == pytest.approx(14.0) and plain.cost > 1.5 * held.cost
