import numpy as np
import pytest

from dynamics import ParameterError, load_terrain, load_vehicle
from dynamics.identify import PAPER_RADII, circle_torques, fit_terrain, table_one_study


def test_paper_radii_are_the_31_of_section_v():
    assert len(PAPER_RADII) == 31
    assert PAPER_RADII[0] == pytest.approx(0.2) and PAPER_RADII[8] == pytest.approx(1.0)
    assert PAPER_RADII[17] == pytest.approx(10.0) and PAPER_RADII[-1] == pytest.approx(1e4)
    assert np.all(np.diff(PAPER_RADII) > 0)


def test_exact_torques_recover_the_parameters():
    """Generated torques at circles the drive holds (on the lemniscate's vinyl the outer
    side of a 0.2-1 m circle at 0.2 m/s asks 5.3-6.4 N m of a 5 N m drive: no steady
    state exists there, and circle_torques says so)."""
    v, t = load_vehicle(), load_terrain("vinyl_lemniscate")
    with pytest.raises(ParameterError, match="cannot hold .* circles at 0.2 m/s .*0.2"):
        circle_torques(v, t, PAPER_RADII[::3])
    radii = PAPER_RADII[PAPER_RADII >= 2.0][::2]
    tl, tr = circle_torques(v, t, radii)
    fit = fit_terrain(v, t.replace(shear_modulus=0.002, mu_sa=0.3, mu_op=0.3), radii, tl, tr)
    assert fit.shear_modulus == pytest.approx(t.shear_modulus, rel=0.02)
    assert fit.mu_sa == pytest.approx(t.mu_sa, rel=0.01)
    assert fit.mu_op == pytest.approx(t.mu_op, rel=0.01)


def test_table_one_study_settles_as_n_grows():
    """Paper Table I: estimates vary modestly from N = 2 to 31 and settle near the truth."""
    v, truth = load_vehicle(), load_terrain("vinyl")
    rows = dict(table_one_study(v, truth, noise=0.05, seed=1, counts=[3, 8, 16, 31]))
    full = rows[31]
    assert full.shear_modulus == pytest.approx(truth.shear_modulus, rel=0.1)
    assert full.mu_sa == pytest.approx(truth.mu_sa, rel=0.03)
    assert full.mu_op == pytest.approx(truth.mu_op, rel=0.05)
    assert full.stderr[1] < rows[3].stderr[1] or rows[3].stderr[1] == np.inf
    assert full.rms == pytest.approx(0.05, rel=0.4)       # residual at the noise level


def test_kinematic_alpha_and_forward_scale_recovered_from_a_jumpy_held_pose():
    """Eq. 1 from pose: a pose generated with alpha = 1.7 and 85 % forward efficiency,
    updated at only 5 Hz (held in between, as scan matching is) and with a few jumps,
    gives back both numbers."""
    from hypothesis import given, settings, strategies as st

    from dynamics.identify import fit_kinematics

    @settings(max_examples=15, deadline=None)
    @given(st.integers(0, 10_000), st.floats(1.1, 3.0), st.floats(0.5, 1.0))
    def check(seed, alpha, s):
        rng = np.random.default_rng(seed)
        dt, r, B = 0.05, 0.3, 1.0
        n = 4000
        hold = rng.uniform(1, 4, n // 40).repeat(40)
        wl = np.where(rng.random(n // 40) < 0.3, 8.0, rng.uniform(-10, 12, n // 40)).repeat(40) + 0.1 * rng.normal(size=n)
        wr = np.where(hold > 2.5, wl, np.r_[rng.uniform(-10, 12, n // 40)].repeat(40))
        v = s * r * (wl + wr) / 2
        w = r * (wr - wl) / (alpha * B)
        yaw = np.r_[0.0, np.cumsum(w[:-1] * dt)]
        x = np.r_[0.0, np.cumsum(v[:-1] * np.cos(yaw[:-1]) * dt)]
        y = np.r_[0.0, np.cumsum(v[:-1] * np.sin(yaw[:-1]) * dt)]
        held = (np.arange(n) // 4) * 4              # 5 Hz updates
        x, y, yaw = x[held], y[held], yaw[held]
        jumps = rng.choice(n, 10, replace=False)
        x[jumps] += rng.normal(0, 2.0, 10)
        t = dt * np.arange(n)
        f = fit_kinematics(t, wl, wr, x, y, yaw, r, B, span_s=1.0)
        assert f["alpha"] == pytest.approx(alpha, rel=0.03)
        assert f["v_scale"] == pytest.approx(s, rel=0.05)
    check()


def test_a_fit_without_enough_data_names_it():
    """fit_terrain on empty lists returned its initial guess with an rms of NaN; torques
    of other lengths than the radii were an unnamed broadcast error."""
    from dynamics import ParameterError
    v, t = load_vehicle("p3at"), load_terrain("vinyl")
    for radii, tl, tr in [([], [], []), ([1.0, 2.0], [0.1], [0.1, 0.2]), ([1.0, np.nan], [0.1, 0.2], [0.1, 0.2]),
                          ([0.0, 2.0], [0.1, 0.2], [0.1, 0.2])]:
        with pytest.raises(ParameterError, match="radii, tau_l, tau_r: expected"):
            fit_terrain(v, t, radii, tl, tr)
