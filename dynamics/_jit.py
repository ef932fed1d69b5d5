"""The one numba decorator of the project: compiled, cached on disk, NumPy error model
(float division by zero gives inf/nan instead of raising, and no zero checks slow the
hot path)."""
from numba import njit


def jit(fn):
    return njit(cache=True, error_model="numpy")(fn)


def jit_inline(fn):
    """:func:`jit`, inlined into its callers by numba (a small helper called in a loop:
    the call would cost as much as its body)."""
    return njit(cache=True, error_model="numpy", inline="always")(fn)
