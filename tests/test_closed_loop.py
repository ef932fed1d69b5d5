import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from dynamics import kernels as K
from dynamics import Model, load_terrain, shipped_terrains
from dynamics.limits import steepest_braked_grade, steepest_grade, top_speed
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
    # eq. 27: within the current limit, unless the back-EMF alone exceeds the supply (a
    # vehicle braking down a slope faster than its no-load speed: 21 deg at 1 m/s reaches
    # 10.7 rad/s), where the voltage bound sets the current (drive.current_window)
    v = m.vehicle
    over = (v.torque_constant * np.abs(tr.wl) - v.v_max) / v.armature_resistance
    assert np.all(np.abs(tr.i_l) <= np.maximum(v.current_limit, over) + 1e-9)


def _eq22_by_hand(v, ter, pitch, w_side, w_other):
    """One side's steady torques by hand from eqs. 17/20, 21 and 24 (exact quadrature,
    not the kernel): (r F(mu_sa), r F(mu_op), G) [N m] for the side turning at w_side
    with the other at w_other (the left side is the right one mirrored)."""
    from dynamics.params import G
    from dynamics.resistance import patch_pressure, rolling_resistance, unit_friction_right
    unit = float(unit_friction_right(w_other, w_side, v, ter))
    p = patch_pressure(v, pitch)
    roll = rolling_resistance(ter.mu_roll, v.mass, pitch, w_side)
    f_sa = v.wheel_radius * (p * ter.mu_sa * unit + roll)
    f_op = v.wheel_radius * (p * ter.mu_op * unit + roll)
    return f_sa, f_op, v.mass * G * v.wheel_radius * math.sin(pitch) / 2.0


@pytest.mark.parametrize("terrain, R, band", [("vinyl", 0.2, False), ("vinyl", 1.0, False), ("vinyl", 16.5, True),
                                              ("vinyl", 20.0, True), ("vinyl", 30.0, False),
                                              ("packed_dirt", 7.5, True), ("grass", 3.2, True)])
def test_steady_circle_settles_on_eq22_without_chatter(terrain, R, band):
    """Steady circles, the radii in eq. 22's band included (vinyl 16-24 m, packed dirt
    about 7.5 m, grass about 3.2 m: there mu_sa would make the inner side brake and
    mu_op would make it drive). The closed loop at the controller rate settles on the
    steady form's torques with no sign flips of the current (it flipped about 90 times
    a second when the kernel chose mu by the sign of current times speed), and the
    inner side's torque never drives with the braking coefficient mu_op."""
    from dynamics.identify import circle_torques
    m = Model.load("p3at", terrain)
    v, ter = m.vehicle, m.terrain
    tr = simulate(m, *circle(m, 0.2, R, 15.0))
    tl, trr = circle_torques(v, ter, [R])
    assert tr.tau_l[-1] == pytest.approx(tl[0], abs=0.01)
    assert tr.tau_r[-1] == pytest.approx(trr[0], abs=0.01)
    late = tr.t > 10.0
    assert np.count_nonzero(np.diff(np.sign(tr.i_l[late])) != 0) <= 1
    assert np.ptp(tr.tau_l[late]) < 0.01
    # eq. 22 on the inner (left) side, by hand from eqs. 17/20 and 21
    wl = tr.wl[-1]
    f_sa, f_op, _ = _eq22_by_hand(v, ter, 0.0, wl, tr.wr[-1])
    assert band == (f_sa * wl < 0 < f_op * wl)
    if f_sa * wl > 0:                                  # drives: mu_sa
        assert tr.tau_l[-1] == pytest.approx(f_sa, abs=0.01)
    elif f_op * wl < 0:                                # brakes: mu_op
        assert tr.tau_l[-1] == pytest.approx(f_op, abs=0.01)
    else:
        # the band: with mu_op it would drive (0.12 N m at vinyl R = 20 m, a driving
        # torque with the braking coefficient), with mu_sa brake: it does neither
        assert abs(tr.tau_l[-1]) < 0.01
    # the vehicle drives the alpha-model circle: radius alpha times the commanded one
    assert tr.v[-1] / tr.yaw_rate[-1] == pytest.approx(R * ter.alpha, rel=1e-3)


@pytest.mark.parametrize("R, rule", [(7.0, "drives"), (4.0, "band")])
def test_on_a_climb_eq22_takes_the_motors_torque_with_gravity(R, rule):
    """Eq. 22 picks mu by what the *motor* does, and on a slope the motor also holds
    gravity (eq. 24). A vinyl circle at 0.2 m/s on a constant 5 degree climb (the outer
    side below its current limit): the inner (left) side is pushed back by the ground
    (its sliding friction brakes) yet its motor drives against gravity, so it takes
    mu_sa (R = 7 m); where mu_sa would make the motor brake and mu_op drive, the motor
    neither drives nor brakes (R = 4 m: its torque is 0, the ground force on the side
    cancels gravity's torque). On level ground the same side brakes with mu_op. The closed loop
    at the controller rate and the steady form agree; a rule on the friction alone
    (mu_op on the climb) misses by 0.39 and 0.51 N m."""
    from dynamics.resistance import steady_resistance
    m = Model.load("p3at", "vinyl")
    v, ter = m.vehicle, m.terrain
    pitch = math.radians(5.0)
    tr = simulate(m, *circle(m, 0.2, R, 10.0), pitch=pitch)
    wl, wr = tr.wl[-1], tr.wr[-1]
    f_sa, f_op, g = _eq22_by_hand(v, ter, pitch, wl, wr)
    assert f_sa < 0.0 and f_op < 0.0                     # the ground pushes the inner side back
    motor = tr.tau_l[-1]                                   # what the inner motor supplies [N m]
    if rule == "drives":                                   # at steady speed: resistance + gravity
        assert f_sa + g > 0.0
        assert motor == pytest.approx(f_sa + g, abs=0.01)
    else:
        assert f_sa + g < 0.0 < f_op + g
        assert abs(motor) < 0.01
    assert abs(tr.tau_r[-1]) < 0.95 * v.current_limit * v.torque_constant
    assert abs(motor - (f_op + g)) > 0.3
    tl, _ = steady_resistance(wl, wr, v, ter, pitch)
    assert float(tl) + g == pytest.approx(motor, abs=0.01)
    flat_l, _ = steady_resistance(wl, wr, v, ter, 0.0)
    assert float(flat_l) == pytest.approx(_eq22_by_hand(v, ter, 0.0, wl, wr)[1], rel=1e-9)


@pytest.mark.parametrize("R, rule", [(10.0, "brakes"), (8.0, "both")])
def test_down_a_slope_the_outer_side_brakes_against_gravity_with_mu_op(R, rule):
    """Eq. 22 on a descent: a vinyl circle at 0.5 m/s on a constant 7 degree descent.
    The ground pushes the outer (right) side forward (its sliding friction drives) while
    gravity pulls the vehicle down: at R = 10 m its motor brakes (r F(mu_sa) + G < 0
    already), so it takes mu_op, the paper's braking coefficient, where a rule on F alone
    took mu_sa. At R = 8 m both coefficients are consistent (r F(mu_sa) + G > 0 >
    r F(mu_op) + G): the rule takes mu_sa and the motor drives a little. Between the two
    the steady torque jumps by r p (mu_sa - mu_op) times the unit friction (0.02 N m at
    R = 8.2 m, -0.43 N m at 8.4 m; docs/model.md), without chatter at 1 kHz."""
    m = Model.load("p3at", "vinyl")
    v, ter = m.vehicle, m.terrain
    pitch = math.radians(-7.0)
    tr = simulate(m, *circle(m, 0.5, R, 12.0), pitch=pitch)
    f_sa, f_op, g = _eq22_by_hand(v, ter, pitch, tr.wr[-1], tr.wl[-1])
    assert f_sa > f_op > 0.0                               # the ground pushes the outer side forward
    motor = tr.tau_r[-1]
    late = tr.t > 7.0
    assert np.count_nonzero(np.diff(np.sign(tr.i_r[late])) != 0) == 0 and np.ptp(tr.tau_r[late]) < 0.01
    if rule == "brakes":
        assert f_sa + g < 0.0
        assert motor == pytest.approx(f_op + g, abs=0.01)
        assert abs(motor - (f_sa + g)) > 0.3               # what the rule on F alone gave
    else:
        assert f_sa + g > 0.0 > f_op + g
        assert motor == pytest.approx(f_sa + g, abs=0.01)


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


def test_the_steepest_grade_with_the_motors_no_load_current_is_the_one_the_model_holds():
    """dynamics.limits counts the motors' no-load current (no_load_current: the drive's
    own Coulomb friction, k i0 of its torque) as the compiled step does: a P3-AT whose
    motors draw 0.8 A turning freely holds a grade no steeper than the closed form
    sin b + mu cos b = 2 k (I_max - i0) / (r m g)), decelerates 1.5 deg beyond it and
    holds a slow speed 2 deg below."""
    m = Model.load("p3at", "vinyl")
    v = m.vehicle.replace(no_load_current=0.8)
    m = m.with_(vehicle=v)
    beta = steepest_grade(v, m.terrain)
    rhs = 2.0 * v.torque_constant * (v.current_limit - 0.8) / (v.wheel_radius * v.mass * 9.81)
    assert math.sin(beta) + m.terrain.mu_roll * math.cos(beta) == pytest.approx(rhs, rel=1e-3)
    assert math.degrees(beta) < math.degrees(steepest_grade(m.vehicle.replace(no_load_current=0.0), m.terrain)) - 2.0
    tr, crossed, _ = ramp_run(m, 0.5, 0.6, math.degrees(beta) + 1.5, 50.0, duration=4.0)
    assert np.all(np.diff(tr.v[tr.s > 0.05]) <= 1e-9) and not crossed
    tr, crossed, _ = ramp_run(m, 0.3, 0.3, math.degrees(beta) - 2.0, 3.0, duration=15.0)
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


def test_a_vehicle_whose_drive_holds_any_grade_is_limited_by_none():
    """A light P3-AT (4 kg: r m g / 2, what one side holds straight up a wall, is less than
    its continuous torque of 5 N m): the drive holds every grade up to vertical at rest,
    so the steepest grade is 90 deg (it was a root-finder error, exit 3 in plan); its
    top speed down a steep slope, where gravity outpulls the losses, is the no-load
    speed's; a grade just under the root is still found for the real vehicle."""
    m = Model.load("p3at", "asphalt")
    light = m.vehicle.replace(mass=4.0)
    assert light.wheel_radius * light.mass * 9.81 / 2 < light.continuous_torque    # holds it straight up
    assert steepest_grade(light, m.terrain) == pytest.approx(math.pi / 2)
    still = light.replace(viscous=0.0)
    assert top_speed(still, m.terrain, -1.2) == pytest.approx(still.no_load_speed * still.wheel_radius)
    heavy = m.vehicle.replace(mass=12.0)
    beta = steepest_grade(heavy, m.terrain)
    assert 0.5 < beta < math.pi / 2
    from dynamics.limits import available_torque, required_torque
    assert required_torque(heavy, m.terrain, beta, 0.0) == pytest.approx(available_torque(heavy, 0.0), rel=1e-9)
    # sin b + mu cos b peaks before 90 deg (at tan b = 1 / mu): a drive that holds a wall
    # may still fail below it, so the peak, not 90 deg, decides whether no grade limits it
    grass = m.terrain.replace(mu_roll=0.2)
    wall = 2 * light.continuous_torque / (light.wheel_radius * 9.81) / 1.01     # mass that just holds 90 deg
    nearly = light.replace(mass=wall)
    assert required_torque(nearly, grass, math.pi / 2, 0.0) < available_torque(nearly, 0.0)
    peak = math.atan(1 / 0.2)
    assert required_torque(nearly, grass, peak, 0.0) > available_torque(nearly, 0.0)
    beta = steepest_grade(nearly, grass)
    assert beta < peak and required_torque(nearly, grass, beta, 0.0) == pytest.approx(available_torque(nearly, 0.0))


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


def test_eqs_29_30_at_reference_points_worked_by_hand():
    """Eqs. 29, 30 pinned by numbers worked from the paper's formulas, not by the code:
    X(0) = 9, Y(0) = 0, dY/dt(0) = 27/50 = 0.54 m/s heading +y; at t = 25 pi s (t/50 =
    pi/2) the crossing (0, 0); at t = 12.5 pi s X = 9 (sqrt2/2) / 1.5 = 4.2426 m and
    Y = 27 (1/2) / 1.5 = 9 m. (The lemniscate test below drives the path the same
    functions give, so it cannot see a wrong constant in them.)"""
    from dynamics.manoeuvres import lemniscate_path, lemniscate_reference
    X, Y = lemniscate_path(np.array([0.0, 25.0 * math.pi, 12.5 * math.pi]))
    assert X == pytest.approx([9.0, 0.0, 4.242640687], abs=1e-9)
    assert Y == pytest.approx([0.0, 0.0, 9.0], abs=1e-9)
    v, kappa, head = lemniscate_reference(np.array([0.0]))
    assert v[0] == pytest.approx(0.54, rel=1e-6) and head[0] == pytest.approx(math.pi / 2, abs=1e-9)


def test_eq5_mass_matrix_by_hand_and_its_yaw_inertia_by_newton():
    """Eq. 5 with the P3-AT's numbers typed in (m 31 kg, I 0.67 kg m^2, r 0.11 m, B 0.4 m,
    alpha 1.5): M11 = m r^2/4 + r^2 I/(alpha B^2) = 0.127554, M12 = 0.059996. Equal and
    opposite wheel torques +-tau give the yaw acceleration Newton's law gives, the ground
    forces' moment over the yaw inertia, tau B / (r I), whatever alpha (the alpha of eq. 5
    cancels against eq. 1's); equal torques give the acceleration 2 tau / (m r). (The other
    tests use M11 + M12 only, where I cancels: alpha squared or 10 I passed them.)"""
    from dynamics.body import mass_matrix, wheel_accelerations
    m, inertia, r, width, alpha = 31.0, 0.67, 0.11, 0.4, 1.5
    m11, m12 = mass_matrix(m, inertia, r, width, alpha)
    assert (m11, m12) == (pytest.approx(0.127554167, abs=1e-8), pytest.approx(0.059995833, abs=1e-8))
    tau = 2.0
    al, ar = wheel_accelerations(m11, m12, -tau, tau, 0.0, 0.0, 0.0)
    assert r * (ar - al) / (alpha * width) == pytest.approx(tau * width / (r * inertia), rel=1e-9)
    al, ar = wheel_accelerations(m11, m12, tau, tau, 0.0, 0.0, 0.0)
    assert r * al == pytest.approx(2.0 * tau / (m * r), rel=1e-9) and al == pytest.approx(ar)


def test_lemniscate_follows_eqs_29_30():
    """Paper Section V-C: the wheel speeds of eqs. 29, 30 through the inverse alpha model
    (Fig. 8), driven by the closed loop on the lemniscate's vinyl: the path driven is the
    lemniscate's, shifted to the start and turned to the start heading, to within 5 cm
    over its first 18 s (8 m; the PID lags the reference a little, so the heading drifts
    by under 1.5 degrees), and the speed is the lemniscate's to 5 mm/s. A wrong alpha
    (eq. 1 with alpha = 1 on vinyl, 1.5) turns the path visibly off."""
    from dynamics.manoeuvres import lemniscate_path, lemniscate_reference
    m = Model.load("p3at", "vinyl_lemniscate")
    run_up = 3.0
    tr = simulate(m, *lemniscate(m, duration=18.0, run_up=run_up))
    follow = tr.t >= run_up
    t = tr.t[follow] - run_up
    X, Y = lemniscate_path(t)
    _, _, head = lemniscate_reference(t)
    # the lemniscate in the vehicle's frame at the start of following
    i0 = np.argmax(follow)
    c, s_ = math.cos(tr.yaw[i0] - head[0]), math.sin(tr.yaw[i0] - head[0])
    dx, dy = X - X[0], Y - Y[0]
    px = tr.x[i0] + c * dx - s_ * dy
    py = tr.y[i0] + s_ * dx + c * dy
    err = np.hypot(tr.x[follow] - px, tr.y[follow] - py)
    length = np.sum(np.hypot(np.diff(X), np.diff(Y)))
    assert length > 8.0
    assert err.max() < 0.05
    v_ref, _, _ = lemniscate_reference(t)
    assert np.max(np.abs(tr.v[follow] - v_ref)[t > 1.0]) < 0.005
    dyaw = np.angle(np.exp(1j * (tr.yaw[follow] - (head + tr.yaw[i0] - head[0]))))
    assert np.degrees(np.max(np.abs(dyaw))) < 1.5
    assert not tr.stalled
    # the same wheel speeds on a ground whose alpha is not the one they were computed for
    wrong = m.with_(terrain=m.terrain.replace(alpha=1.0))
    off = simulate(wrong, *lemniscate(m, duration=18.0, run_up=run_up))
    assert np.hypot(off.x[-1] - px[-1], off.y[-1] - py[-1]) > 0.5


@pytest.mark.slow
def test_planner_edges_converge_to_the_controller_rate():
    """A small version of bench/bench_edges.py: 40 random planner edges (1 s at the
    planner's 20 ms step) on every shipped terrain, entry at rest, moving or turning,
    commands over the whole sampled range (pivots included), grades up to the steepest
    sustainable one + 5 degrees, compared with the 1 kHz digital PID. The explicit PID
    at 20 ms agreed on energy for about 70 % of such edges and turned a grass pivot by
    82 degrees instead of 0.3; the implicit step without sub-steps at wheel-speed
    reversals, for 95 %."""
    from dynamics.convergence import compare, random_edges, shipped_models
    rng = np.random.default_rng(11)
    stall, energy, pose, n, compared = 0, 0, 0, 0, 0
    for m in shipped_models():
        a = compare(random_edges(m, 40, rng), 0.02)
        both = ~a.stall_ref & a.stall_agrees
        stall += a.stall_agrees.sum()
        energy += a.energy_ok()[both].sum()
        pose += a.pose_ok()[both].sum()
        n += len(a.stall_ref)
        compared += both.sum()
    # measured (seed 11): stall 237/240, energy 150/151, pose 151/151 (energy 145/152
    # before the sub-steps at wheel-speed reversals)
    assert stall / n >= 0.98
    assert energy / compared >= 0.98 and pose / compared >= 0.98


def test_the_stall_timer_does_not_depend_on_the_step():
    """From rest up vinyl at 14-15 degrees (full forward command, 3 s) the stall timer
    peaks at 0.08-0.42 s, across the 0.25 s threshold. The test runs on fixed 20 ms
    windows whatever the step, so the 1 kHz controller rate, a 5 ms step and the
    planner's 20 ms step reach the same peak (within 1 ms) and the same verdict. Tested
    per step, the peaks parted by up to 16 ms (14.1 deg: 0.096 s at 1 ms, 0.080 s at
    20 ms), enough to turn an edge whose timer peaks near 0.25 s."""
    m = Model.load("p3at", "vinyl")
    verdicts = set()
    for deg in np.arange(14.0, 15.01, 0.1):
        p = math.radians(deg)
        peaks, stalled = [], []
        for dt in (0.001, 0.005, 0.02):
            S = m.state(0.0, 0.0, pitch=p)[None, :].copy()
            peak = 0.0
            for _ in range(150):
                S = K.rollout_batch(m.P, m.table, S, np.array([[8.0, 8.0]]), int(round(0.02 / dt)), p, dt)
                peak = max(peak, S[0, K.S_STALLT])
            peaks.append(peak)
            stalled.append(S[0, K.S_STALLED])
        assert max(peaks) - min(peaks) < 0.001, (deg, peaks)
        assert len(set(stalled)) == 1, (deg, stalled)
        verdicts.add(stalled[0])
    assert verdicts == {0.0, 1.0}     # the grades straddle the threshold


def test_a_stall_window_follows_its_command_and_closes_at_the_nearest_step():
    """A window is judged against one command: where the command changes within it (a
    control that ends off the 20 ms grid: the goal cut, a truth's command delay), the
    part before the change is dropped and a new window starts. A step that does not
    divide 20 ms closes the window at the step nearest 20 ms (19.9 ms steps: one step,
    not two; 15 ms: one; 12.5 ms: two)."""
    m = Model.load("p3at", "vinyl")
    O = np.zeros(K.NO)
    S = m.state(0.0, 0.0)
    for _ in range(5):
        K.step(m.P, m.table, S, 6.0, 6.0, 0.0, 0.001, False, O)
    assert S[K.S_SWT] == pytest.approx(0.005) and (S[K.S_SWCL], S[K.S_SWCR]) == (6.0, 6.0)
    wl, wr = S[K.S_WL], S[K.S_WR]
    K.step(m.P, m.table, S, 6.0, 3.0, 0.0, 0.001, False, O)
    assert S[K.S_SWT] == pytest.approx(0.001) and (S[K.S_SWCL], S[K.S_SWCR]) == (6.0, 3.0)
    assert (S[K.S_SWL], S[K.S_SWR]) == (wl, wr)          # the new window starts where the change did
    for dt, steps in ((0.0199, 1), (0.015, 1), (0.0125, 2), (0.005, 4), (0.001, 20)):
        S = m.state(6.0, 6.0)      # moving: no sub-steps (a wheel leaving rest splits a coarse step)
        for i in range(steps):
            K.step(m.P, m.table, S, 6.0, 6.0, 0.0, dt, False, O)
            assert (S[K.S_SWT] == 0.0) == (i == steps - 1), (dt, i)     # closed after exactly that many


@pytest.mark.parametrize("terrain, w0, cmd, pitch_deg", [
    ("concrete", (-3.2, 7.5), (-2.2, 7.2), -13.4),   # left wheel dragged through zero downhill, drive saturated
    ("asphalt", (0.0, 0.0), (5.0, -1.2), -16.0),     # a turn started from rest on a steep descent
])
def test_a_wheel_through_zero_speed_at_the_planners_step(terrain, w0, cmd, pitch_deg):
    """Where a wheel speed changes sign the friction turns over; one 20 ms step there lost
    2.7 % of the first edge's energy (8.42 J against 8.65 J at 1 kHz). Such a step is now
    redone in sub-steps: within 1 % of the controller rate's energy (or 0.01 J where the
    edge draws well under 1 J: the turn from rest down 16 degrees, where the band of
    eq. 22 holds the inner side, 0.607 J against 0.598 J), speeds within 0.01 rad/s."""
    from dynamics.convergence import _feasible
    m = Model.load("p3at", terrain)
    p = math.radians(pitch_deg)
    S0 = _feasible(m, m.state(*w0, pitch=p))
    out = {}
    for dt in (0.001, 0.02):
        n = int(round(1.0 / dt))
        end = K.rollout_batch(m.P, m.table, S0[None, :].copy(), np.array([cmd], float), n, p, dt)[0]
        out[dt] = end
    fine, coarse = out[0.001], out[0.02]
    assert coarse[K.S_E] - S0[K.S_E] == pytest.approx(fine[K.S_E] - S0[K.S_E], rel=0.01, abs=0.01)
    assert abs(coarse[K.S_WL] - fine[K.S_WL]) < 0.01 and abs(coarse[K.S_WR] - fine[K.S_WR]) < 0.01
    assert coarse[K.S_STALLED] == fine[K.S_STALLED] == 0.0


def test_grass_pivot_at_the_planners_step_turns_as_at_the_controller_rate():
    """The issue's pivot: +-4 rad/s on grass for 4 s from rest."""
    m = Model.load("p3at", "grass")
    fine = simulate(m, hold(-4.0, 4.0, 0.001), hold(4.0, 4.0, 0.001), dt=0.001)
    for dt in (0.01, 0.02):
        coarse = simulate(m, hold(-4.0, 4.0, dt), hold(4.0, 4.0, dt), dt=dt)
        assert abs(math.degrees(coarse.yaw[-1] - fine.yaw[-1])) < 1.0
        assert coarse.energy_J[-1] == pytest.approx(fine.energy_J[-1], rel=0.02)
        assert coarse.stalled == fine.stalled


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
    # eq. 27: within the current limit, unless the back-EMF alone exceeds the supply (a
    # vehicle braking down a slope faster than its no-load speed: 21 deg at 1 m/s reaches
    # 10.7 rad/s), where the voltage bound sets the current (drive.current_window)
    v = m.vehicle
    over = (v.torque_constant * np.abs(tr.wl) - v.v_max) / v.armature_resistance
    assert np.all(np.abs(tr.i_l) <= np.maximum(v.current_limit, over) + 1e-9)
    assert np.all(np.abs(tr.wl) < 1.5 * m.vehicle.no_load_speed + 10 * abs(pitch) + 1)


def test_implicit_step_reduces_to_eq25_and_drive_window_to_eqs26_27(p3at):
    from dynamics.body import mass_matrix, newton_step, wheel_accelerations
    from dynamics.drive import current_window, motor_torque
    m11, m12 = mass_matrix(p3at.mass, p3at.inertia, p3at.wheel_radius, p3at.width, 1.5)
    al, ar = wheel_accelerations(m11, m12, 3.0, -1.0, 0.5, 0.2, 0.4)
    # the residual of M (w - w0) - dt (tau - C - G) at w0, and its correction with J = 0
    rl, rr = -0.01 * (3.0 - 0.5 - 0.4), -0.01 * (-1.0 - 0.2 - 0.4)
    dl, dr = newton_step(m11, m12, 0.0, 0.0, 0.0, 0.0, rl, rr, 0.01)
    assert (dl, dr) == (pytest.approx(0.01 * al), pytest.approx(0.01 * ar))
    # a dissipative slope (each wheel's own friction) only damps the correction
    sl, sr = newton_step(m11, m12, 5.0, 0.0, 0.0, 5.0, rl, rr, 0.01)
    assert abs(sl) < abs(dl) and abs(sr) < abs(dr)
    k, ra, vmax = p3at.torque_constant, p3at.armature_resistance, p3at.v_max
    lo, hi = current_window(7.0, vmax, k, ra, p3at.current_limit)      # voltage-bound at 7 rad/s
    assert hi == pytest.approx(motor_torque(vmax, 7.0, k, ra) / k) and hi < p3at.current_limit
    assert k * 7.0 + ra * hi == pytest.approx(vmax)     # eq. 27: back-EMF plus armature drop at the limit
    lo, hi = current_window(5.0, vmax, k, 2.0, 100.0)                 # braking holds a larger back-EMF
    assert k * 5.0 + 2.0 * lo == pytest.approx(-vmax) and k * 5.0 < vmax + 2.0 * abs(lo)
    assert current_window(0.0, vmax, k, ra, p3at.current_limit) == (-p3at.current_limit, p3at.current_limit)
    lo, hi = current_window(10.0, vmax, k, ra, p3at.current_limit)     # braking window below over-speed
    assert (lo, hi) == (-p3at.current_limit, pytest.approx((vmax - k * 10.0) / ra))
    lo, hi = current_window(12.0, vmax, k, ra, p3at.current_limit)     # over-speed (> 10.53 rad/s): one current
    assert lo == hi == pytest.approx((vmax - k * 12.0) / ra)
    lo, hi = current_window(-12.0, vmax, k, ra, p3at.current_limit)
    assert lo == hi == pytest.approx((-vmax + k * 12.0) / ra)


@pytest.mark.parametrize("terrain", ["vinyl", "asphalt", "grass", "packed_dirt"])
def test_commands_from_rest_at_the_planners_step_match_the_controller_rate(terrain):
    """Every command of a grid over the planner's range (and the point turn wl = -0.61,
    wr = 4.56 rad/s that once made the implicit matrix singular on packed dirt), from
    rest for 1.5 s: at the planner's 20 ms step the end pose and the energy are those of
    the 1 kHz digital PID, the stall verdict the same, and the current does not jump
    between the limits step after step (the explicit PID's chatter at 20 ms)."""
    m = Model.load("p3at", terrain)
    v = m.vehicle
    w0 = v.no_load_speed
    cmds = [(-0.608, 4.56)] + [(a * w0, b * w0) for a in np.linspace(-0.5, 1, 5) for b in np.linspace(-0.5, 1, 5)]
    bad = []
    for cl, cr in cmds:
        ref = simulate(m, hold(cl, 1.5, 0.001), hold(cr, 1.5, 0.001), state=m.state(0.0, 0.0), dt=0.001)
        tr = simulate(m, hold(cl, 1.5, 0.02), hold(cr, 1.5, 0.02), state=m.state(0.0, 0.0), dt=0.02)
        pos = math.hypot(tr.x[-1] - ref.x[-1], tr.y[-1] - ref.y[-1])
        yaw = abs(math.degrees(tr.yaw[-1] - ref.yaw[-1]))
        de = abs(tr.energy_J[-1] - ref.energy_J[-1])
        jumps = np.count_nonzero(np.abs(np.diff(tr.i_l)) > v.current_limit)
        if tr.stalled != ref.stalled or pos > 0.05 or yaw > 2.0 or de > max(0.02 * ref.energy_J[-1], 0.05) or jumps:
            bad.append((cl, cr, pos, yaw, de, jumps))
    assert len(bad) <= 2, bad


def test_open_loop_held_current_against_eqs_25_to_27(vinyl):
    """The open-loop model (Fig. 3, no PID) driven straight by a held current command on
    flat vinyl, checked against the equations by hand. Rolling resistance per side:
    tau_roll = r mu_roll m g / 2. Half of it leaves the vehicle at rest (the wheels
    hold); twice it accelerates it at (k I - tau_roll) / (m11 + m12) in wheel speed
    (eq. 25, straight: no sliding friction), until the back-EMF closes the voltage window
    (eqs. 26, 27) at k w + R_a I_roll = V_max, where the current left equals the rolling
    resistance's."""
    from dynamics.body import mass_matrix
    v, ter = vinyl.vehicle, vinyl.terrain
    k, ra, r = v.torque_constant, v.armature_resistance, v.wheel_radius
    tau_roll = r * ter.mu_roll * v.mass * 9.81 / 2.0
    i_roll = tau_roll / k
    held = simulate(vinyl, hold(0.5 * i_roll, 2.0, vinyl.step_s), hold(0.5 * i_roll, 2.0, vinyl.step_s),
                    open_loop=True)
    from dynamics.resistance import OMEGA_EPS
    assert np.max(np.abs(held.wl)) <= 0.5 * OMEGA_EPS + 1e-9     # within the regularisation of sign(w)
    i_cmd = 2.0 * i_roll
    assert i_cmd < v.current_limit
    tr = simulate(vinyl, hold(i_cmd, 40.0, vinyl.step_s), hold(i_cmd, 40.0, vinyl.step_s), open_loop=True)
    m11, m12 = mass_matrix(v.mass, v.inertia, r, v.width, ter.alpha)
    a = r * (k * i_cmd - tau_roll) / (m11 + m12)
    early = (tr.t > 0.2) & (tr.t < 1.0)
    assert np.polyfit(tr.t[early], tr.v[early], 1)[0] == pytest.approx(a, rel=0.02)
    w_end = (v.v_max - ra * i_roll) / k
    assert tr.v[-1] == pytest.approx(r * w_end, rel=0.01)
    assert tr.i_l[-1] == pytest.approx(i_roll, rel=0.02)
    assert np.allclose(tr.yaw, 0.0, atol=1e-9)


@pytest.mark.parametrize("terrain", ["vinyl", "grass", "concrete"])
def test_the_solves_starting_guess_does_not_decide_the_step(terrain):
    """At the planner's step each implicit solve starts from the speeds the last step's
    end acceleration predicts (S_DWL, S_DWR) and ends after a small enough correction.
    The step's answer must not depend on that start: the same random edges with no
    prediction (the solves start at the step's speeds) and with a wrong one (+-10 rad/s^2
    every step) end at the same speeds (0.05 rad/s; a solve stops after a correction
    below 0.01 rad/s), energy (2 %, the benchmark's tolerance) and stall verdict, but
    for edges on a stall threshold (at most 2 of 40; measured: 0-1 stall verdicts,
    speeds within 0.03 rad/s, one energy 3 % off on concrete)."""
    from dynamics.convergence import random_edges
    m = Model.load("p3at", terrain)
    e = random_edges(m, 40, np.random.default_rng(5))
    rng = np.random.default_rng(6)
    O = np.zeros(K.NO)
    ends = {}
    for mode in ("predicted", "none", "wrong"):
        out = e.S0.copy()
        for b in range(len(out)):
            S = out[b]
            for _ in range(50):
                if mode == "none":
                    S[K.S_DWL] = S[K.S_DWR] = 0.0
                elif mode == "wrong":
                    S[K.S_DWL], S[K.S_DWR] = rng.uniform(-10.0, 10.0, 2)
                K.step(m.P, m.table, S, e.cmds[b, 0], e.cmds[b, 1], e.pitch[b], 0.02, False, O)
        ends[mode] = out
    ref = ends["predicted"]
    de = ref[:, K.S_E] - e.S0[:, K.S_E]
    for mode in ("none", "wrong"):
        x = ends[mode]
        off = ((np.abs(x[:, K.S_WL] - ref[:, K.S_WL]) > 0.05) | (np.abs(x[:, K.S_WR] - ref[:, K.S_WR]) > 0.05)
               | (np.abs(x[:, K.S_E] - ref[:, K.S_E]) > np.maximum(0.02 * np.abs(de), 0.05))
               | (x[:, K.S_STALLED] != ref[:, K.S_STALLED]))
        assert off.sum() <= 2, (mode, np.flatnonzero(off))


@pytest.mark.parametrize("terrain", ["asphalt", "vinyl"])
def test_down_the_steepest_braked_grade_the_drive_holds_its_command_and_beyond_runs_away(terrain):
    """dynamics.limits.steepest_braked_grade: 1 deg gentler, the drive brakes the vehicle
    to the commanded wheel speed; 2 deg steeper its continuous torque no longer holds it
    and the vehicle runs faster than commanded (the time heuristic's downhill bound
    rests on this)."""
    m = Model.load("p3at", terrain)
    w = 8.68
    limit = math.degrees(steepest_braked_grade(m.vehicle, m.terrain, w))
    assert -30.0 < limit < -10.0
    for deg, held in ((limit + 1.0, True), (limit - 2.0, False)):
        th = math.radians(deg)
        tr = simulate(m, hold(w, 5, 1e-3), hold(w, 5, 1e-3), state=m.state(w, w, th), pitch=th, dt=1e-3)
        v_end = tr.v[-1]
        if held:
            assert v_end == pytest.approx(w * m.vehicle.wheel_radius, rel=2e-3)
        else:
            assert v_end > 1.01 * w * m.vehicle.wheel_radius


def test_simulate_state_and_limits_name_a_bad_argument(vinyl):
    """NaN commands, states or pitches gave NaN trajectories with energy 0 and no stall;
    a pitch beside a profile was ignored, a zero profile step dropped the profile, a
    short state read past its end; a NaN speed or a grade of 10 rad gave numbers."""
    from dynamics import ParameterError
    from dynamics.limits import available_torque
    n = np.full(200, 5.0)
    for kw, says in [(dict(cmd_l=np.r_[n[:-1], np.nan]), "cmd_l: expected finite numbers"),
                     (dict(state=[1.0, 2.0, 3.0]), f"state: expected a model state of {K.NS} numbers"),
                     (dict(pitch=np.zeros(5)), r"pitch: expected one grade \[rad\] or one per command \(200\)"),
                     (dict(pitch=3.0), r"in degrees\? radians are expected"),
                     (dict(profile=np.full(10, 0.2), pitch=0.1), "pitch, profile: expected one of them"),
                     (dict(profile=np.full(10, 0.2), profile_step=0.0), "profile_step: expected a positive"),
                     (dict(record_dt=0.0), "record_dt: expected a positive recording interval")]:
        cl = kw.pop("cmd_l", n)
        with pytest.raises(ParameterError, match=says):
            simulate(vinyl, cl, n, **kw)
    with pytest.raises(ParameterError, match="wl: expected a finite number, found nan"):
        vinyl.state(float("nan"))
    for call, says in [(lambda: steepest_grade(vinyl.vehicle, vinyl.terrain, -1.0), r"speed: expected a number in \[0, inf\]"),
                       (lambda: top_speed(vinyl.vehicle, vinyl.terrain, 10.0), "grade: expected a number in"),
                       (lambda: available_torque(vinyl.vehicle, float("nan")), "omega: expected")]:
        with pytest.raises(ParameterError, match=says):
            call()
    assert simulate(vinyl, n, n, pitch=np.zeros(200)).x[-1] == pytest.approx(simulate(vinyl, n, n).x[-1])


@pytest.mark.parametrize("terrain, pitch_deg, wl, wr", [("vinyl", 4.0, 3.0, 5.0), ("grass", -6.0, 6.0, 4.5),
                                                        ("asphalt", 0.0, 4.0, 4.4)])
def test_a_steady_state_of_a_vehicle_with_scaled_radii_stays_steady(terrain, pitch_deg, wl, wr):
    """Model.state(steady=True) for a vehicle whose right tyres are 8 % smaller and left
    ones 3 % larger (the radius-scale extension), on a slope, turning: held at its own
    wheel speeds at the controller rate, nothing moves (speeds within 1e-3 rad/s,
    currents within 1e-3 A after 0.5 s). The steady form must scale each side's rim,
    rim speeds and gravity as the compiled step does (it ignored the scales until
    2026-12-01: currents off by up to 8 % of the side's torque)."""
    m = Model.load("p3at", terrain)
    m = m.with_(vehicle=m.vehicle.replace(radius_scale_left=1.03, radius_scale_right=0.92))
    p = math.radians(pitch_deg)
    S = m.state(wl, wr, pitch=p)
    tr = simulate(m, hold(wl, 0.5, 0.001), hold(wr, 0.5, 0.001), state=S.copy(), pitch=p, dt=0.001)
    assert not tr.stalled
    assert np.max(np.abs(tr.wl - wl)) < 1e-3 and np.max(np.abs(tr.wr - wr)) < 1e-3
    assert np.max(np.abs(tr.i_l - S[K.S_IL])) < 1e-3 and np.max(np.abs(tr.i_r - S[K.S_IR])) < 1e-3


@pytest.mark.parametrize("scale", [0.8, 1.15])
def test_a_weak_motor_draws_the_current_its_torque_needs_and_mirrors(scale):
    """One side's motor constant scaled (``torque_scale_right``, a weak motor: eq. 26's
    torque k i and back-EMF k w on that side): held straight at 4 rad/s on a 5 deg grade,
    the wheel loops hold the speeds, and that side draws 1/scale times the current of
    the other (the torques balance the same loads); its electrical power at the same
    torque and speed is i^2 R more by that current. Scaling the left side instead mirrors
    the currents exactly. The steady state of Model.state is the simulation's."""
    m = Model.load("p3at", "asphalt")
    p = math.radians(5.0)
    right = m.with_(vehicle=m.vehicle.replace(torque_scale_right=scale))
    left = m.with_(vehicle=m.vehicle.replace(torque_scale_left=scale))
    runs = []
    for mm in (right, left):
        S = mm.state(4.0, 4.0, pitch=p)
        tr = simulate(mm, hold(4.0, 1.0, 0.001), hold(4.0, 1.0, 0.001), state=S.copy(), pitch=p, dt=0.001)
        assert not tr.stalled and np.max(np.abs(tr.wl - 4.0)) < 1e-3 and np.max(np.abs(tr.wr - 4.0)) < 1e-3
        assert np.max(np.abs(tr.i_l - S[K.S_IL])) < 1e-3 and np.max(np.abs(tr.i_r - S[K.S_IR])) < 1e-3
        runs.append(tr)
    r, lft = runs
    assert r.i_r[-1] == pytest.approx(r.i_l[-1] / scale, rel=1e-6)
    assert r.tau_r[-1] == pytest.approx(r.tau_l[-1], rel=1e-6)
    assert lft.i_l[-1] == pytest.approx(r.i_r[-1], rel=1e-9) and lft.i_r[-1] == pytest.approx(r.i_l[-1], rel=1e-9)
