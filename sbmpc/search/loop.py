"""The compiled loop of the SBMPC graph search (:mod:`sbmpc.search.astar` drives it from
Python and documents the search): the first-class function types a problem compiles
its functions for, the node and open-set operations, one chunk of the serial search
(:func:`run_search`), one round of the batched one (:func:`run_batch`) and a batch's
edges through a problem's serial expander (:func:`expand_nodes`).

All compiled code uses numba's numpy error model: division by zero gives inf or nan
instead of raising, and costs no check (with the Python model two divisions cost 44 ns
instead of 4, which made the snap of an edge cost more than its ten integration
sub-steps). The loop runs in chunks and returns to Python, which checks the wall-clock
budget, shows progress and grows the arrays when asked (status ``GROW``); no Python
object is made per node or per simulated step.
"""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from .cells import _EMPTY, _code, _insert, _is_key, _lookup, _shift, cell_index
from .counters import (C_DEPTHCUT, C_EDGES, C_FIRST, C_GOAL, C_HEAP, C_INVALID, C_ITERS, C_NODES, C_SEQ, EXHAUSTED,
                       FOUND, GROW, ITERATIONS, MAX_CODE, RUNNING)
from .heap import SEQ_LIMIT, _pop, _push, _renumber

# ---- first-class function types of a problem -------------------------------------
_ARR = types.float64[::1]
_ARR2 = types.float64[:, ::1]
EXPAND = types.FunctionType(types.void(_ARR, _ARR, _ARR, _ARR, _ARR2, _ARR2, _ARR))
HEURISTIC = types.FunctionType(types.float64(_ARR, _ARR, _ARR))
GOAL = types.FunctionType(types.boolean(_ARR, _ARR, _ARR))



# explicit signatures: the model functions arrive as addresses (an int64 array, see
# sbmpc.search.astar._addresses), so the compiled search is the same (and cached on disk) whatever the problem
_F1, _F2, _I1, _I2 = types.float64[::1], types.float64[:, ::1], types.int64[::1], types.int64[:, ::1]
_RUN_SIG = types.int64(_I1, types.float64, _F1, _F1, _F1, _F1, _F2, types.int64, types.int64,
                       types.boolean, _I1, _F1, types.boolean, types.int64, types.int64, types.int64, types.float64,
                       types.int64, _F2, _F1, _I1, _I1, _I1, types.uint8[::1], _I2, _I1, _I1, _I1, _F1)


def _function_value(ftype):
    """An intrinsic that makes a first-class function value of type ``ftype`` from the
    addresses of its C wrapper and of its compiled body (0 if none): the search gets a
    problem's functions as integers (:func:`sbmpc.search.astar._addresses`), because numba unboxes a function
    object argument by calling two Python functions (3.5 us per argument and call), and
    calls the compiled body directly, without the wrapper, when it has its address."""
    @intrinsic
    def make(typingctx, c_addr, jit_addr):
        def codegen(context, builder, signature, args):
            f = cgutils.create_struct_proxy(ftype)(context, builder)
            vp = context.get_value_type(types.voidptr)
            f.c_addr = builder.inttoptr(args[0], vp)
            f.py_addr = ir.Constant(vp, None)
            f.jit_addr = builder.inttoptr(args[1], vp)
            return f._getvalue()
        return ftype(types.int64, types.int64), codegen
    return make


_expand_fn = _function_value(EXPAND)
_heuristic_fn = _function_value(HEURISTIC)
_goal_fn = _function_value(GOAL)


@njit(cache=True, error_model="numpy", inline="always")
def _key_of(state, dims, res, key):
    for d in range(dims.shape[0]):
        key[d] = cell_index(state[dims[d]], res[d])


@njit(cache=True, error_model="numpy", inline="always")
def _centre(state, dims, res, key):
    """Snap ``state`` to the centre of its cell ``key``."""
    for d in range(dims.shape[0]):
        state[dims[d]] = key[d] * res[d]


@njit(cache=True, error_model="numpy", inline="always")
def _new_node(cnt, KEYS, CLO, key):
    """A new open node for cell ``key``: its id."""
    j = cnt[C_NODES]
    cnt[C_NODES] += 1
    for d in range(key.shape[0]):
        KEYS[j, d] = key[d]
    CLO[j] = 0
    return j


@njit(cache=True, error_model="numpy", inline="always")
def _set_node(X, G, PAR, CTL, DEP, j, state, g, parent, control, depth):
    """Node j's state, cost from the start, parent, control row and depth."""
    for d in range(state.shape[0]):
        X[j, d] = state[d]
    G[j] = g
    PAR[j] = parent
    CTL[j] = control
    DEP[j] = depth


@njit(cache=True, error_model="numpy", inline="always")
def _start(heur, weight, params, data, start, dims, res, snap, X, G, PAR, CTL, DEP, CLO, KEYS, table, H, cnt):
    """Put the start node into empty search arrays (cnt zero but C_GOAL and C_FIRST -1)."""
    table[:] = _EMPTY
    key = np.empty(dims.shape[0], np.int64)
    _key_of(start, dims, res, key)
    _new_node(cnt, KEYS, CLO, key)
    _set_node(X, G, PAR, CTL, DEP, 0, start, 0.0, -1, -1, 0)
    if snap:
        _centre(X[0], dims, res, key)
    code = _code(key)
    slot, _ = _lookup(table, _shift(table), KEYS, key, code)
    _insert(table, slot, code, 0)
    _push(H, cnt, weight * heur(params, data, X[0]), 0)


@njit(cache=True, error_model="numpy", inline="always")
def _begin(heur, weight, params, data, start, dims, res, snap, X, G, PAR, CTL, DEP, CLO, KEYS, table, H, cnt):
    """The start of every call of the compiled loop: the start node put in on the first
    (no node yet); the cell table's shift and scratch space for a key and a child state."""
    if cnt[C_NODES] == 0:
        _start(heur, weight, params, data, start, dims, res, snap, X, G, PAR, CTL, DEP, CLO, KEYS, table, H, cnt)
    return _shift(table), np.empty(dims.shape[0], dtype=np.int64), np.empty(X.shape[1])


@njit(cache=True, error_model="numpy", inline="always")
def _next(fa, weight, params, data, refine, max_iters, max_depth, X, G, DEP, CLO, H, cnt, best, cur, taken):
    """Pop the open set until a node to expand: returns (RUNNING, its id), its state
    copied into ``cur``; or (status, -1) when the search ends (FOUND, EXHAUSTED,
    ITERATIONS). ``taken``: nodes already taken into the current batch; a goal popped
    then goes back into the open set and (RUNNING, -1) ends the batch, so that the
    batch's nodes, which come before it, are expanded first (as the serial search
    would)."""
    heur = _heuristic_fn(fa[2], fa[3])
    goal = _goal_fn(fa[4], fa[5])
    while True:
        if cnt[C_HEAP] == 0:
            return (FOUND if cnt[C_GOAL] >= 0 else EXHAUSTED), -1
        if cnt[C_ITERS] >= max_iters:
            return (FOUND if cnt[C_GOAL] >= 0 else ITERATIONS), -1
        if cnt[C_FIRST] >= 0 and cnt[C_ITERS] >= cnt[C_FIRST] * (1.0 + refine):
            return FOUND, -1
        n = _pop(H, cnt)
        if CLO[n]:
            continue
        for d in range(cur.shape[0]):
            cur[d] = X[n, d]
        if best[0] < np.inf and G[n] + best[1] * heur(params, data, cur) >= best[0]:
            CLO[n] = 1
            continue
        if goal(params, data, cur):
            if taken > 0:
                _push(H, cnt, G[n] + weight * heur(params, data, cur), n)
                return RUNNING, -1
            if G[n] < best[0]:
                best[0] = G[n]
                best[1] = 1.0
                cnt[C_GOAL] = n
                if cnt[C_FIRST] < 0:
                    cnt[C_FIRST] = max(cnt[C_ITERS], 1)
            if refine <= 0.0:
                return FOUND, -1
            CLO[n] = 1
            continue
        CLO[n] = 1
        cnt[C_ITERS] += 1
        if DEP[n] >= max_depth:
            cnt[C_DEPTHCUT] += 1
            continue
        return RUNNING, n


@njit(cache=True, error_model="numpy", inline="always")
def _pick(controls, nbranch, nfixed, rotate, iters, U, crow, off):
    """The controls of one expansion (the ``iters``-th) into rows off.. of U and their
    rows in ``controls`` into crow (Problem's branching, fixed rows and rotation)."""
    m = controls.shape[0]
    base = (iters - 1) * (nbranch - nfixed) if rotate else 0
    for b in range(nbranch):
        c = b if b < nfixed else nfixed + (base + b - nfixed) % (m - nfixed)
        crow[off + b] = c
        for d in range(U.shape[1]):
            U[off + b, d] = controls[c, d]


@njit(cache=True, error_model="numpy", inline="always")
def _add_children(fa, weight, params, data, dims, res, snap, settle, n, crow, CH, CO, off, nbranch,
                  X, G, PAR, CTL, DEP, CLO, KEYS, table, shift, H, cnt, best, key, child):
    """Merge the children of node n (rows off.. off + nbranch of CH, CO and crow) into
    the graph and the open set (:mod:`sbmpc.search.astar`'s module doc)."""
    heur = _heuristic_fn(fa[2], fa[3])
    goal = _goal_fn(fa[4], fa[5])
    pcode = _code(KEYS[n])
    cnt[C_EDGES] += nbranch
    for b in range(off, off + nbranch):
        c = crow[b]
        cost = CO[b]
        if cost < 0.0:
            code = int(-cost)
            if code > MAX_CODE:
                code = MAX_CODE
            cnt[C_INVALID + code] += 1
            continue
        for d in range(child.shape[0]):
            child[d] = CH[b, d]
        _key_of(child, dims, res, key)
        code = _code(key)
        g = G[n] + cost
        same = code == pcode and (code >= 0 or _is_key(KEYS, n, key))
        terminal = not snap and goal(params, data, child)
        if terminal or (same and DEP[n] < settle):
            # a node of its own, outside the grid: a goal state is terminal (the goal
            # disc may be smaller than a cell, or lie in the parent's or a closed
            # cell); near the start a child may stay in its parent's cell while its
            # hidden state moves on (a drive slewing from a stall to reverse)
            if g < best[0]:
                j = _new_node(cnt, KEYS, CLO, key)
                _set_node(X, G, PAR, CTL, DEP, j, child, g, n, c, DEP[n] + 1)
                _push(H, cnt, g + weight * heur(params, data, child), j)
            continue
        if same:
            continue
        slot, j = _lookup(table, shift, KEYS, key, code)
        if j < 0:
            j = _new_node(cnt, KEYS, CLO, key)
            _insert(table, slot, code, j)
        elif g >= G[j] or (CLO[j] and not snap):
            continue
        if snap:
            _centre(child, dims, res, key)
        _set_node(X, G, PAR, CTL, DEP, j, child, g, n, c, DEP[n] + 1)
        if not CLO[j]:
            h = heur(params, data, child)
            if g + best[1] * h < best[0]:
                _push(H, cnt, g + weight * h, j)


@njit(cache=True, error_model="numpy", inline="always")
def _full(cnt, table, H, cap, new):
    """Whether the arrays may not hold ``new`` more nodes and open-set entries."""
    return (cnt[C_NODES] + new > cap or 2 * (cnt[C_HEAP] + new + 1) > H.shape[0]
            or 4 * (cnt[C_NODES] + new) > table.shape[0])


@njit(_RUN_SIG, cache=True, error_model="numpy")
def run_search(fa, weight, params, data, work, start, controls, nbranch, nfixed, rotate, dims, res,
               snap, max_depth, settle, max_iters, refine, chunk, X, G, PAR, CTL, DEP, CLO, KEYS, table, H,
               cnt, best):
    """Expand up to ``chunk`` nodes (:mod:`sbmpc.search.astar`'s module doc). Returns a status: FOUND (node id in
    cnt[C_GOAL]), EXHAUSTED (open set empty), ITERATIONS (max_iters reached), GROW (the
    arrays are too small for the next expansion) or RUNNING (chunk done). The first call
    (no node yet) puts the start node in.

    With ``refine`` > 0 the search is anytime (AWA*): a goal reached becomes the
    incumbent (cost in best[0]) and the search goes on, pruning every node whose g + h
    (unweighted) cannot beat it, for ``refine`` times the expansions the first solution
    took; FOUND then means the open set was emptied (the incumbent is optimal over the
    grid) or that refinement budget was spent.

    A search may start with an incumbent found elsewhere (best[0] its cost, best[1] the
    weight of h in the pruning test, see :meth:`sbmpc.search.astar.Search.bound`): nodes with
    g + best[1] h >= best[0] are never opened; the first goal reached (necessarily
    cheaper) resets the weight to 1."""
    expand = _expand_fn(fa[0], fa[1])
    heur = _heuristic_fn(fa[2], fa[3])
    shift, key, child = _begin(heur, weight, params, data, start, dims, res, snap, X, G, PAR, CTL, DEP, CLO, KEYS,
                               table, H, cnt)
    cur = np.empty(X.shape[1])
    # the controls of one expansion (all rows in order when every row is tried), their
    # rows in ``controls``, the children and edge costs
    every = nbranch == controls.shape[0] and not rotate
    U = controls if every else np.empty((nbranch, controls.shape[1]))
    crow = np.arange(nbranch)
    CH = np.empty((nbranch, X.shape[1]))
    CO = np.empty(nbranch)
    done = 0
    while done < chunk:
        if _full(cnt, table, H, X.shape[0], nbranch):
            return GROW
        if cnt[C_SEQ] > SEQ_LIMIT - 2 - nbranch:
            _renumber(H, cnt)
        st, n = _next(fa, weight, params, data, refine, max_iters, max_depth, X, G, DEP, CLO, H, cnt, best, cur, 0)
        if n < 0:
            return st
        done += 1
        if not every:
            _pick(controls, nbranch, nfixed, rotate, cnt[C_ITERS], U, crow, 0)
        expand(params, data, work, cur, U, CH, CO)
        _add_children(fa, weight, params, data, dims, res, snap, settle, n, crow, CH, CO, 0, nbranch,
                      X, G, PAR, CTL, DEP, CLO, KEYS, table, shift, H, cnt, best, key, child)
    return RUNNING


_BATCH_SIG = types.UniTuple(types.int64, 2)(
    _I1, types.float64, _F1, _F1, _F1, _F2, types.int64, types.int64, types.boolean, _I1, _F1, types.boolean,
    types.int64, types.int64, types.int64, types.float64, types.int64, types.int64,
    _F2, _F1, _I1, _I1, _I1, types.uint8[::1], _I2, _I1, _I1, _I1, _F1,
    _I1, _F2, _I1, _F2, _I1, _F2, _F1)


@njit(_BATCH_SIG, cache=True, error_model="numpy")
def run_batch(fa, weight, params, data, start, controls, nbranch, nfixed, rotate, dims, res, snap,
              max_depth, settle, max_iters, refine, size, pending,
              X, G, PAR, CTL, DEP, CLO, KEYS, table, H, cnt, best,
              BN, BP, BO, BU, BR, CH, CO):
    """One round of the batched search: merge the children of the ``pending`` nodes of
    the last batch (BN: their ids; rows i * nbranch.. of CH, CO: the edges of BN[i]),
    then take up to ``size`` nodes to expand, in the serial search's order, into a new
    batch: BN their ids, BP their states, and per edge e (nbranch per node) BO[e] the
    row of its node in BP, BU[e] its control, BR[e] the control's row. Returns
    (RUNNING, k) with k > 0 nodes taken (the caller simulates their k * nbranch edges
    into CH, CO and calls again with pending = k), (GROW, 0) when the arrays must grow
    first (the pending children were merged), or (status, 0) when the search ends (as
    :func:`run_search`)."""
    heur = _heuristic_fn(fa[2], fa[3])
    shift, key, child = _begin(heur, weight, params, data, start, dims, res, snap, X, G, PAR, CTL, DEP, CLO, KEYS,
                               table, H, cnt)
    for i in range(pending):
        _add_children(fa, weight, params, data, dims, res, snap, settle, BN[i], BR, CH, CO, i * nbranch, nbranch,
                      X, G, PAR, CTL, DEP, CLO, KEYS, table, shift, H, cnt, best, key, child)
    new = size * nbranch
    if _full(cnt, table, H, X.shape[0], new + size):
        return GROW, 0
    if cnt[C_SEQ] > SEQ_LIMIT - 2 - new - size:
        _renumber(H, cnt)
    k = 0
    st = RUNNING
    while k < size:
        st, n = _next(fa, weight, params, data, refine, max_iters, max_depth, X, G, DEP, CLO, H, cnt, best, BP[k], k)
        if n < 0:
            break
        BN[k] = n
        _pick(controls, nbranch, nfixed, rotate, cnt[C_ITERS], BU, BR, k * nbranch)
        for b in range(k * nbranch, (k + 1) * nbranch):
            BO[b] = k
        k += 1
    if k > 0:
        return RUNNING, k
    return st, 0


@njit(cache=True, error_model="numpy")
def expand_nodes(fa, params, data, work, BP, BO, BU, CH, CO):
    """The edges of a batch, one node after another through the problem's serial
    ``expand`` (for a problem with no batch expander of its own): the rows of BO come in
    runs of equal node index."""
    expand = _expand_fn(fa[0], fa[1])
    e = 0
    E = BO.shape[0]
    while e < E:
        k = BO[e]
        f = e
        while f < E and BO[f] == k:
            f += 1
        expand(params, data, work, BP[k], BU[e:f], CH[e:f], CO[e:f])
        e = f
