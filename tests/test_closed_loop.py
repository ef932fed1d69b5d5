import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from dynamics import Model, load_terrain, shipped_terrains
from dynamics.limits import steepest_grade, top_speed
from dynamics.manoeuvres import circle, lemniscate, ramp_run, straight
from dynamics.simulate import hold, simulate


def test_fig17_unachievable_command_settles_at_093(vinyl):
    """Paper Fig. 17: commanded 1.5 m/s straight on vinyl, the speed settles at 0.93 m/s."""
    tr = simulate(vinyl, *straight(vinyl, 1.5, 8.0))
    assert tr.v[-1] == pytest.approx(0.93, abs=0.02)
    assert np.ptp(tr.v[-100:]) < 1e-3          # settled
    assert top_speed(vinyl.vehicle, vinyl.terrain) == pytest.approx(tr.v[-1], abs=2e-3)


def test_reference_ramp_and_acceleration_limit(vinyl):
    """A reachable command is approached at the commanded 1 m/s^2 and then held exactly."""
    tr = simulate(vinyl, *straight(vinyl, 0.6, 3.0))
    i = np.searchsorted(tr.t, 0.3)
    assert tr.v[i] == pytest.approx(0.3, abs=0.05)
    assert tr.v[-1] == pytest.approx(0.6, abs=1e-3)


def test_largest_acceleration_from_rest_is_current_limited():
    """PARAMETERS.md: about 2.6 m/s^2 from rest with the continuous torque of 5 N m."""
    m = Model.load("p3at", "vinyl")
    fast = m.with_(vehicle=m.vehicle.replace(ref_accel=100.0))
    tr = simulate(fast, *straight(fast, 0.8, 0.3))
    acc = np.gradient(tr.v, tr.t)
    assert acc[3:15].max() == pytest.approx(2.57, abs=0.1)
    assert np.all(np.abs(tr.i_l) <= m.vehicle.current_limit + 1e-9)


@pytest.mark.parametrize("R", [0.2, 1.0, 4.0, 100.0])
def test_steady_circle_matches_eq22(vinyl, R):
    from dynamics.identify import circle_torques
    tr = simulate(vinyl, *circle(vinyl, 0.2, R, 15.0))
    tl, trr = circle_torques(vinyl.vehicle, vinyl.terrain, [R])
    assert tr.tau_l[-1] == pytest.approx(tl[0], abs=0.01)
    assert tr.tau_r[-1] == pytest.approx(trr[0], abs=0.01)
    # the vehicle drives the alpha-model circle: radius alpha times the commanded one
    assert tr.v[-1] / tr.yaw_rate[-1] == pytest.approx(R * vinyl.terrain.alpha, rel=1e-3)


def test_mirror_symmetry_of_a_rollout(vinyl):
    cl, cr = circle(vinyl, 0.4, 1.5, 4.0)
    a = simulate(vinyl, cl, cr)
    b = simulate(vinyl, cr, cl)
    assert np.allclose(b.yaw_rate, -a.yaw_rate, atol=1e-9)
    assert np.allclose(b.tau_l, a.tau_r, atol=1e-9) and np.allclose(b.tau_r, a.tau_l, atol=1e-9)
    assert np.allclose(b.y, -a.y, atol=1e-9) and np.allclose(b.x, a.x, atol=1e-9)
    assert np.allclose(b.energy_J, a.energy_J, rtol=1e-9)


def test_hill_54deg_asphalt_holds_07(asphalt):
    """Paper Fig. 18: 0.7 m/s held on a 5.4 degree asphalt hill."""
    tr, crossed, _ = ramp_run(asphalt, 0.7, 0.7, 5.4, 6.0, duration=9.0)
    on = (tr.s > 0.5) & (tr.s < 5.5)
    assert crossed and not tr.stalled
    assert np.all(np.abs(tr.v[on] - 0.7) < 0.01)


@pytest.mark.parametrize("terrain", ["vinyl", "asphalt", "grass"])
def test_beyond_the_steepest_grade_the_vehicle_decelerates_whatever_the_command(terrain):
    m = Model.load("p3at", terrain)
    beta = math.degrees(steepest_grade(m.vehicle, m.terrain)) + 1.5
    for v_cmd in (0.5, 1.2):
        tr, crossed, _ = ramp_run(m, v_cmd, 0.6, beta, 50.0, duration=4.0)
        on = tr.s > 0.05
        assert np.all(np.diff(tr.v[on]) <= 1e-9), (terrain, v_cmd)
        assert not crossed
    # just below it the vehicle holds a slow speed indefinitely
    tr, crossed, _ = ramp_run(m, 0.3, 0.3, beta - 2.0, 3.0, duration=15.0)
    assert crossed and not tr.stalled


def test_steep_ramp_crossing_depends_on_entry_speed(vinyl):
    """Paper Figs. 19, 20: the same steep ramp is crossed from a fast entry and not from a slow one."""
    fast, crossed_fast, t_top = ramp_run(vinyl, 1.2, 0.9, 17.0, 1.0, duration=6.0)
    slow, crossed_slow, _ = ramp_run(vinyl, 1.2, 0.3, 17.0, 1.0, duration=6.0)
    assert crossed_fast and not fast.stalled and t_top < 3.0
    assert not crossed_slow and slow.stalled
    on = (fast.s > 0.05) & (fast.s < 0.95)
    assert np.all(np.diff(fast.v[on]) < 0)  # decelerating all the way up


def test_steepest_grade_per_terrain_is_reported_and_ordered():
    grades = {t: math.degrees(steepest_grade(Model.load("p3at", t).vehicle, load_terrain(t))) for t in shipped_terrains()}
    assert grades["vinyl"] == pytest.approx(15.3, abs=0.3)     # PARAMETERS.md: about 15 degrees
    assert grades["vinyl"] > grades["asphalt"] > grades["packed_dirt"] > grades["grass"]


def test_integral_does_not_wind_up_while_saturated(vinyl):
    """Held against an unreachable command for 5 s, the drive recovers from the new,
    reachable command without the overshoot that a wound-up integral would cause."""
    w_hi, w_lo = 1.5 / 0.11, 0.5 / 0.11
    cl = np.concatenate([hold(w_hi, 5.0, vinyl.step_s), hold(w_lo, 3.0, vinyl.step_s)])
    tr = simulate(vinyl, cl, cl)
    after = tr.t > 5.0
    assert tr.v[after].min() > 0.5 - 0.03
    assert tr.v[-1] == pytest.approx(0.5, abs=2e-3)
    assert abs(tr.final_state[4] * vinyl.vehicle.ki) < 2 * vinyl.vehicle.current_limit


def test_closed_loop_predicts_far_better_than_open_loop():
    """Paper Fig. 16. A 'real' vehicle differs from the nominal model (heavier, rolls worse).
    Commanded 0.2 m/s, the nominal closed-loop model predicts its speed; the nominal open-loop
    model driven with the real vehicle's own current does not (it integrates the mismatch)."""
    nominal = Model.load("p3at", "vinyl")
    real = nominal.with_(vehicle=nominal.vehicle.replace(mass=36.0),
                         terrain=nominal.terrain.replace(mu_roll=0.06))
    cl, cr = straight(nominal, 0.2, 10.0)
    truth = simulate(real, cl, cr)
    closed = simulate(nominal, cl, cr)
    dt = nominal.step_s
    i_real = np.interp(np.arange(len(cl)) * dt + dt, truth.t, truth.i_l)
    opened = simulate(nominal, i_real, i_real, open_loop=True)
    err_closed = np.sqrt(np.mean((closed.v - truth.v) ** 2))
    err_open = np.sqrt(np.mean((opened.v - truth.v) ** 2))
    assert err_closed < 0.01
    assert err_open > 10 * err_closed


def test_lemniscate_is_finite_and_smooth():
    m = Model.load("p3at", "vinyl_lemniscate")
    tr = simulate(m, *lemniscate(m, duration=18.0))
    for ch in (tr.v, tr.yaw_rate, tr.tau_l, tr.tau_r, tr.power_W):
        assert np.all(np.isfinite(ch))
    follow = tr.t > 4.0
    assert np.max(np.abs(np.diff(tr.v[follow]))) < 1e-3           # no jumps over 10 ms
    assert np.max(np.abs(np.diff(tr.tau_r[follow]))) < 0.05
    assert not tr.stalled
    assert np.all(np.abs(tr.tau_r) <= m.vehicle.continuous_torque + 1e-9)


def test_coarse_step_stays_close_to_the_controller_rate(vinyl):
    """The planner integrates with 10 ms steps: within 1 cm of the 1 ms solution over 5 s."""
    fine = simulate(vinyl, *circle(vinyl, 0.5, 1.0, 5.0))
    coarse = simulate(vinyl, *circle(vinyl, 0.5, 1.0, 5.0, dt=0.01), dt=0.01)
    assert math.hypot(fine.x[-1] - coarse.x[-1], fine.y[-1] - coarse.y[-1]) < 0.01
    assert coarse.energy_J[-1] == pytest.approx(fine.energy_J[-1], rel=0.02)


def test_energy_is_the_integral_of_battery_power(vinyl):
    tr = simulate(vinyl, *circle(vinyl, 0.3, 0.8, 4.0))
    assert np.all(tr.power_W >= 0) and np.all(np.diff(tr.energy_J) >= 0)
    assert tr.energy_J[-1] == pytest.approx(np.trapezoid(tr.power_W, tr.t), rel=0.01)


@given(wl=st.floats(-12, 12), wr=st.floats(-12, 12), pitch=st.floats(-0.45, 0.45),
       terrain=st.sampled_from(["vinyl", "asphalt", "grass", "packed_dirt"]),
       v0=st.floats(-1, 1), dt=st.sampled_from([0.001, 0.01, 0.02]))
def test_no_nan_or_inf_over_random_commands_grades_and_terrains(wl, wr, pitch, terrain, v0, dt):
    m = Model.load("p3at", terrain)
    w0 = v0 / m.vehicle.wheel_radius
    tr = simulate(m, hold(wl, 1.0, dt), hold(wr, 1.0, dt), pitch=pitch, state=m.state(w0, w0), dt=dt)
    for name in ("v", "yaw_rate", "wl", "wr", "tau_l", "tau_r", "power_W", "energy_J", "x", "y"):
        assert np.all(np.isfinite(tr.data[name])), name
    assert np.all(np.abs(tr.i_l) <= m.vehicle.current_limit + 1e-9)
    assert np.all(np.abs(tr.wl) < 1.5 * m.vehicle.no_load_speed + 10 * abs(pitch) + 1)


def test_implicit_step_reduces_to_eq25_and_drive_window_to_eqs26_27(p3at):
    from dynamics.body import implicit_wheel_step, mass_matrix, wheel_accelerations
    from dynamics.drive import current_window, max_motor_voltage, motor_torque
    m11, m12 = mass_matrix(p3at.mass, p3at.inertia, p3at.wheel_radius, p3at.width, 1.5)
    al, ar = wheel_accelerations(m11, m12, 3.0, -1.0, 0.5, 0.2, 0.4)
    dl, dr = implicit_wheel_step(m11, m12, 0.0, 0.0, 0.0, 0.0, 3.0, -1.0, 0.5, 0.2, 0.4, 0.4, 0.01)
    assert (dl, dr) == (pytest.approx(0.01 * al), pytest.approx(0.01 * ar))
    k, ra, vmax = p3at.torque_constant, p3at.armature_resistance, p3at.v_max
    lo, hi = current_window(7.0, vmax, k, ra, p3at.current_limit)      # voltage-bound at 7 rad/s
    assert hi == pytest.approx(motor_torque(vmax, 7.0, k, ra) / k) and hi < p3at.current_limit
    assert k * 7.0 == pytest.approx(max_motor_voltage(vmax, ra, hi))   # eq. 27: back-EMF at the limit
    assert current_window(0.0, vmax, k, ra, p3at.current_limit) == (-p3at.current_limit, p3at.current_limit)
    lo, hi = current_window(10.0, vmax, k, ra, p3at.current_limit)     # braking window below over-speed
    assert (lo, hi) == (-p3at.current_limit, pytest.approx((vmax - k * 10.0) / ra))
    lo, hi = current_window(12.0, vmax, k, ra, p3at.current_limit)     # over-speed (> 10.53 rad/s): one current
    assert lo == hi == pytest.approx((vmax - k * 12.0) / ra)
    lo, hi = current_window(-12.0, vmax, k, ra, p3at.current_limit)
    assert lo == hi == pytest.approx((-vmax + k * 12.0) / ra)


@pytest.mark.parametrize("terrain", ["vinyl", "asphalt", "grass", "packed_dirt"])
def test_commands_from_rest_stay_bounded_at_the_planners_steps(terrain):
    """Regression: a point turn from rest (wl = -0.61, wr = 4.56 rad/s on packed dirt) blew
    up at dt = 10 ms when the friction's cross slopes made the implicit matrix singular.
    Every command of a grid over the planner's range, from rest, at 10 and 20 ms: wheel
    speeds stay within the drive's reach and battery power within what the drive can
    draw (both sides at the current limit and the no-load speed)."""
    m = Model.load("p3at", terrain)
    v = m.vehicle
    p_max = 2 * (v.current_limit ** 2 * v.armature_resistance + v.torque_constant * v.current_limit * v.no_load_speed)
    w0 = v.no_load_speed
    cmds = [(-0.608, 4.56)] + [(a * w0, b * w0) for a in np.linspace(-0.5, 1, 7) for b in np.linspace(-0.5, 1, 7)]
    for dt in (0.01, 0.02):
        for cl, cr in cmds:
            tr = simulate(m, hold(cl, 1.5, dt), hold(cr, 1.5, dt), state=m.state(0.0, 0.0), dt=dt)
            assert np.all(np.abs(tr.wl) <= 1.1 * w0) and np.all(np.abs(tr.wr) <= 1.1 * w0), (dt, cl, cr)
            assert np.all(tr.power_W <= p_max + 1e-9), (dt, cl, cr)
