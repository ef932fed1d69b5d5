import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st
from scipy.integrate import dblquad

from dynamics import kernels as K
from dynamics import load_terrain, load_vehicle
from dynamics.kinematics import wheel_speeds
from dynamics.resistance import (contact_time, friction_table, shear_displacement,
                                 sliding_velocity, steady_resistance, steady_resistance_fast,
                                 unit_friction_fast, unit_friction_right)

V = load_vehicle("p3at")
VINYL = load_terrain("vinyl")


def commanded(R, v=0.2):
    return wheel_speeds(v, 1.0 / np.asarray(R, float), V.wheel_radius, V.width, 1.0)


def test_quadrature_matches_adaptive_integration_of_eq17():
    """The tensor Gauss-Legendre form equals scipy's adaptive dblquad of the same integrand."""
    wl, wr = commanded(1.0)
    r, B, L, C, b = V.wheel_radius, V.width, V.patch_outer, V.patch_inner, V.patch_width
    v = r * (wl + wr) / 2
    yaw_rate = r * (wr - wl) / (VINYL.alpha * B)

    def integrand(y, x, y0):
        xw = B / 2 + x
        t = contact_time(y0, y, r * wr, yaw_rate)
        jx, jy = shear_displacement(xw, y, y0, v, t, yaw_rate)
        vx, vy = sliding_velocity(xw, y, v, yaw_rate, r * wr)
        return float((1 - np.exp(-np.hypot(jx, jy) / VINYL.shear_modulus)) * -vy / np.hypot(vx, vy))

    front = dblquad(integrand, -b / 2, b / 2, C / 2, L / 2, args=(L / 2,), epsabs=1e-12)[0]
    rear = dblquad(integrand, -b / 2, b / 2, -L / 2, -C / 2, args=(-C / 2,), epsabs=1e-12)[0]
    assert float(unit_friction_right(wl, wr, V, VINYL)) == pytest.approx(front + rear, rel=1e-5)


@settings(max_examples=40, deadline=None)
@given(wl=st.floats(-8.0, 8.0), wr=st.floats(-8.0, 8.0), front=st.booleans(), x=st.floats(-0.025, 0.025),
       frac=st.floats(0.0, 1.0), alpha=st.floats(1.0, 3.0))
def test_shear_displacement_of_eqs_12_16_is_the_integral_of_the_sliding_velocity(wl, wr, front, x, frac, alpha):
    """Eqs. 12-16 in closed form against their definition, integrated numerically: a
    tread particle of the right side enters its patch at y0 (L/2 front, -C/2 rear) and
    moves back at the rim speed, y(tau) = y0 - r w tau (eq. 8); its sliding velocity in
    the body frame is eq. 9's (-y yaw_rate, v + xw yaw_rate - r w), and the body has
    turned by yaw_rate tau since (eq. 11); j is the integral of that velocity in the
    ground frame over the contact time. Any rotation angle (the closed forms are exact at
    constant rates); the quadrature test above reuses the closed forms, this one does not."""
    from scipy.integrate import quad
    r, B, L, C = V.wheel_radius, V.width, V.patch_outer, V.patch_inner
    rw = r * wr
    assume(abs(rw) > 0.02)
    v = r * (wl + wr) / 2.0
    yaw_rate = r * (wr - wl) / (alpha * B)
    lo, hi = (C / 2, L / 2) if front else (-L / 2, -C / 2)
    y0 = hi if rw > 0 else lo          # the edge the tread enters at (a reversing wheel: the other)
    y = lo + frac * (hi - lo)
    xw = B / 2 + x
    t = (y0 - y) / rw
    assume(t >= 0.0)

    def ground(tau, axis):
        yy = y0 - rw * tau
        vx, vy = -yy * yaw_rate, v + xw * yaw_rate - rw
        ph = yaw_rate * tau
        return vx * np.cos(ph) - vy * np.sin(ph) if axis == 0 else vx * np.sin(ph) + vy * np.cos(ph)

    jx = quad(ground, 0.0, t, args=(0,), epsabs=1e-13, epsrel=1e-12)[0]
    jy = quad(ground, 0.0, t, args=(1,), epsabs=1e-13, epsrel=1e-12)[0]
    cx, cy = shear_displacement(xw, y, y0, v, t, yaw_rate)
    assert float(cx) == pytest.approx(jx, abs=1e-10) and float(cy) == pytest.approx(jy, abs=1e-10)


def test_outer_wheel_torque_of_the_tightest_vinyl_circle():
    """PARAMETERS.md: about 4.7 N m on the outer wheels at 0.2 m commanded radius, inside the
    5.0 N m continuous limit."""
    tl, tr = steady_resistance(*commanded(0.2), V, VINYL)
    assert float(tr) == pytest.approx(4.7, abs=0.05)
    assert float(tr) < V.continuous_torque
    assert float(tl) < 0  # the inner side brakes


def test_fig9_torques_fall_with_radius_and_tend_to_rolling():
    radii = np.array([0.2, 0.3, 0.5, 1, 2, 4, 10, 30, 100, 1000, 1e4])
    tl, tr = steady_resistance(*commanded(radii), V, VINYL)
    rolling = VINYL.mu_roll * V.mass * 9.81 / 2 * V.wheel_radius
    fric_r = tr - rolling
    assert np.all(np.diff(fric_r) < 0)                  # right (outer) friction torque falls
    assert np.all(np.diff(tl[1:]) > 0)                  # left torque rises towards rolling
    assert tr[-1] == pytest.approx(rolling, abs=5e-3)
    assert tl[-1] == pytest.approx(rolling, abs=5e-3)


def test_no_slip_terrain_has_no_sliding_friction():
    """With alpha = 1 the kinematics are those of pure rolling: sliding friction vanishes."""
    ter = VINYL.replace(alpha=1.0)
    for R in (0.5, 2.0, 20.0):
        tl, tr = steady_resistance(*commanded(R), V, ter)
        # only the lateral scrub of the patches remains; its longitudinal share is tiny
        rolling = ter.mu_roll * V.mass * 9.81 / 2 * V.wheel_radius
        assert abs(float(tr) - rolling) < 0.02 * abs(float(steady_resistance(*commanded(R), V, VINYL)[1]) - rolling) + 1e-3


def test_straight_motion_has_zero_friction():
    assert float(unit_friction_right(3.0, 3.0, V, VINYL)) == 0.0
    assert float(unit_friction_right(-3.0, -3.0, V, VINYL)) == 0.0


@pytest.mark.parametrize("wl, wr, case", [
    (0.0, 3.0, "inner wheel at rest"), (3.0, 0.0, "outer wheel at rest"),
    (-2.0, 2.0, "point turn"), (-0.5, 3.0, "inner wheel reversing"),
    (2.0, 2.0 + 1e-9, "almost straight"), (1e-7, 2e-7, "almost at rest"),
])
def test_singular_cases_are_finite_and_bounded(wl, wr, case):
    fmax = V.patch_width * (V.patch_outer - V.patch_inner)   # unit friction cannot exceed the area
    for f in (unit_friction_right(wl, wr, V, VINYL), unit_friction_right(wr, wl, V, VINYL)):
        assert np.isfinite(f) and abs(float(f)) <= fmax * (1 + 1e-9), case
    tl, tr = steady_resistance_fast(wl, wr, V, VINYL)
    assert np.isfinite(tl) and np.isfinite(tr)


def test_point_turn_sides_oppose_each_other():
    tl, tr = steady_resistance(-2.0, 2.0, V, VINYL)
    assert float(tl) == pytest.approx(-float(tr), rel=1e-9)
    assert float(tr) > 0


def test_wheel_at_rest_is_the_fully_sheared_limit():
    """w -> 0 approaches the fully sheared value continuously."""
    f0 = float(unit_friction_right(3.0, 0.0, V, VINYL))
    f_small = float(unit_friction_right(3.0, 1e-6, V, VINYL))
    assert f_small == pytest.approx(f0, rel=1e-3)


def test_mirror_and_reversal_symmetry():
    for wl, wr in [(1.0, 2.0), (-0.3, 2.5), (0.0, 1.0)]:
        tl, tr = steady_resistance(wl, wr, V, VINYL)
        ml, mr = steady_resistance(wr, wl, V, VINYL)
        assert float(ml) == pytest.approx(float(tr), rel=1e-12)
        assert float(mr) == pytest.approx(float(tl), rel=1e-12)
        assert float(unit_friction_right(-wl, -wr, V, VINYL)) == pytest.approx(-float(unit_friction_right(wl, wr, V, VINYL)), rel=1e-9)


@pytest.mark.parametrize("terrain", ["vinyl", "grass", "vinyl_lemniscate"])
def test_fast_form_within_one_percent_of_exact_over_the_whole_range(terrain):
    """Every direction of the wheel-speed plane (all radii, point turns, reversing)."""
    ter = load_terrain(terrain)
    psi = np.linspace(-np.pi, np.pi, 361)
    wl, wr = 2.0 * np.cos(psi), 2.0 * np.sin(psi)
    el, er = steady_resistance(wl, wr, V, ter, n_long=200, n_lat=16)
    fl, fr = steady_resistance_fast(wl, wr, V, ter)
    full_scale = V.wheel_radius * V.mass * 9.81 / 2 * ter.mu_sa
    assert np.max(np.abs(fl - el)) < 0.01 * full_scale / 10   # 0.1 % of full scale
    big = np.abs(er) > 0.3
    assert np.max(np.abs(fr - er)[big] / np.abs(er[big])) < 0.01


def test_fast_form_scale_free_and_jacobian_consistent():
    table = friction_table(V, VINYL)
    a = unit_friction_fast(table, 1.0, 1.3)
    b = unit_friction_fast(table, 5.0, 6.5)
    assert a[0] == pytest.approx(b[0]) and a[1] == pytest.approx(b[1])
    h = 1e-6
    num = (unit_friction_fast(table, 1.0 + h, 1.3)[1] - unit_friction_fast(table, 1.0 - h, 1.3)[1]) / (2 * h)
    assert a[4] == pytest.approx(num, rel=1e-3)


def test_friction_forces_and_eq18_give_the_resistance_torques():
    from dynamics.resistance import friction_forces, rolling_resistance
    wl, wr = commanded(0.7)
    fl, fr = friction_forces(wl, wr, V, VINYL, VINYL.mu_op, VINYL.mu_sa)   # inner brakes, outer drives
    tl, tr = steady_resistance(wl, wr, V, VINYL)
    roll = rolling_resistance(VINYL.mu_roll, V.mass, 0.0, 1.0)
    assert float(tr) == pytest.approx(V.wheel_radius * (float(fr) + roll), rel=1e-12)
    assert float(tl) == pytest.approx(V.wheel_radius * (float(fl) + roll), rel=1e-12)


def test_friction_table_disk_cache_gives_the_computed_table_and_survives_a_bad_file(tmp_path, monkeypatch):
    from dynamics import resistance as R
    monkeypatch.setenv("SBMPC_CACHE_DIR", str(tmp_path))
    veh, ter = load_vehicle("p3at"), load_terrain("grass")
    args = (veh.wheel_radius, veh.width, veh.patch_outer, veh.patch_inner, veh.patch_width, ter.alpha,
            ter.shear_modulus, 512)
    fresh = R._compute_table(*args)
    R._table_cached.cache_clear()
    first = R._table_cached(*args)                    # computed and written
    files = list(tmp_path.glob("friction-*.npy"))
    assert len(files) == 1 and np.array_equal(first, fresh)
    R._table_cached.cache_clear()
    assert np.array_equal(R._table_cached(*args), fresh)     # read back
    files[0].write_bytes(b"not a numpy file")
    R._table_cached.cache_clear()
    assert np.array_equal(R._table_cached(*args), fresh)     # recomputed
    R._table_cached.cache_clear()


def test_a_vehicle_at_rest_on_level_ground_meets_no_resistance():
    """steady_resistance(0, 0) was (nan, nan): the patch integrals are 0/0 at rest."""
    from dynamics import load_terrain, load_vehicle
    from dynamics.resistance import steady_resistance
    tl, tr = steady_resistance(0.0, 0.0, load_vehicle("p3at"), load_terrain("vinyl"))
    assert tl == 0.0 and tr == 0.0


@settings(max_examples=15, deadline=None)
@given(i0=st.floats(0.2, 1.5), v=st.floats(0.2, 0.8), k=st.floats(-0.6, 0.6), sign=st.sampled_from([1.0, -1.0]))
def test_the_motors_no_load_current_is_drawn_on_top_of_the_load_in_any_motion(i0, v, k, sign):
    """A P3-AT whose motors draw i0 turning freely (``no_load_current``, a Coulomb torque k
    i0 against each side's rotation), driven at steady wheel speeds on level vinyl for 3 s
    at 1 kHz, forwards or backwards, straight or turning: each side draws i0 more than the
    same vehicle without it, in the direction its wheels turn, at the same wheel speeds
    (the PID holds them) wherever the drive has that much current to spare; a steady start
    state has those currents already; at rest it draws nothing more."""
    from dynamics.simulate import Model, simulate
    wl, wr = sign * (v + k * v) / V.wheel_radius, sign * (v - k * v) / V.wheel_radius
    n = 3000
    base = Model.load("p3at", "vinyl")
    out = {}
    for name, vehicle in (("without", V), ("with", V.replace(no_load_current=i0))):
        m = base.with_(vehicle=vehicle)
        tr = simulate(m, np.full(n, wl), np.full(n, wr), state=m.state(wl, wr))
        out[name] = tr
        assume(max(abs(tr.i_l[-1]), abs(tr.i_r[-1])) + (i0 if name == "without" else 0.0) < 0.9 * V.current_limit)
        start = m.state(wl, wr)
        assert start[K.S_IL] == pytest.approx(tr.i_l[-1], abs=0.02 + 0.01 * abs(tr.i_l[-1]))   # steady already
    a, b = out["without"], out["with"]
    assert b.i_l[-1] - a.i_l[-1] == pytest.approx(i0 * np.sign(wl), abs=0.02 * i0 + 0.01)
    assert b.i_r[-1] - a.i_r[-1] == pytest.approx(i0 * np.sign(wr), abs=0.02 * i0 + 0.01)
    assert b.wl[-1] == pytest.approx(a.wl[-1], abs=0.02) and b.wr[-1] == pytest.approx(a.wr[-1], abs=0.02)
    m = base.with_(vehicle=V.replace(no_load_current=i0))
    rest = simulate(m, np.zeros(500), np.zeros(500))
    assert np.max(np.abs(rest.i_l)) < 1e-6 and np.max(np.abs(rest.i_r)) < 1e-6
