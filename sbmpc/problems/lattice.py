"""The heading lattice of the value (:mod:`sbmpc.planning.value`) and its compiled read,
which the skid-steer heuristic calls (:mod:`sbmpc.problems.skidsteer`): 16 headings,
those of the grid vectors (1, 0), (2, 1), (1, 1), (1, 2), ... (Pivtoraiko and Kelly's,
and Smac's, choice: a straight step along a heading ends on a lattice point)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

VECTORS = ((1, 0), (2, 1), (1, 1), (1, 2), (0, 1), (-1, 2), (-1, 1), (-2, 1),
           (-1, 0), (-2, -1), (-1, -1), (-1, -2), (0, -1), (1, -2), (1, -1), (2, -1))
NH = 16
ANGLES_T = tuple(math.atan2(b, a) % (2.0 * math.pi) for a, b in VECTORS)     # [rad], ascending from 0


@njit(cache=True, error_model="numpy", inline="always")
def read(V, nxv, nyv, cell, ox, oy, x, y, yaw):
    """V (flat, (nyv, nxv, 16)) at the pose (x, y [m], yaw [rad]): the weighted mean of
    the finite values of the eight lattice states around it (bilinear in x and y, linear
    between the two nearest headings), inf where all eight are closed or unreached, or
    the pose lies off the lattice."""
    u = (x - ox) / cell
    v = (y - oy) / cell
    if u < 0.0 or v < 0.0 or u > nxv - 1 or v > nyv - 1:
        return np.inf
    i = min(int(u), nxv - 2)
    j = min(int(v), nyv - 2)
    fu = u - i
    fv = v - j
    a = yaw % (2.0 * math.pi)
    k0 = 15
    for k in range(16):
        if ANGLES_T[k] <= a:
            k0 = k
    k1 = (k0 + 1) % 16
    span = (ANGLES_T[k1] - ANGLES_T[k0]) % (2.0 * math.pi)
    fh = ((a - ANGLES_T[k0]) % (2.0 * math.pi)) / span
    tot = 0.0
    wsum = 0.0
    for dj in range(2):
        wy = fv if dj else 1.0 - fv
        for di in range(2):
            wx = fu if di else 1.0 - fu
            base = ((j + dj) * nxv + i + di) * 16
            for dk in range(2):
                wk = fh if dk else 1.0 - fh
                w = wx * wy * wk
                val = V[base + (k1 if dk else k0)]
                if w > 0.0 and not math.isinf(val):
                    tot += w * val
                    wsum += w
    if wsum <= 1e-9:
        return np.inf
    return tot / wsum


