"""The search's open set: a binary heap of (f, push counter, node) in one int64 array
(compiled, no allocation, no reference counting)."""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from .counters import C_HEAP, C_SEQ


@intrinsic
def _bits(typingctx, x):
    """The bits of a float64 as an int64."""
    if x == types.float64:
        def codegen(context, builder, sig, args):
            return builder.bitcast(args[0], ir.IntType(64))
        return types.int64(x), codegen


# The open set: a binary heap of (f, push counter, node) entries, two int64 per entry in
# one array (a level's compare reads one cache line instead of three): the bits of f made
# monotone (a float64's bits order like its value for f >= 0; negative ones are flipped),
# then the push counter (high 32 bits, below SEQ_LIMIT: see _renumber) and the node id
# (low 32 bits). Ties of f go to the entry pushed first. The helpers compare and swap in
# place, with no calls of their own, and are compiled without reference counting
# (_nrt=False): a numba function increments and decrements the count of every array it
# is handed, with atomic operations, and a call per heap level made that 30 % of the
# unicycle benchmark; after that, the counts of one push and one pop per expansion were
# still 5 %.
@njit(cache=True, error_model="numpy", _nrt=False)
def _push(H, cnt, f, node):
    i = cnt[C_HEAP]
    b = _bits(f + 0.0)                 # (-0.0 + 0.0 is +0.0: the zeros tie)
    k1 = b ^ ((b >> 63) & 0x7FFFFFFFFFFFFFFF)
    k2 = (cnt[C_SEQ] << 32) | node
    cnt[C_HEAP] += 1
    cnt[C_SEQ] += 1
    while i > 0:                       # sift up: move larger parents down
        p = (i - 1) >> 1
        p1 = H[2 * p]
        p2 = H[2 * p + 1]
        if k1 < p1 or (k1 == p1 and k2 < p2):
            H[2 * i] = p1
            H[2 * i + 1] = p2
            i = p
        else:
            break
    H[2 * i] = k1
    H[2 * i + 1] = k2


SEQ_LIMIT = 1 << 31      # push counters fit in 31 bits; near it the heap is renumbered


@njit(cache=True, error_model="numpy")
def _renumber(H, cnt):
    """Give the heap's entries the push counters 0, 1, ... in their order (their order and
    so the heap are unchanged) and restart the counter after them: a search may push more
    than SEQ_LIMIT entries in all, never that many at once."""
    h = cnt[C_HEAP]
    seq = np.empty(h, np.int64)
    for i in range(h):
        seq[i] = H[2 * i + 1] >> 32
    order = np.argsort(seq)
    for r in range(h):
        i = order[r]
        H[2 * i + 1] = (r << 32) | (H[2 * i + 1] & 0xFFFFFFFF)
    cnt[C_SEQ] = h


@njit(cache=True, error_model="numpy", _nrt=False)
def _pop(H, cnt):
    """Take the entry of least f (the first pushed among equals); its node id."""
    top = H[1] & 0xFFFFFFFF
    last = cnt[C_HEAP] - 1
    cnt[C_HEAP] = last
    if last > 0:
        k1 = H[2 * last]
        k2 = H[2 * last + 1]
        i = 0
        while True:                    # sift down: move smaller children up
            c = 2 * i + 1
            if c >= last:
                break
            c1 = H[2 * c]
            c2 = H[2 * c + 1]
            if c + 1 < last:
                d1 = H[2 * c + 2]
                d2 = H[2 * c + 3]
                if d1 < c1 or (d1 == c1 and d2 < c2):
                    c += 1
                    c1 = d1
                    c2 = d2
            if c1 < k1 or (c1 == k1 and c2 < k2):
                H[2 * i] = c1
                H[2 * i + 1] = c2
                i = c
            else:
                break
        H[2 * i] = k1
        H[2 * i + 1] = k2
    return top
