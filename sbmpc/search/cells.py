"""The implicit state grid's cell table (compiled, no allocation): a state's cell index,
and the open-addressing table from a cell's packed key to the node that holds it."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

_EMPTY = -1


@njit(cache=True, error_model="numpy", _nrt=False)
def cell_index(x, res):
    """round(x / res), half away from zero (without a branch on the sign, which the
    processor cannot predict for states around zero)."""
    q = x / res
    c = int(math.floor(abs(q) + 0.5))
    return c if q >= 0.0 else -c


# The cell table: open addressing with linear probing, a slot per pair of int64 (the
# cell's code, its node id or -1 if empty), so that a probe reads one cache line and a
# hit needs no look at the node's key. A key of up to 3 cells of magnitude < 2^20 packs
# exactly into a non-negative code (21 bits each); any other key's code is its 64-bit
# hash with the top bit set (negative), and an equal code is confirmed on the keys.
_PACK = 1 << 20


@njit(cache=True, error_model="numpy", inline="always")
def _code(key):
    kd = key.shape[0]
    if kd <= 3:
        c = np.int64(0)
        exact = True
        for d in range(kd):
            k = key[d]
            exact &= -_PACK <= k < _PACK
            c = (c << 21) | (k & (2 * _PACK - 1))
        if exact:
            return c
    h = np.uint64(1469598103934665603)
    for d in range(kd):
        h = (h ^ np.uint64(key[d] & 0xFFFFFFFFFFFF)) * np.uint64(1099511628211)
        h ^= h >> np.uint64(29)
    return np.int64(h | np.uint64(1 << 63))


@njit(cache=True, error_model="numpy", inline="always")
def _shift(table):
    """64 - log2(slots of the cell table): the home slot is the top bits of the code's
    Fibonacci hash (Knuth's multiplicative hashing; its low bits cluster the codes of
    neighbouring cells)."""
    n = table.shape[0] >> 1
    s = 64
    while n > 1:
        n >>= 1
        s -= 1
    return np.uint64(s)


@njit(cache=True, error_model="numpy", inline="always")
def _is_key(keys, n, key):
    """Whether node n's key (row n of ``keys``) is ``key``."""
    for d in range(key.shape[0]):
        if keys[n, d] != key[d]:
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _lookup(table, shift, keys, key, code):
    """Slot of ``key`` (with its :func:`_code`) in the cell ``table`` (``shift``:
    :func:`_shift`): returns (slot, node id or -1)."""
    mask = np.int64((table.shape[0] >> 1) - 1)
    i = np.int64((np.uint64(code) * np.uint64(0x9E3779B97F4A7C15)) >> shift)
    while True:
        n = table[2 * i + 1]
        if n == _EMPTY:
            return i, -1
        if table[2 * i] == code and (code >= 0 or _is_key(keys, n, key)):
            return i, n
        i = (i + 1) & mask


@njit(cache=True, error_model="numpy", inline="always")
def _insert(table, slot, code, node):
    table[2 * slot] = code
    table[2 * slot + 1] = node


@njit(cache=True, error_model="numpy")
def rehash(table, keys, n_nodes):
    """Rebuild a cell table for the first n_nodes keys (after growing)."""
    table[:] = _EMPTY
    shift = _shift(table)
    for n in range(n_nodes):
        code = _code(keys[n])
        slot, _ = _lookup(table, shift, keys, keys[n], code)
        _insert(table, slot, code, n)
