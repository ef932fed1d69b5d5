"""sbmpc.search.lanes: 16 float32 lanes equal 16 scalar float32 computations, bit for bit."""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numba import njit

from sbmpc.search import lanes

_f32 = st.floats(-1e6, 1e6, width=32)


@njit(cache=True)
def _euler(x0, c, v, dt, n, out):
    """x += c v dt, n times, in lanes (out[0:16]) and as scalars (out[16:32])."""
    x = lanes.splat(x0)
    for _ in range(n):
        x = lanes.add(x, lanes.mul(lanes.mul(lanes.load(c, 0), lanes.load(v, 0)), lanes.splat(dt)))
    lanes.store(out, 0, x)
    for b in range(16):
        s = x0
        for _ in range(n):
            s = np.float32(s + c[b] * v[b] * dt)
        out[16 + b] = s


@njit(cache=True)
def _less_sub(a, b, off):
    return lanes.less(lanes.sub(lanes.load(a, off), lanes.load(b, off)), lanes.splat(np.float32(0.0)))


@settings(max_examples=60, deadline=None)
@given(_f32, arrays(np.float32, 16, elements=_f32), arrays(np.float32, 16, elements=_f32),
       st.floats(0.0009765625, 1.0, width=32), st.integers(0, 12))
def test_lane_arithmetic_equals_scalar_float32(x0, c, v, dt, n):
    out = np.zeros(32, np.float32)
    _euler(np.float32(x0), c, v, np.float32(dt), n, out)
    np.testing.assert_array_equal(out[:16].view(np.int32), out[16:].view(np.int32))


@settings(max_examples=60, deadline=None)
@given(arrays(np.float32, 20, elements=_f32), arrays(np.float32, 20, elements=_f32), st.integers(0, 4))
def test_less_is_the_bit_mask_of_the_lanes(a, b, off):
    mask = _less_sub(a, b, off)
    want = sum(1 << i for i in range(16) if np.float32(a[off + i] - b[off + i]) < 0)
    assert mask == want


@njit(cache=True)
def _snap_dist(x32, y32, res, out):
    """float64 lanes: distance from the origin of the cell centres of float32 points."""
    x = lanes.widen(lanes.load(x32, 0))
    y = lanes.widen(lanes.load(y32, 0))
    h = lanes.splat(0.5)
    qx = lanes.div(x, lanes.splat(res))
    qy = lanes.div(y, lanes.splat(res))
    sx = lanes.mul(lanes.copysign(lanes.floor(lanes.add(lanes.absolute(qx), h)), qx), lanes.splat(res))
    sy = lanes.mul(lanes.copysign(lanes.floor(lanes.add(lanes.absolute(qy), h)), qy), lanes.splat(res))
    lanes.store(out, 0, lanes.sqrt(lanes.add(lanes.mul(sx, sx), lanes.mul(sy, sy))))


@settings(max_examples=60, deadline=None)
@given(arrays(np.float32, 16, elements=_f32), arrays(np.float32, 16, elements=_f32),
       st.sampled_from([0.1, 0.25, 1.0 / 3.0]))
def test_float64_lanes_equal_numpy(x, y, res):
    """widen, div, absolute, floor, copysign, mul, add, sqrt in float64 lanes: numpy's
    values bit for bit."""
    out = np.zeros(16)
    _snap_dist(x, y, res, out)
    qx, qy = x.astype(float) / res, y.astype(float) / res
    sx = np.copysign(np.floor(np.abs(qx) + 0.5), qx) * res
    sy = np.copysign(np.floor(np.abs(qy) + 0.5), qy) * res
    np.testing.assert_array_equal(out, np.sqrt(sx * sx + sy * sy))
