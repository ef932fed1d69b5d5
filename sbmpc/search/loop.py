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
from .counters import (C_DEPTHCUT, C_EDGES, C_FIRST, C_GOAL, C_HEAP, C_INVALID, C_ITERS, C_NODES, C_SEQ,
                       C_SIMULATED, C_STALE, EXHAUSTED,
                       FOUND, GROW, ITERATIONS, MAX_CODE, RUNNING)
from .heap import SEQ_LIMIT, _bits, _pop, _push, _renumber

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
                       types.boolean, types.int64, _I1, _F1, types.boolean, types.int64, types.int64, types.int64, types.float64,
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
def _next(fa, weight, params, data, refine, max_iters, max_depth, X, G, DEP, CLO, H, cnt, best, cur):
    """Pop the open set until a node to expand: returns (RUNNING, its id), its state
    copied into ``cur``; or (status, -1) when the search ends (FOUND, EXHAUSTED,
    ITERATIONS)."""
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
def _pick(controls, nbranch, nfixed, rotate, hold, n, CTL, U, crow, off):
    """The controls of node n's expansion into rows off.. of U and their rows in
    ``controls`` into crow (Problem's branching, fixed rows, rotation and hold). With
    ``rotate`` the window of rows follows the node's id, not the order of expansion, so
    that a node's edges are known before it is taken (the batched search simulates
    them ahead). With ``hold`` the last of them is the row that reached n (CTL[n], its
    parent's edge) where that is not a fixed row, tried anyway: a control can be held
    over several periods. With ``hold`` 2 the table's second half holds each row's
    variant over several periods: the window samples the first half, and the last row
    is the variant of the row that reached n (fixed rows too)."""
    m = controls.shape[0]
    held = CTL[n] if hold else -1
    if hold == 2:
        # the table's second half holds each row's variant held over several periods:
        # the samples come from the first half, the held control is its variant
        m = m // 2
        held = held % m + m if held >= 0 else -1
    base = n * (nbranch - nfixed) if rotate else 0
    for b in range(nbranch):
        c = b if b < nfixed else nfixed + (base + b - nfixed) % (m - nfixed)
        if b == nbranch - 1 and held >= nfixed:
            c = held
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


@njit(_RUN_SIG, cache=True, error_model="numpy", nogil=True)
def run_search(fa, weight, params, data, work, start, controls, nbranch, nfixed, rotate, hold, dims, res,
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
        st, n = _next(fa, weight, params, data, refine, max_iters, max_depth, X, G, DEP, CLO, H, cnt, best, cur)
        if n < 0:
            return st
        done += 1
        if not every:
            _pick(controls, nbranch, nfixed, rotate, hold, n, CTL, U, crow, 0)
        expand(params, data, work, cur, U, CH, CO)
        cnt[C_SIMULATED] += nbranch
        _add_children(fa, weight, params, data, dims, res, snap, settle, n, crow, CH, CO, 0, nbranch,
                      X, G, PAR, CTL, DEP, CLO, KEYS, table, shift, H, cnt, best, key, child)
    return RUNNING


@njit(cache=True, error_model="numpy", inline="always")
def _cached(SN, SX, SL, n, X, cnt):
    """The slot of the edge cache that holds node n's edges simulated from its present
    state (the same bits), or -1; a slot of n's for an earlier state, replaced since by
    a cheaper arrival, is freed (counted in C_STALE). SL[n]: n's last slot, which a
    later node may have taken since."""
    s = SL[n]
    if s < 0 or SN[s] != n:
        return -1
    for d in range(X.shape[1]):
        if _bits(SX[s, d]) != _bits(X[n, d]):
            SN[s] = -1
            cnt[C_STALE] += 1
            return -1
    return s


@njit(cache=True, error_model="numpy", inline="always")
def _ahead(fa, params, data, max_depth, X, DEP, CLO, H, cnt, SN, SX, SL, BN, k, size, cand):
    """Fill BN[k:size] with the open nodes next in the open set's order, without taking
    them (a best-first walk down the heap from its root, at most 4 size entries):
    closed nodes, goals, nodes at the depth limit, nodes already in the batch and nodes
    whose edges are cached are passed over. Returns the new k. (The walk picks each
    next entry by a scan of its candidates and the batch is checked for duplicates by a
    scan: O(size^2) a round, nothing next to a round's edges for the batches of tens of
    nodes it is meant for.)"""
    goal = _goal_fn(fa[4], fa[5])
    h = cnt[C_HEAP]
    nc = 0
    if h > 0:
        cand[0] = 0
        nc = 1
    seen = 0
    while nc > 0 and k < size and seen < 4 * size:
        bi = 0
        for c in range(1, nc):
            i = cand[c]
            j = cand[bi]
            if H[2 * i] < H[2 * j] or (H[2 * i] == H[2 * j] and H[2 * i + 1] < H[2 * j + 1]):
                bi = c
        i = cand[bi]
        nc -= 1
        cand[bi] = cand[nc]
        seen += 1
        for c in range(2 * i + 1, 2 * i + 3):
            if c < h:
                cand[nc] = c
                nc += 1
        n = H[2 * i + 1] & 0xFFFFFFFF
        if CLO[n] or DEP[n] >= max_depth:
            continue
        dup = False
        for b in range(k):
            dup = dup or BN[b] == n
        if dup or _cached(SN, SX, SL, n, X, cnt) >= 0 or goal(params, data, X[n]):
            continue
        BN[k] = n
        k += 1
    return k


_BATCH_SIG = types.UniTuple(types.int64, 2)(
    _I1, types.float64, _F1, _F1, _F1, _F2, types.int64, types.int64, types.boolean, types.int64, _I1, _F1, types.boolean,
    types.int64, types.int64, types.int64, types.float64, types.int64, types.int64, types.int64,
    _F2, _F1, _I1, _I1, _I1, types.uint8[::1], _I2, _I1, _I1, _I1, _F1,
    _I1, _F2, _I1, _F2, _I1, _F2, _F1, _I1, _F2, _I1, _F2, _F1, _I1, _I1, _I1)


@njit(_BATCH_SIG, cache=True, error_model="numpy", nogil=True)
def run_batch(fa, weight, params, data, start, controls, nbranch, nfixed, rotate, hold, dims, res, snap,
              max_depth, settle, max_iters, refine, size, pending, chunk,
              X, G, PAR, CTL, DEP, CLO, KEYS, table, H, cnt, best,
              BN, BP, BO, BU, BR, CH, CO, SN, SX, SL, SCH, SCO, SCR, sc, cand):
    """One round of the batched search, which expands the serial search's nodes in the
    serial search's order (the same plan, node for node) and simulates the edges of up
    to ``size`` nodes at a time: the node to expand and the open nodes next in line.

    A round first takes the ``pending`` nodes of the last batch (BN: their ids, BP the
    states they were simulated from; rows i * nbranch.. of CH, CO, BR: the edges of
    BN[i]): the children of BN[0], the node being expanded, are merged; the edges of
    the others go into the edge cache (slots s of SN: node id, -1 when free; SX: the
    state simulated from; rows s * nbranch.. of SCH, SCO, SCR: children, costs, control
    rows; filled round robin, sc[0] the next slot; SL[n]: node n's slot, one int64 per
    node, -1 or stale where it has none). Then it expands nodes in order
    (up to ``chunk``) as long as their edges are cached for their present state. At the
    first that is not, it returns (RUNNING, k): BN[0] that node (taken, closed), BN[1:k]
    the open nodes next in line (not taken), BP their states, and per edge e (nbranch
    per node) BO[e] the row of its node in BP, BU[e] its control, BR[e] the control's
    row; the caller simulates the k * nbranch edges into CH, CO and calls again with
    pending = k. (RUNNING, 0): ``chunk`` nodes expanded from the cache; (GROW, 0) when
    the arrays must grow first; (status, 0) when the search ends (as
    :func:`run_search`). ``cand``: scratch of 4 size + 2 int64."""
    heur = _heuristic_fn(fa[2], fa[3])
    shift, key, child = _begin(heur, weight, params, data, start, dims, res, snap, X, G, PAR, CTL, DEP, CLO, KEYS,
                               table, H, cnt)
    if pending > 0:
        _add_children(fa, weight, params, data, dims, res, snap, settle, BN[0], BR, CH, CO, 0, nbranch,
                      X, G, PAR, CTL, DEP, CLO, KEYS, table, shift, H, cnt, best, key, child)
    for i in range(1, pending):
        s = sc[0]
        sc[0] = (s + 1) % SN.shape[0]
        SN[s] = BN[i]
        SL[BN[i]] = s
        for d in range(X.shape[1]):
            SX[s, d] = BP[i, d]
        for b in range(nbranch):
            SCO[s * nbranch + b] = CO[i * nbranch + b]
            SCR[s * nbranch + b] = BR[i * nbranch + b]
            for d in range(X.shape[1]):
                SCH[s * nbranch + b, d] = CH[i * nbranch + b, d]
    done = 0
    while done < chunk:
        if _full(cnt, table, H, X.shape[0], nbranch):
            return GROW, 0
        if cnt[C_SEQ] > SEQ_LIMIT - 2 - nbranch:
            _renumber(H, cnt)
        st, n = _next(fa, weight, params, data, refine, max_iters, max_depth, X, G, DEP, CLO, H, cnt, best, BP[0])
        if n < 0:
            return st, 0
        done += 1
        s = _cached(SN, SX, SL, n, X, cnt)
        if s >= 0:
            SN[s] = -1
            _add_children(fa, weight, params, data, dims, res, snap, settle, n, SCR, SCH, SCO, s * nbranch, nbranch,
                          X, G, PAR, CTL, DEP, CLO, KEYS, table, shift, H, cnt, best, key, child)
            continue
        BN[0] = n
        k = _ahead(fa, params, data, max_depth, X, DEP, CLO, H, cnt, SN, SX, SL, BN, 1, size, cand)
        for i in range(k):
            for d in range(X.shape[1]):
                BP[i, d] = X[BN[i], d]
            _pick(controls, nbranch, nfixed, rotate, hold, BN[i], CTL, BU, BR, i * nbranch)
            for b in range(i * nbranch, (i + 1) * nbranch):
                BO[b] = i
        cnt[C_SIMULATED] += k * nbranch
        return RUNNING, k
    return RUNNING, 0


@njit(cache=True, error_model="numpy", nogil=True)
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
