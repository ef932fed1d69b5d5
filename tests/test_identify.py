import numpy as np
import pytest

from dynamics import load_terrain, load_vehicle
from dynamics.identify import PAPER_RADII, circle_torques, fit_terrain, table_one_study


def test_paper_radii_are_the_31_of_section_v():
    assert len(PAPER_RADII) == 31
    assert PAPER_RADII[0] == pytest.approx(0.2) and PAPER_RADII[8] == pytest.approx(1.0)
    assert PAPER_RADII[17] == pytest.approx(10.0) and PAPER_RADII[-1] == pytest.approx(1e4)
    assert np.all(np.diff(PAPER_RADII) > 0)


def test_exact_torques_recover_the_parameters():
    v, t = load_vehicle(), load_terrain("vinyl_lemniscate")
    tl, tr = circle_torques(v, t, PAPER_RADII[::3])
    fit = fit_terrain(v, t.replace(shear_modulus=0.002, mu_sa=0.3, mu_op=0.3), PAPER_RADII[::3], tl, tr)
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
