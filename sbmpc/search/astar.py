"""The SBMPC graph search: A* over sampled controls with an implicit state grid.

The search knows nothing of a particular robot (OMPL's split): a *problem* supplies

* ``expand(params, data, work, state, controls, children, costs)``: simulate the edges
  of one expansion, one from ``state`` under each row of ``controls`` (k, control_dim),
  into the rows of ``children`` (k, state_dim), and put each edge's cost (>= 0) or a
  negative code saying why it is invalid (the problem names its codes) into ``costs``
  (k,). One call per expansion, not per edge: a model may share work between the edges
  of a node (the unicycle reads the sub-step headings of all its controls from one
  table row per node heading) and the search pays one indirect call instead of k;
* ``heuristic(params, data, state) -> float``: a lower bound of the cost to the goal
  (admissible for optimal plans);
* ``is_goal(params, data, state) -> bool``;

as numba functions compiled for the signatures :data:`EXPAND`, :data:`HEURISTIC`,
:data:`GOAL` (first-class function types: the search gets their addresses and makes
the function values inside, so it is compiled and cached on disk once for every
problem), plus flat float arrays ``params`` and ``data`` that only the problem
reads, ``work``, scratch space the problem may write during an expansion, and the
control set, an (m, control_dim) array.

The implicit grid maps a state to the integer cell ``round(state[dims] / res)`` (half
away from zero). A child that lands in its parent's cell is dropped; a child that lands
in a known cell replaces that cell's node only when it is cheaper. Two modes:

* ``snap`` (the reference C++ SBMPO): a node's state is its cell centre and children
  are propagated from it; a closed node may still take a cheaper parent (not expanded
  again).
* no snap (the skid-steer planner): a node keeps the exact state its edge ended in, so
  that replaying the chosen controls reproduces the path; closed nodes are never
  changed, open ones are replaced by a cheaper arrival. A child in the goal is terminal
  and never merged: it gets a node of its own even in its parent's or a closed cell
  (a goal disc smaller than a cell would otherwise be lost near the goal).

Priority: lowest f = g + w h first (w = 1: A*; w > 1: weighted A*); ties go to the node pushed first (FIFO, by a push
counter), which makes the search deterministic.

The compiled loop (:mod:`sbmpc.search.loop`, numba's numpy error model) runs in chunks
of at most ``chunk`` expansions and returns to this module's :class:`Search`, which
checks the wall-clock budget, shows progress and grows the arrays when asked (status
``GROW``); no Python object is made per node or per simulated step.
"""
from __future__ import annotations

import contextlib
import functools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import types
from numba.core.ccallback import CFunc

from .cells import rehash
from .counters import (C_DEPTHCUT, C_EDGES, C_FIRST, C_GOAL, C_HEAP, C_INVALID, C_ITERS, C_NODES, C_SIMULATED,
                       EXHAUSTED,
                       FOUND, GROW, ITERATIONS, MAX_CODE, NC, RUNNING, budget_text)
from .loop import _BATCH_SIG, _RUN_SIG, EXPAND, GOAL, HEURISTIC, _full, expand_nodes, run_batch, run_search

@functools.lru_cache(maxsize=None)
def _address_pair(fn, ftype) -> tuple[int, int]:
    """(C wrapper, compiled body) addresses of a problem's function for ``ftype``; a
    numba dispatcher is compiled for the signature if needed (the dispatcher, kept by
    the cache, keeps the code alive); any other wrapper-address object (a cfunc) gives
    its wrapper only."""
    sig = ftype.signature
    if isinstance(fn, types.WrapperAddressProtocol):
        return fn.__wrapper_address__(), 0
    if isinstance(fn, CFunc):
        return fn.address, 0
    cres = fn.get_compile_result(sig)
    if cres is None:
        fn.compile(sig.args)
        cres = fn.get_compile_result(sig)
    lib = cres.library
    return (lib.get_pointer_to_function(cres.fndesc.llvm_cfunc_wrapper_name),
            lib.get_pointer_to_function(cres.fndesc.llvm_func_name))


@functools.lru_cache(maxsize=None)
def _addresses(expand, heuristic, is_goal) -> np.ndarray:
    """The addresses of a problem's expand, heuristic and goal test, as the compiled
    search takes them (read-only int64 array of 6: wrapper and body of each)."""
    fa = np.array(_address_pair(expand, EXPAND) + _address_pair(heuristic, HEURISTIC)
                  + _address_pair(is_goal, GOAL), np.int64)
    fa.flags.writeable = False
    return fa


@functools.lru_cache(maxsize=None)
def _entry():
    """The compiled entry point of run_search (explicit signature): calling it skips the
    dispatcher's typing of every argument (the search takes 29), so :class:`Search`
    checks the problem's arrays itself (:func:`_check`)."""
    return run_search.overloads[tuple(_RUN_SIG.args)].entry_point


@functools.lru_cache(maxsize=None)
def _batch_entry():
    """The compiled entry point of :func:`run_batch` (as :func:`_entry`)."""
    return run_batch.overloads[tuple(_BATCH_SIG.args)].entry_point


_F64, _I64 = np.dtype(np.float64), np.dtype(np.int64)
_KINDS = (("params", _F64, 1), ("data", _F64, 1), ("start", _F64, 1), ("controls", _F64, 2), ("dims", _I64, 1),
          ("res", _F64, 1))


def _check(p) -> None:
    for name, dtype, ndim in _KINDS:
        a = getattr(p, name)
        if not (type(a) is np.ndarray and a.dtype == dtype and a.ndim == ndim and a.flags.c_contiguous):
            raise TypeError(f"Problem.{name}: expected a C-contiguous {ndim}-D {dtype.name} array, "
                            f"found {type(a).__name__} {getattr(a, 'dtype', '')} {getattr(a, 'shape', '')}")


@dataclass(frozen=True, eq=False)
class Problem:
    """What the search needs to know about a robot and its task (module doc).

    ``start`` (state_dim,); ``controls`` (m, control_dim); ``dims``/``res``: which state
    entries form the grid cell and the cell size of each; ``branching``: controls tried
    per expansion: the first ``fixed_controls`` rows always, then the next rows (the same
    ones at every expansion, or with ``rotate`` a window of the remaining rows that
    follows the node's id); with ``hold`` the last of those is the row of the edge that
    reached the node, where that is not a fixed row (a control held over periods);
    ``max_depth``: edges from the start; ``settle_depth``: children of nodes less than
    this many edges from the start that stay in their parent's cell are kept as nodes of
    their own instead of dropped (for states whose hidden part, such as a controller's,
    changes while the gridded part does not); ``codes``: names of the invalid-edge codes
    (1-based) for the reason of a failure; ``work_size``: length of the ``work`` array
    each search gives ``expand``; ``expand_batch``: optionally, a numba function
    ``expand_batch(params, data, parents, owner, controls, children, costs)`` that
    simulates the edges of a batch of nodes (:meth:`Search.run` with ``batch`` > 1):
    edge e from state ``parents[owner[e]]`` under ``controls[e]`` into ``children[e]``
    and ``costs[e]``, as ``expand`` would; it may run them in parallel (numba's
    ``prange``: the search sets numba's thread count) or on another device. Without
    one, a batch's nodes are expanded one after another through ``expand``.
    """

    expand: object
    heuristic: object
    is_goal: object
    params: np.ndarray
    data: np.ndarray
    start: np.ndarray
    controls: np.ndarray
    dims: np.ndarray
    res: np.ndarray
    branching: int
    rotate: bool = False
    fixed_controls: int = 0
    hold: int = 0
    snap: bool = False
    max_depth: int = 1 << 30
    settle_depth: int = 0
    codes: tuple = ()
    weight: float = 1.0
    refine: float = 0.0
    work_size: int = 0
    expand_batch: object = None


@dataclass
class SearchResult:
    """Outcome of a search: ``status`` is 'found' or 'no_path' (with ``reason``);
    ``path`` the node ids from start to goal, ``states`` (len(path), state_dim),
    ``controls`` the row of ``problem.controls`` of each edge (len(path) - 1), ``cost``
    the goal node's g; ``exhausted``: no path because every state reachable on the grid was
    explored (not because a budget ran out); ``edges``: the edges of the expanded
    nodes, ``edges_simulated``: the edges simulated (a batched search also simulates
    the edges of open nodes it then does not expand); ``ended``: how it ended, one
    of ENDINGS (its ``reason`` says the same in words)."""

    status: str
    reason: str | None
    cost: float
    path: np.ndarray
    states: np.ndarray
    control_rows: np.ndarray
    iterations: int
    nodes: int
    edges: int
    planning_time_s: float
    invalid: dict = field(default_factory=dict)
    first_solution_iterations: int = -1
    exhausted: bool = False
    edges_simulated: int = 0
    ended: str = "found"
    threads_chosen: str | None = None   # threads "auto": "parallel" or "serial", what the search measured last


ENDINGS = ("found", "exhausted", "node_budget", "time_budget")   # SearchResult.ended


CACHE_ROUNDS = 16      # the batched search's edge cache holds this many batches' nodes simulated ahead ...
CACHE_MAX = 4096       # ... but no more nodes than this (or than one batch)
BATCH_RAMP = 32        # the batch grows by one node every this many expansions, up to its size: a
                       # search over within a few hundred expansions (a re-plan, a flat map) does not
                       # simulate ahead the edges of open nodes it never expands (flat's time plan,
                       # 64 expansions: 3.8x the serial search's edges with 16 from the start, 1.1x)


class Search:
    """Arrays of one search and the chunked driver around the compiled loop."""

    def __init__(self, problem: Problem, capacity: int = 4096):
        p = problem
        self.problem = p
        ns = p.start.shape[0]
        kd = p.dims.shape[0]
        cap = max(int(capacity), 4 * p.branching + 4)
        self.X = np.empty((cap, ns))
        self.G = np.empty(cap)
        self.PAR = np.empty(cap, np.int64)
        self.CTL = np.empty(cap, np.int64)
        self.DEP = np.empty(cap, np.int64)
        self.CLO = np.empty(cap, np.uint8)
        self.KEYS = np.empty((cap, kd), np.int64)
        self.SL = np.full(cap, -1, np.int64)    # the batched search's edge-cache slot of each node
        self.table = _cell_table(cap)
        self.H = np.empty(4 * cap, np.int64)    # the open set: 2 int64 per entry
        self.cnt = np.zeros(NC, np.int64)       # no node: the first run puts the start in
        self.cnt[C_GOAL] = -1
        self.cnt[C_FIRST] = -1
        self.best = np.array([np.inf, 1.0])     # [incumbent cost, weight of h in the pruning test]
        self.work = np.zeros(max(int(p.work_size), 1))
        _check(p)
        self._fa = _addresses(p.expand, p.heuristic, p.is_goal)
        self._run = _entry()

    def bound(self, cost: float, weight: float | None = None) -> None:
        """Start with an incumbent of ``cost`` found elsewhere (a warm start): nodes
        with g + weight h >= cost are pruned. With ``weight`` the problem's w (the
        default), a search that ends without a cheaper goal has shown the incumbent to
        be within w of the optimum over the grid, the guarantee weighted A* gives
        anyway; with 1 it must prove optimality, which costs far more expansions."""
        self.best[0] = cost
        self.best[1] = self.problem.weight if weight is None else weight

    def _grow(self, new: int):
        """Double the arrays until they hold ``new`` more nodes and open-set entries."""
        n = self.cnt[C_NODES]
        if n + new > self.X.shape[0] or 4 * (n + new) > self.table.shape[0]:
            cap = 2 * self.X.shape[0]
            for name in ("X", "G", "PAR", "CTL", "DEP", "CLO", "KEYS", "SL"):
                a = getattr(self, name)
                b = np.full((cap,) + a.shape[1:], -1, a.dtype) if name == "SL" else np.empty((cap,) + a.shape[1:], a.dtype)
                b[:n] = a[:n]
                setattr(self, name, b)
            self.table = _cell_table(cap)
            rehash(self.table, self.KEYS, n)
        h = self.cnt[C_HEAP]
        if 2 * (h + new + 1) > self.H.shape[0]:
            H = np.empty(2 * self.H.shape[0], np.int64)
            H[:2 * h] = self.H[:2 * h]
            self.H = H
        if _full(self.cnt, self.table, self.H, self.X.shape[0], new):
            self._grow(new)

    def run(self, max_iterations: int, time_budget_s: float = math.inf, chunk: int = 256,
            progress=None, batch: int = 1, threads: int | None = None, ramp: int = BATCH_RAMP) -> SearchResult:
        """Search until the goal, an empty open set, ``max_iterations`` expansions or
        ``time_budget_s`` of wall-clock time. ``progress(iterations, nodes, elapsed_s)``
        is called after every chunk of about ``chunk`` expansions; a callback that takes
        a fourth argument also gets the best plan's cost so far (the incumbent: a goal
        reached while refining, or a plan the search started with), or None; one with a
        ``budgets(max_iterations, time_budget_s)`` method is told this search's budgets
        first.

        ``batch`` > 1: expand the serial search's nodes in its order (the same plan, node
        for node), but whenever the next node's edges are not known yet, simulate them
        together with those of the ``batch`` - 1 open nodes next in line as one batch
        (while 1 + iterations // ``ramp`` is fewer, that many: the batch grows with the
        search; 0: ``batch`` from the start) (``Problem.expand_batch``, on ``threads``
        threads; "auto": every core, or the
        serial expander when measurements say the cores are busy). Edges simulated
        ahead are cached with the state they were simulated from, and used when their
        node is expanded from that state (a node replaced by a cheaper arrival is
        simulated again); those of nodes never expanded are the batch's price
        (``SearchResult.edges_simulated`` against ``edges``). With batch 1 and
        ``threads`` > 1 a node's edges run in parallel. Either way the nodes expanded,
        and the plan, are the serial search's.
        """
        if hasattr(progress, "budgets"):
            progress.budgets(max_iterations, time_budget_s)
        progress = _with_best(progress, self.best)
        with numba_threads():                 # each mode sets numba's threads: restored after
            if batch > 1 or threads == "auto" or (threads or 1) > 1:
                return self._run_batched(max_iterations, time_budget_s, chunk, progress, int(batch), threads, int(ramp))
            if threads == 1:                # a problem's expander may loop in parallel: one thread
                set_threads(1)
            return self._run_serial(max_iterations, time_budget_s, chunk, progress)

    def _run_serial(self, max_iterations, time_budget_s, chunk, progress) -> SearchResult:
        p = self.problem
        t0 = time.perf_counter()
        while True:
            st = self._run(self._fa, float(p.weight), p.params, p.data, self.work, p.start, p.controls,
                            int(p.branching), int(p.fixed_controls), bool(p.rotate), int(p.hold), p.dims, p.res, bool(p.snap),
                            int(p.max_depth), int(p.settle_depth), int(max_iterations), float(p.refine), int(chunk), self.X, self.G, self.PAR, self.CTL, self.DEP,
                            self.CLO, self.KEYS, self.table, self.H, self.cnt, self.best)
            if st == GROW:
                self._grow(p.branching)
                continue
            elapsed = time.perf_counter() - t0
            if st != RUNNING:
                break
            if progress is not None:
                progress(int(self.cnt[C_ITERS]), int(self.cnt[C_NODES]), elapsed)
            if elapsed > time_budget_s:
                if self.cnt[C_GOAL] >= 0:
                    st = FOUND
                break
        return self._result(st, elapsed, max_iterations, time_budget_s)

    def _run_batched(self, max_iterations, time_budget_s, chunk, progress, size, threads, ramp) -> SearchResult:
        p = self.problem
        nb = int(p.branching)
        E = size * nb
        ns = p.start.shape[0]
        BN = np.zeros(size, np.int64)
        BP = np.zeros((size, ns))
        BO = np.zeros(E, np.int64)
        BU = np.zeros((E, p.controls.shape[1]))
        BR = np.zeros(E, np.int64)
        CH = np.zeros((E, ns))
        CO = np.zeros(E)
        S = min(CACHE_ROUNDS * max(size - 1, 1), max(CACHE_MAX, size))   # the edge cache: nodes simulated ahead
        SN = np.full(S, -1, np.int64)
        SX = np.zeros((S, ns))
        SCH = np.zeros((S * nb, ns))
        SCO = np.zeros(S * nb)
        SCR = np.zeros(S * nb, np.int64)
        sc = np.zeros(1, np.int64)
        cand = np.zeros(4 * size + 2, np.int64)

        def serial(k):
            expand_nodes(self._fa, p.params, p.data, self.work, BP[:k], BO[:k * nb], BU[:k * nb], CH[:k * nb],
                         CO[:k * nb])
        if p.expand_batch is not None:
            if threads is not None:             # (Search.run restores the count after)
                set_threads(threads)

            def batched(k):
                p.expand_batch(p.params, p.data, BP[:k], BO[:k * nb], BU[:k * nb], CH[:k * nb], CO[:k * nb])
            if threads == "auto":
                import numba
                every = numba.get_num_threads()

                def one_thread(k):
                    # a problem's expander may loop in parallel itself (skidsteer.expand):
                    # the serial mode runs it on one thread, or it is parallel too
                    numba.set_num_threads(1)
                    try:
                        serial(k)
                    finally:
                        numba.set_num_threads(every)
                expand = self._chooser = _Chooser(batched, one_thread, size if ramp > 0 else 1)
            else:
                expand = batched
        else:
            expand = serial
        run = _batch_entry()

        def call(pending, chunk, size=size):         # one round (the arrays as they are now: _grow replaces them)
            return run(self._fa, float(p.weight), p.params, p.data, p.start, p.controls, nb, int(p.fixed_controls),
                       bool(p.rotate), int(p.hold), p.dims, p.res, bool(p.snap), int(p.max_depth), int(p.settle_depth),
                       int(max_iterations), float(p.refine), size, pending, int(chunk), self.X, self.G, self.PAR,
                       self.CTL, self.DEP, self.CLO, self.KEYS, self.table, self.H, self.cnt, self.best,
                       BN, BP, BO, BU, BR, CH, CO, SN, SX, self.SL, SCH, SCO, SCR, sc, cand)
        t0 = time.perf_counter()
        pending = 0
        shown = 0
        chooser = expand if isinstance(expand, _Chooser) else None
        while True:
            nominal = size if ramp <= 0 else min(size, 1 + int(self.cnt[C_ITERS]) // ramp)
            st, k = call(pending, chunk, nominal if chooser is None else chooser.request(nominal))
            pending = 0
            if st == GROW:
                self._grow(nb)
                continue
            elapsed = time.perf_counter() - t0
            if st != RUNNING:
                break
            if k > 0:
                expand(k)
                pending = k
            if self.cnt[C_ITERS] - shown >= chunk or k == 0:
                shown = self.cnt[C_ITERS]
                elapsed = time.perf_counter() - t0
                if progress is not None:
                    progress(int(self.cnt[C_ITERS]), int(self.cnt[C_NODES]), elapsed)
                if elapsed > time_budget_s:
                    if pending:      # the node being expanded: its children merged, nothing else run
                        call(pending, 0)
                    st = FOUND if self.cnt[C_GOAL] >= 0 else RUNNING
                    break
        return self._result(st, elapsed, max_iterations, time_budget_s)

    def _result(self, st, elapsed, max_iterations, time_budget_s) -> SearchResult:
        p = self.problem
        cnt = self.cnt
        invalid = {}
        for k in range(1, MAX_CODE + 1):
            if cnt[C_INVALID + k]:
                name = p.codes[k - 1] if k - 1 < len(p.codes) else f"code {k}"
                invalid[name] = int(cnt[C_INVALID + k])
        common = dict(first_solution_iterations=int(cnt[C_FIRST]), iterations=int(cnt[C_ITERS]), nodes=int(cnt[C_NODES]), edges=int(cnt[C_EDGES]),
                      planning_time_s=elapsed, invalid=invalid, edges_simulated=int(cnt[C_SIMULATED]))
        ch = getattr(self, "_chooser", None)          # what threads "auto" chose last
        common["threads_chosen"] = ch.choices[-1] if ch is not None and ch.choices else None
        if st == FOUND:
            path = []
            n = int(cnt[C_GOAL])
            while n >= 0:
                path.append(n)
                n = int(self.PAR[n])
            path = np.array(path[::-1], np.int64)
            return SearchResult("found", None, float(self.G[path[-1]]), path, self.X[path].copy(),
                                self.CTL[path[1:]].copy(), **common)
        if st == EXHAUSTED:
            why, ended = "every state the search could reach on its grid was explored without reaching the goal", "exhausted"
        elif st == ITERATIONS:
            why, ended = f"node budget of {max_iterations} expansions used up", "node_budget"
        else:
            why, ended = f"time budget of {budget_text(time_budget_s)} s used up", "time_budget"
        if invalid:
            why += "; edges rejected: " + ", ".join(f"{v} {k}" for k, v in sorted(invalid.items(), key=lambda kv: -kv[1]))
        if cnt[C_DEPTHCUT]:
            why += f"; {int(cnt[C_DEPTHCUT])} nodes at the depth limit {p.max_depth}"
        empty = np.zeros(0, np.int64)
        return SearchResult("no_path", why, math.inf, empty, np.zeros((0, p.start.shape[0])), empty,
                            exhausted=bool(st == EXHAUSTED), ended=ended, **common)


def set_threads(threads) -> None:
    """Set numba's thread count to ``threads`` ("auto": every thread numba has), clamped
    to [1, NUMBA_NUM_THREADS]."""
    import numba
    n = numba.config.NUMBA_NUM_THREADS if threads == "auto" else int(threads)
    numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))


@contextlib.contextmanager
def numba_threads(threads=None):
    """Run the block with numba's threads set to ``threads`` (:func:`set_threads`; None:
    as they are); the count the block found is restored after, whatever it set."""
    import numba
    before = numba.get_num_threads()
    try:
        if threads is not None:
            set_threads(threads)
        yield
    finally:
        numba.set_num_threads(before)


def _with_best(progress, best):
    """The progress callback as the search calls it, (iterations, nodes, elapsed_s): one
    that takes a fourth argument gets the incumbent's cost (``best[0]``; None while
    there is none) too."""
    if progress is None:
        return None
    import inspect
    try:
        params = inspect.signature(progress).parameters.values()
    except (TypeError, ValueError):
        return progress
    if sum(p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD) for p in params) < 4:
        return progress          # (print or *args callbacks keep the three arguments)

    def call(iterations, nodes, elapsed):
        cost = float(best[0])
        progress(iterations, nodes, elapsed, cost if math.isfinite(cost) else None)
    return call


class _Chooser:
    """``threads: auto``: expand with the parallel batch expander or the serial one,
    whichever is faster here and now. Both give the same children bit for bit (one
    edge function), so the choice changes the time, never the plan. The first
    2 x TRIES rounds alternate the two and keep the one with the smaller median time per
    edge (the first round of each is a warm-up and not counted; after CLEAR_AFTER
    measured pairs, a mode CLEAR times slower than the other at the median is not
    measured further: parallel rounds on busy cores cost 16 ms, serial ones 0.2 ms, and
    the measuring itself took most of a short search); the choice is measured
    again every RECHECK rounds (other work may have taken or freed cores: with both
    cores busy elsewhere, parallel rounds ran many times slower than serial ones), and
    once more at the first round of a full batch (``full`` nodes: the batch grows over
    the first few hundred expansions, and parallel rounds gain with its size). Rounds
    are measured from the first: a search of a few hundred expansions, all of them in
    the growing batch, ran parallel throughout on a busy machine, 2-10x slower than
    serial. While the serial expander is the choice, the search asks for rounds of one
    node (:meth:`request`): the open nodes simulated ahead are a parallel batch's price,
    and serial rounds would only pay it."""

    TRIES = 12
    RECHECK = 2048
    CLEAR_AFTER = 3
    CLEAR = 3.0

    def __init__(self, parallel, serial, full: int = 1):
        self.modes = (parallel, serial)
        self.full = full          # the full batch: measured again when the growing batch reaches it
        self.calls = 0
        self.times = ([], [])
        self.best = 0
        self.choices = []
        self.at_full = False

    def _choose(self):
        self.best = 0 if np.median(self.times[0]) <= np.median(self.times[1]) else 1
        self.choices.append("parallel" if self.best == 0 else "serial")
        self.times = ([], [])

    def request(self, size: int) -> int:
        """The nodes the next round should hold, the batch being ``size`` now: ``size``
        while measuring or while parallel is the choice, else one."""
        if size >= self.full > 1 and not self.at_full:
            self.at_full = True
            self.calls = 0                    # measure again on full batches
            self.times = ([], [])
        measuring = self.calls % self.RECHECK < 2 * self.TRIES
        return size if measuring or self.best == 0 else 1

    def __call__(self, k):
        phase = self.calls % self.RECHECK
        self.calls += 1
        if phase < 2 * self.TRIES:
            m = phase % 2
            t0 = time.perf_counter()
            self.modes[m](k)
            if phase >= 2:
                self.times[m].append((time.perf_counter() - t0) / max(k, 1))
            if phase == 2 * self.TRIES - 1:
                self._choose()
            elif m == 1 and len(self.times[1]) >= self.CLEAR_AFTER:
                a, b = np.median(self.times[0]), np.median(self.times[1])
                if max(a, b) > self.CLEAR * min(a, b):
                    self._choose()
                    self.calls = 2 * self.TRIES     # (the measuring is over until the next recheck)
            return
        self.modes[self.best](k)


def _pow2(n: int) -> int:
    return 1 << max(4, int(n - 1).bit_length())


def _cell_table(capacity: int) -> np.ndarray:
    """An (unfilled) cell table for up to ``capacity`` nodes, at most half full: two
    int64 per slot."""
    return np.empty(2 * _pow2(2 * capacity), np.int64)


def search(problem: Problem, max_iterations: int, time_budget_s: float = math.inf,
           progress=None, chunk: int = 256) -> SearchResult:
    """Run the SBMPC search on a problem (see :class:`Search`)."""
    return Search(problem).run(max_iterations, time_budget_s, chunk=chunk, progress=progress)
