"""The one numba decorator of the project: compiled, cached on disk, NumPy error model
(float division by zero gives inf/nan instead of raising, and no zero checks slow the
hot path), and without the GIL (nogil): a search in the controller's worker thread
(:mod:`sbmpc.robot`) leaves the robot's loop free to answer while it runs."""
from numba import njit


def jit(fn):
    return njit(cache=True, error_model="numpy", nogil=True)(fn)


def jit_inline(fn):
    """:func:`jit`, inlined into its callers by numba (a small helper called in a loop:
    the call would cost as much as its body)."""
    return njit(cache=True, error_model="numpy", inline="always", nogil=True)(fn)
