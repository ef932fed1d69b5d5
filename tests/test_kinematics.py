import numpy as np
import pytest
from hypothesis import given, strategies as st

from dynamics.kinematics import (alpha_from_slip_ratios, alpha_model, commanded_curvature,
                                 slip_model, slip_ratios_for_alpha, wheel_speeds)

speeds = st.floats(0.1, 10.0) | st.floats(-10.0, -0.1)


@given(wl=speeds, wr=speeds, alpha=st.floats(1.0, 4.0))
def test_eq3_slip_ratios_make_eq2_equal_eq1(wl, wr, alpha):
    il, ir = slip_ratios_for_alpha(wl, wr, alpha)
    v1, w1 = alpha_model(wl, wr, 0.11, 0.4, alpha)
    v2, w2 = slip_model(wl, wr, il, ir, 0.11, 0.4)
    assert v2 == pytest.approx(v1, abs=1e-9)
    assert w2 == pytest.approx(w1, abs=1e-9)
    if abs(wr - wl) > 1e-3 and alpha > 1.01:
        assert il / ir == pytest.approx(-wr / wl, rel=1e-9)
        assert alpha_from_slip_ratios(il, ir) == pytest.approx(alpha, rel=1e-6)


@given(v=st.floats(-2, 2), kappa=st.floats(-4, 4), alpha=st.floats(1.0, 3.0))
def test_inverse_kinematics_roundtrip(v, kappa, alpha):
    wl, wr = wheel_speeds(v, kappa, 0.11, 0.4, alpha)
    v2, yaw_rate = alpha_model(wl, wr, 0.11, 0.4, alpha)
    assert v2 == pytest.approx(v, abs=1e-12)
    assert yaw_rate == pytest.approx(v * kappa, abs=1e-9)


def test_commanded_radius_is_the_no_slip_radius():
    wl, wr = wheel_speeds(0.2, 1 / 4.0, 0.11, 0.4, 1.0)
    assert 1 / commanded_curvature(wl, wr, 0.4) == pytest.approx(4.0)
    # a left turn (positive radius) has the right wheels faster
    assert wr > wl
    # the actual radius is alpha times larger: alpha B kinematics
    v, w = alpha_model(wl, wr, 0.11, 0.4, 1.5)
    assert v / w == pytest.approx(6.0)


def test_alpha_one_is_a_differential_drive():
    v, w = alpha_model(np.array([1.0]), np.array([3.0]), 0.1, 0.5, 1.0)
    assert v[0] == pytest.approx(0.2) and w[0] == pytest.approx(0.4)
