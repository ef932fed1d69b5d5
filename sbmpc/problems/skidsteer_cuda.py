"""The skid-steer's batch expander on an NVIDIA GPU (numba-cuda, ``pip install 'sbmpc[gpu]'``).

One CUDA thread per edge runs :func:`sbmpc.problems.skidsteer.edge_cost`, the function
the CPU expanders run: numba-cuda compiles it and everything it calls (the closed-loop
step of ``dynamics.kernels``, the terrain's friction, ``maps.grid``'s pitch and roll)
from the same Python source as device functions. There is no second copy of the
physics; the only CUDA code is the kernel below, which gives each thread its scratch
arrays (``cuda.local.array``: the model allocates nothing).

:func:`unavailable` says why the GPU cannot be used (no numba-cuda, no driver, no
device), or None. :class:`CudaEdges` holds a problem's ``params`` and ``data`` on the
device and is a ``Problem.expand_batch``: each call copies the batch's parent states and
controls in, runs one thread per edge and copies the children and costs back.

Tested in CI with numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``: the same kernel,
run by Python threads), and compiled for sm_90 with ``numba.cuda.compile_ptx`` where a
CUDA toolkit is installed (``tests/test_cuda.py``).
"""
from __future__ import annotations

import functools
import time

import numpy as np

if not hasattr(np, "row_stack"):    # numba-cuda 0.30 registers np.row_stack, which NumPy 2.5 removed
    np.row_stack = np.vstack
from numba import cuda  # noqa: E402

from dynamics import kernels as K

from . import skidsteer as SS

THREADS_PER_BLOCK = 128
BY_CONTROL = False     # CudaEdges' default thread order (by control was slower on an H200: bench_gpu)


def _simulated(fn):
    """Under numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1) a kernel's arrays are
    Python wrappers that compiled CPU code cannot take: hand ``fn`` the NumPy arrays
    inside them. On a GPU ``fn`` itself is called (compiled as a device function)."""
    from numba import config
    if not config.ENABLE_CUDASIM:
        return fn

    def unwrap(a):
        if isinstance(a, np.ndarray) or np.isscalar(a):
            return a
        a = vars(a).get("_item", a)            # FakeWithinKernelCUDAArray -> FakeCUDAArray
        return vars(a).get("_ary", a)          # FakeCUDAArray -> ndarray

    def call(*args):
        return fn(*(unwrap(a) for a in args))
    return call


edge_cost = _simulated(SS.edge_cost)
NO = K.NO            # (module constants: cuda.local.array needs literal shapes)
NR = K.NR


@functools.lru_cache(maxsize=1)
def unavailable() -> str | None:
    """Why the CUDA backend cannot run here (one line), or None when it can."""
    try:
        if not cuda.is_available():
            return "no CUDA GPU or driver found"
    except Exception as exc:                 # a broken driver or toolkit
        return f"CUDA cannot start: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
    return None


@functools.lru_cache(maxsize=1)
def kernel():
    """The edge kernel (compiled for the GPU on its first launch)."""
    @cuda.jit
    def edges(params, data, parents, owner, controls, order, children, costs):
        t = cuda.grid(1)
        if t < owner.shape[0]:
            e = order[t]                       # thread t runs edge order[t]
            O = cuda.local.array(NO, np.float64)
            rec = cuda.local.array((1, NR), np.float64)
            # rows = 1 = rec's length: nothing is recorded
            costs[e] = edge_cost(params, data, parents[owner[e]], controls[e], children[e], rec, 1, O)
    return edges


class CudaEdges:
    """``Problem.expand_batch`` on the GPU for one problem's ``params`` and ``data``
    (copied to the device once).

    ``by_control``: hand neighbouring threads the edges of one control (from different
    nodes) rather than one node's different controls. The 32 threads of a warp run in
    lockstep and wait for each other's branches (Newton iterations, split steps, a
    stall), and edges under one command take more alike paths. ``threads``: threads per
    block. The children and costs are the same either way."""

    def __init__(self, params: np.ndarray, data: np.ndarray, by_control: bool | None = None,
                 threads: int | None = None):
        self.by_control = BY_CONTROL if by_control is None else by_control
        self.threads = threads or THREADS_PER_BLOCK
        self.params = params
        self.data = data
        self.d_params = cuda.to_device(params)
        self.d_data = cuda.to_device(data)
        self.launches = 0
        self.edges = 0
        self.seconds = 0.0          # wall time inside calls: copies in, kernel, copies out

    def __call__(self, params, data, parents, owner, controls, children, costs):
        if params is not self.params or data is not self.data:
            raise ValueError("CudaEdges was made for another problem's params and data")
        n = owner.shape[0]
        if n == 0:
            return
        t0 = time.perf_counter()
        d_par = cuda.to_device(np.ascontiguousarray(parents))
        d_own = cuda.to_device(np.ascontiguousarray(owner))
        d_ctl = cuda.to_device(np.ascontiguousarray(controls))
        order = (np.lexsort((controls[:, 1], controls[:, 0])) if self.by_control else np.arange(n)).astype(np.int64)
        d_ord = cuda.to_device(order)
        d_ch = cuda.device_array(children.shape, np.float64)
        d_co = cuda.device_array(n, np.float64)
        blocks = (n + self.threads - 1) // self.threads
        kernel()[blocks, self.threads](self.d_params, self.d_data, d_par, d_own, d_ctl, d_ord, d_ch, d_co)
        children[:] = d_ch.copy_to_host()
        costs[:] = d_co.copy_to_host()
        self.launches += 1
        self.edges += n
        self.seconds += time.perf_counter() - t0
