"""The compiled hot path: one closed-loop (or open-loop) step of both sides, and rollouts.

Everything here works on plain float64 arrays (numba, ``cache=True``, no jitclass):

* ``P`` (length ``NP``) holds the vehicle and terrain, packed by :func:`pack`;
* ``S`` (length ``NS``) is the state: wheel speeds, controller state (rate-limited
  references, integrals), delivered currents and friction states of the extensions,
  pose (x, y, z, yaw), time, energy, distance, stall timer;
* ``O`` (length ``NO``) receives the outputs of the last step: torques, currents,
  powers, speed and yaw rate.

One step of length dt (Fig. 3 closed loop, Fig. 6 kinematics):

1. the wheel-speed reference approaches the command at the rate limit ``ref_accel``;
2. the modified PID (Fig. 4) gives a current command, clipped to the current window of
   the drive (continuous limit and the voltage limit of eq. 27); the integral does not
   wind up while the output is saturated (conditional integration);
3. the resistance C (eqs. 17-22, fast form), gravity G (eq. 24), mass matrix M (eq. 5)
   give the wheel accelerations of eq. 25, integrated *implicitly*: backward Euler at
   the controller period, an L-stable two-stage SDIRK at coarser steps, each stage a
   Newton solve of M (w - w0) = dt (tau - C - G) started from the speeds that the last
   step's end acceleration predicts (kept in the state). The friction is stiff near
   straight motion at low speed (its slope grows like 1 / |w|); the implicit treatment
   keeps the step stable at the planner's coarse steps and exact in the limit dt -> 0;
4. the kinematic model (eq. 1) advances the pose: the speed v is along the slope, the
   map position advances by v cos(pitch) along the heading (midpoint heading).

A coarse step over which a wheel speed changes sign is redone in SUBSTEPS parts
(:func:`step`).

With dt = 1 / controller_rate the PID is exactly the paper's 1 kHz digital controller.
"""
from __future__ import annotations

import math

import numpy as np
from ._jit import jit, jit_inline

from .body import mass_matrix, newton_step, slope_gravity_torque
from .drive import current_window, electrical_power, pid_current
from .kinematics import alpha_model
from .params import G, Terrain, Vehicle
from .resistance import OMEGA_EPS, side_force, unit_friction_fast

INV_OMEGA_EPS = 1.0 / OMEGA_EPS

# ---- parameter vector P ----------------------------------------------------------
(P_M, P_I, P_R, P_B, P_ALPHA, P_MUROLL, P_MUSA, P_MUOP, P_PRESS, P_VMAX, P_K, P_RA,
 P_IMAX, P_KP, P_KI, P_KD, P_AREF, P_REGEN, P_SCL, P_SCR, P_VISC, P_LAG, P_SAG,
 P_SHEARLAG, P_M11, P_M12, P_TC, P_KSL, P_KSR, P_I0) = range(30)
NP = 30

# ---- state vector S --------------------------------------------------------------
(S_WL, S_WR, S_REFL, S_REFR, S_INTL, S_INTR, S_IL, S_IR, S_FL, S_FR, S_X, S_Y, S_Z,
 S_YAW, S_T, S_E, S_DIST, S_S, S_STALLT, S_STALLED,
 S_CWL, S_CWR, S_CFL, S_CFR, S_CLL, S_CLR, S_CRL, S_CRR, S_DWL, S_DWR,
 S_SWT, S_SWL, S_SWR, S_SWCL, S_SWCR) = range(35)
NS = 35
# S_SW*: the stall test's window (STALL_WINDOW): time into it [s], the wheel speeds at
# its start [rad/s], the command it is judged against [rad/s]
# S_C*: the unit friction and its slopes (fast form) at the speeds (S_CWL, S_CWR), kept
# from the last step: the next step starts its solve there and need not look them up.
# S_DW*: the wheel accelerations [rad/s^2] at the end of the last step (from its stages):
# the next step's solves start from the speeds they predict (0: from the speeds themselves)

# ---- step outputs O --------------------------------------------------------------
(O_TAUL, O_TAUR, O_IL, O_IR, O_PL, O_PR, O_PB, O_V, O_YAWRATE, O_SAT) = range(10)
NO = 10

# ---- recorded channels of a rollout ----------------------------------------------
CHANNELS = ("t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r",
            "i_l", "i_r", "power_W", "energy_J", "pitch", "ref_l", "ref_r", "s")
(R_T, R_X, R_Y, R_Z, R_YAW, R_V, R_YAWRATE, R_WL, R_WR, R_TAUL, R_TAUR, R_IL, R_IR,
 R_PB, R_E, R_PITCH, R_REFL, R_REFR, R_S) = range(19)
NR = 19

STALL_SPEED = 0.02   # m/s: progress below this along the commanded motion, drive saturated ...
STALL_ACCEL = 0.5    # m/s^2: ... closing in on the commanded rim speeds slower than this ...
STALL_TIME = 0.25    # s: ... for this long, the vehicle has stalled
STALL_WINDOW = 0.02  # s: the test runs on windows of this length whatever the step (a coarser step: each step)


def pack(vehicle: Vehicle, terrain: Terrain) -> np.ndarray:
    """The parameter vector P of a vehicle on a terrain."""
    v, t = vehicle, terrain
    P = np.zeros(NP)
    P[P_M], P[P_I], P[P_R], P[P_B] = v.mass, v.inertia, v.wheel_radius, v.width
    P[P_ALPHA], P[P_MUROLL], P[P_MUSA], P[P_MUOP] = t.alpha, t.mu_roll, t.mu_sa, t.mu_op
    P[P_PRESS] = v.mass * G / (2.0 * v.patch_width * (v.patch_outer - v.patch_inner))
    P[P_VMAX], P[P_K], P[P_RA], P[P_IMAX] = v.v_max, v.torque_constant, v.armature_resistance, v.current_limit
    P[P_KP], P[P_KI], P[P_KD] = v.kp, v.ki, v.kd
    P[P_AREF] = v.ref_wheel_accel
    P[P_REGEN] = 1.0 if v.regen else 0.0
    P[P_SCL], P[P_SCR], P[P_VISC] = v.radius_scale_left, v.radius_scale_right, v.viscous
    P[P_LAG], P[P_SAG], P[P_SHEARLAG] = v.lag, v.sag, v.shear_lag
    P[P_M11], P[P_M12] = mass_matrix(v.mass, v.inertia, v.wheel_radius, v.width, t.alpha)
    P[P_TC] = 1.0 / v.controller_rate
    P[P_KSL], P[P_KSR] = v.torque_scale_left, v.torque_scale_right
    P[P_I0] = v.no_load_current
    return P


@jit_inline
def _clip(x, lo, hi):
    return lo if x < lo else (hi if x > hi else x)


@jit_inline
def _resistance(P, S, wl, wr, cp, a_shear, fl, fr, dll, dlr, drl, drr, g_l, g_r):
    """Resistance torques C (eqs. 17-22, with rolling, the viscous extension and the
    motors' no-load current: :func:`dynamics.resistance.drive_friction`) [N m] of
    both sides at wheel speeds (wl, wr) [rad/s] on a slope of cosine cp with gravity
    torques (g_l, g_r) [N m] (eq. 24; they enter eq. 22's choice of coefficient), from the unit
    frictions (fl, fr) and their slopes there (:func:`unit_friction_fast`), and their
    Jacobian dC/dw [N m s/rad]. ``a_shear`` < 1 blends the friction with its lagged value
    in S (shear-lag extension). Returns (res_l, res_r, j_ll, j_lr, j_rl, j_rr, fl, fr),
    the last two the (lagged) unit frictions."""
    scl = P[P_SCL]
    scr = P[P_SCR]
    r = P[P_R]
    dll *= scl
    dlr *= scr
    drl *= scl
    drr *= scr
    if a_shear < 1.0:
        fl = S[S_FL] + a_shear * (fl - S[S_FL])
        fr = S[S_FR] + a_shear * (fr - S[S_FR])
        dll *= a_shear
        dlr *= a_shear
        drl *= a_shear
        drr *= a_shear
    press = P[P_PRESS] * cp
    roll = P[P_MUROLL] * P[P_M] * G * cp / 2.0
    # the regularised sign of each wheel's rotation and its slope [s/rad]: the rolling
    # resistance's and the motors' no-load current's (both Coulomb, OMEGA_EPS wide at rest)
    sg_l = _clip(wl * INV_OMEGA_EPS, -1.0, 1.0)
    sg_r = _clip(wr * INV_OMEGA_EPS, -1.0, 1.0)
    dsg_l = INV_OMEGA_EPS if abs(wl) < OMEGA_EPS else 0.0
    dsg_r = INV_OMEGA_EPS if abs(wr) < OMEGA_EPS else 0.0
    visc = P[P_VISC]
    rim_l = r * scl
    rim_r = r * scr
    # the motors' no-load current: a Coulomb torque k i0 against each side's rotation inside
    # the drive (not in eq. 22's choice: the ground sees what the wheel passes on; 0 without
    # it: the paper's model)
    t0_l = P[P_K] * P[P_KSL] * P[P_I0]
    t0_r = P[P_K] * P[P_KSR] * P[P_I0]
    F_l, dF_l, dR_l, dG_l = side_force(fl, roll * sg_l, wl, press, P[P_MUSA], P[P_MUOP], visc * wl + g_l, rim_l)
    F_r, dF_r, dR_r, dG_r = side_force(fr, roll * sg_r, wr, press, P[P_MUSA], P[P_MUOP], visc * wr + g_r, rim_r)
    res_l = rim_l * F_l + visc * wl + t0_l * sg_l
    res_r = rim_r * F_r + visc * wr + t0_r * sg_r
    # (in eq. 22's band the motor holds no torque beyond the drive's own friction: res = -g
    # + k i0 sign(w), its slope in w that of the last term alone)
    j_ll = rim_l * (dF_l * dll + dR_l * (roll * dsg_l) + dG_l * visc) + visc + t0_l * dsg_l
    j_lr = rim_l * dF_l * dlr
    j_rl = rim_r * dF_r * drl
    j_rr = rim_r * (dF_r * drr + dR_r * (roll * dsg_r) + dG_r * visc) + visc + t0_r * dsg_r
    return res_l, res_r, j_ll, j_lr, j_rl, j_rr, fl, fr


@jit_inline
def _extrapolated_friction(u, dl, dr):
    """The unit frictions ``u`` (6-tuple of :func:`unit_friction_fast`) carried along
    their slopes to wheel speeds changed by (dl, dr) [rad/s, radius-scaled]; slopes kept."""
    return (u[0] + u[2] * dl + u[3] * dr, u[1] + u[4] * dl + u[5] * dr, u[2], u[3], u[4], u[5])


@jit_inline
def _lagged(S, il, ir, a_lag):
    """The delivered currents [A] of the actuator-lag extension: the state's currents
    moved by the fraction a_lag towards the commanded (il, ir)."""
    return S[S_IL] + a_lag * (il - S[S_IL]), S[S_IR] + a_lag * (ir - S[S_IR])


@jit_inline
def _loop_current(P, k, ref, integral, ref_rate, w, vmax, dt):
    """The PID current (Fig. 4) of one side (its motor constant k [N m/A]) with its
    integral advanced implicitly to the end of a step of dt [s] at wheel speed w, clipped
    to the drive's window (eq. 27). Returns (current [A], d current / d w [A s/rad],
    saturated, new integral)."""
    ra = P[P_RA]
    e = ref - w
    z = integral + e * dt
    ic = pid_current(e, z, ref_rate, P[P_KP], P[P_KI], P[P_KD])
    lo, hi = current_window(w, vmax, k, ra, P[P_IMAX])
    i = _clip(ic, lo, hi)
    sat = i != ic
    if not sat:
        return i, -(P[P_KP] + P[P_KI] * dt), False, z
    if e * (ic - i) > 0.0:          # saturated while winding up: the integral holds
        z = integral
    di = -k / ra if abs(i) < P[P_IMAX] else 0.0      # on the voltage bound of eq. 27
    return i, di, True, z


@jit_inline
def _held_current(icmd, w, vmax, k, ra, imax):
    """A held current command [A] as the drive delivers it at wheel speed w: clipped to
    its window (eq. 27). Returns (current, d current / d w [A s/rad], saturated)."""
    lo, hi = current_window(w, vmax, k, ra, imax)
    i = _clip(icmd, lo, hi)
    if i == icmd:
        return i, 0.0, False
    return i, (-k / ra if abs(i) < imax else 0.0), True


NEWTON_ITERATIONS = 6    # most one implicit solve takes (typically 1-2; where it cycles between
                         # kinks of the friction or the current limit, the last iterate stands)
NEWTON_TOL = 1e-4        # rad/s: a solve has converged when its next correction is below
STEP_RATE = 0.5          # rad/s^2: ... or when a full Newton correction is below this times the
                         # step (0.01 rad/s at the planner's 20 ms; its error is of the order
                         # of its square: the speeds it reaches are taken, the currents
                         # evaluated there, the friction extrapolated)
REST_BAND = OMEGA_EPS    # rad/s: ... and neither wheel within this of rest, where the friction
                         # turns over (there the residual decides: a stop held by friction
                         # otherwise drifts from the controller-rate solution)
SDIRK_GAMMA = 1.0 - math.sqrt(0.5)   # Alexander's L-stable two-stage SDIRK, order 2


@jit_inline
def _solve(P, table, S, wl0, wr0, wl, wr, u, known, off_l, off_r, h, digital, icl, icr, refl, refr,
           zl_b, zr_b, rdl, rdr, vmax, cp, g_l, g_r):
    """One implicit solve for the wheel speeds w [rad/s] (Newton on two unknowns):

        M (w - w0) = off + h (k I(w) - C(w) - G)

    with resistance C (eqs. 17-22), gravity G (eq. 24), M of eq. 5 (eq. 25) and ``off``
    [N m s] what earlier stages contributed; starting from the guess (wl, wr). ``u``: the
    unit frictions and their slopes (6-tuple of :func:`unit_friction_fast`) at the guess
    when ``known``, else they are looked up first. The delivered current I: ``digital``,
    the held commands (icl, icr) clipped to
    the drive's window at w (its voltage bound falls with speed, eq. 27); otherwise the
    PID current (Fig. 4) at w with the integral advanced from (zl_b, zr_b) by h e(w),
    clipped, not winding up while saturated. The friction is stiff near straight motion
    and at rest (its slope grows like 1/|w|); a step that overshoots a kink is halved.
    The solve ends when the residual is within NEWTON_TOL, or (the continuous loop only)
    when a full Newton correction is below STEP_RATE times the step, leaves both
    currents on the same side of their limits and both wheels outside REST_BAND: from a
    good guess that is the first correction, and the friction at the speeds it reaches
    is extrapolated along its slopes (no lookup).
    Returns (wl, wr, il, ir, zl, zr, sat_l, sat_r, fl, fr, u): speeds, currents [A],
    integrals [rad], saturation, unit frictions (lagged) and ``u`` at the solution."""
    kl = P[P_K] * P[P_KSL]
    kr = P[P_K] * P[P_KSR]
    ra = P[P_RA]
    imax = P[P_IMAX]
    m11 = P[P_M11]
    m12 = P[P_M12]
    lag = P[P_LAG]
    a_lag = 1.0 - math.exp(-h / lag) if lag > 0.0 else 1.0
    a_shear = 1.0 - math.exp(-h / P[P_SHEARLAG]) if P[P_SHEARLAG] > 0.0 else 1.0
    tol = NEWTON_TOL * (m11 - abs(m12))     # on the residual [N m s]
    step_tol = h * (STEP_RATE / SDIRK_GAMMA)   # on a correction [rad/s] (h is a stage of the step)
    pl = wl
    pr = wr
    pnorm = 1e300
    lam = 1.0
    stl = 0.0
    str_ = 0.0
    zl = zl_b
    zr = zr_b
    for it in range(NEWTON_ITERATIONS):
        if it > 0 or not known:
            u = unit_friction_fast(table, P[P_SCL] * wl, P[P_SCR] * wr)
        if digital:
            il, dil, sat_l = _held_current(icl, wl, vmax, kl, ra, imax)
            ir, dir_, sat_r = _held_current(icr, wr, vmax, kr, ra, imax)
        else:
            il, dil, sat_l, zl = _loop_current(P, kl, refl, zl_b, rdl, wl, vmax, h)
            ir, dir_, sat_r, zr = _loop_current(P, kr, refr, zr_b, rdr, wr, vmax, h)
        if lag > 0.0:
            il, ir = _lagged(S, il, ir, a_lag)
            dil *= a_lag
            dir_ *= a_lag
        res_l, res_r, j_ll, j_lr, j_rl, j_rr, fl, fr = _resistance(P, S, wl, wr, cp, a_shear, u[0], u[1], u[2], u[3], u[4], u[5], g_l, g_r)
        if it == NEWTON_ITERATIONS - 1:
            break
        rl = m11 * (wl - wl0) + m12 * (wr - wr0) - off_l - h * (kl * il - res_l - g_l)
        rr = m12 * (wl - wl0) + m11 * (wr - wr0) - off_r - h * (kr * ir - res_r - g_r)
        norm = abs(rl) + abs(rr)
        if (it > 0 or not known) and norm < tol:
            break
        if norm > pnorm and lam > 0.01:
            # the Newton step overshot a kink of the friction: step back halfway
            lam *= 0.5
            wl = pl + lam * stl
            wr = pr + lam * str_
            continue
        pl = wl
        pr = wr
        pnorm = norm
        stl, str_ = newton_step(m11, m12, j_ll - kl * dil, j_lr, j_rl, j_rr - kr * dir_, rl, rr, h)
        lam = 1.0
        wl = pl + stl
        wr = pr + str_
        if (not digital and abs(stl) + abs(str_) < step_tol
                and min(abs(wl), abs(wr)) > REST_BAND):
            # converged unless a current crossed its limit: the currents at the new
            # speeds, the friction extrapolated there
            il2, dil, sat_l2, zl2 = _loop_current(P, kl, refl, zl_b, rdl, wl, vmax, h)
            ir2, dir_, sat_r2, zr2 = _loop_current(P, kr, refr, zr_b, rdr, wr, vmax, h)
            if sat_l2 != sat_l or sat_r2 != sat_r:
                continue
            il = il2
            ir = ir2
            zl = zl2
            zr = zr2
            u = _extrapolated_friction(u, P[P_SCL] * stl, P[P_SCR] * str_)
            if lag > 0.0:
                il, ir = _lagged(S, il, ir, a_lag)
            res_l, res_r, j_ll, j_lr, j_rl, j_rr, fl, fr = _resistance(P, S, wl, wr, cp, a_shear, u[0], u[1], u[2], u[3], u[4], u[5], g_l, g_r)
            break
    return wl, wr, il, ir, zl, zr, sat_l, sat_r, fl, fr, u


@jit_inline
def _cached_friction(P, table, S):
    """The unit frictions and slopes at the state's speeds: kept from the last step when
    it ended at these speeds, else looked up."""
    if S[S_CWL] == S[S_WL] and S[S_CWR] == S[S_WR]:
        return (S[S_CFL], S[S_CFR], S[S_CLL], S[S_CLR], S[S_CRL], S[S_CRR])
    return unit_friction_fast(table, P[P_SCL] * S[S_WL], P[P_SCR] * S[S_WR])


@jit_inline
def _battery_power(il, ir, wl, wr, kl, kr, ra, regen):
    """Battery power [W] of both sides (motor constants kl, kr; PARAMETERS.md: none
    regenerated by default)."""
    pb = electrical_power(il, wl, kl, ra) + electrical_power(ir, wr, kr, ra)
    return pb if (pb > 0.0 or regen) else 0.0


SUBSTEPS = 4   # a coarse step over which a wheel speed changes sign is redone as this many


# Flags the kernels pass as arguments, as globals: numba types a literal True or False
# in a call apart from a bool and compiles the callee once for each (the model's step,
# _step, compiled four times over: checked and not, literal and variable open_loop, a
# read-only table and not, 87 s of a fresh clone's first compile, 2026-12-06); a NumPy
# bool as a global is typed as a plain bool (a Python one as a literal).
CHECK = np.bool_(True)
NO_CHECK = np.bool_(False)
CLOSED_LOOP = np.bool_(False)


@jit_inline
def step(P, table, S, cmd_l, cmd_r, pitch, dt, open_loop, O):
    """Advance state S by dt [s] under commands (cmd_l, cmd_r) and pitch [rad]; outputs in
    O (:func:`step_slope`)."""
    step_slope(P, table, S, cmd_l, cmd_r, math.sin(pitch), math.cos(pitch), dt, open_loop, O)


@jit
def step_slope(P, table, S, cmd_l, cmd_r, sp, cp, dt, open_loop, O):
    """:func:`step` on a slope given by the sine and cosine of its pitch (sp, cp); outputs
    in O (:func:`_step`). A coarse step (the continuous loop, dt above the controller
    period) over which a wheel speed changes sign (or leaves or reaches rest) is redone
    as SUBSTEPS shorter steps: the friction turns over there (its slope grows like
    1/|w|, its sign flips), the one place where a second-order step of 20 ms is not
    accurate (a wheel dragged through zero downhill under a saturated drive: 2-3 % off
    in energy in one step; dynamics.convergence measures it). Allocates nothing."""
    if open_loop or dt <= P[P_TC] * (1.0 + 1e-9):
        _step(P, table, S, cmd_l, cmd_r, sp, cp, dt, open_loop, O, NO_CHECK)
    elif not _step(P, table, S, cmd_l, cmd_r, sp, cp, dt, open_loop, O, CHECK):
        h = dt / SUBSTEPS
        for _ in range(SUBSTEPS):
            _step(P, table, S, cmd_l, cmd_r, sp, cp, h, open_loop, O, NO_CHECK)


@jit_inline
def _reference(ref_l, ref_r, cmd_l, cmd_r, aref, dt):
    """Step 1 (Fig. 4's reference): the wheel-speed references (ref_l, ref_r) approach
    the commands [rad/s] at the rate limit ``aref`` [rad/s^2] (0: at once). Returns
    their changes over the step (dl, dr) [rad/s]. (Scalars in and out, as the other
    pieces of the step where they can: an array passed into an inlined function costs
    reference counting that the compiled step does not otherwise pay.)"""
    dl = cmd_l - ref_l
    dr = cmd_r - ref_r
    if aref > 0.0:
        dl = _clip(dl, -aref * dt, aref * dt)
        dr = _clip(dr, -aref * dt, aref * dt)
    return dl, dr


@jit_inline
def _digital_pid(el, er, int_l, int_r, rdl, rdr, wl0, wr0, vmax, kl, kr, ra, imax, kp, ki, kd, dt):
    """Step 2 at the controller period: the paper's digital PID (Fig. 4, gains kp, ki,
    kd) on the speed errors el, er [rad/s] of the measured wheel speeds wl0, wr0 gives
    the current commands (icl, icr) [A], held over the step; ``rdl``, ``rdr`` are the
    references' rates [rad/s^2]. The integrals int_l, int_r [rad] grow only while they
    would not drive a command further beyond the current window it violates (eq. 27's,
    voltage ``vmax`` [V], current ``imax`` [A]; conditional integration, as in
    :func:`_loop_current`). Returns (icl, icr, int_l, int_r)."""
    icl = pid_current(el, int_l, rdl, kp, ki, kd)
    icr = pid_current(er, int_r, rdr, kp, ki, kd)
    lo, hi = current_window(wl0, vmax, kl, ra, imax)
    if el * (icl - _clip(icl, lo, hi)) <= 0.0:
        int_l += el * dt
    lo, hi = current_window(wr0, vmax, kr, ra, imax)
    if er * (icr - _clip(icr, lo, hi)) <= 0.0:
        int_r += er * dt
    return icl, icr, int_l, int_r


@jit_inline
def _euler_rates(il, ir, wl0, wr0, wl, wr, kl, kr, ra, regen, scl, scr, r, b, alpha, inv_dt):
    """After step 3 at the controller period (backward Euler from wl0, wr0 to wl, wr
    [rad/s] under the held currents il, ir [A]): the battery power pb [W] (the held
    current against the wheel speed, linear over the step; eq. 26's motor constants kl, kr,
    resistance ra), eq. 1's speed v [m/s] and yaw rate [rad/s] at the end, their means
    over the step, and the wheel accelerations [rad/s^2]."""
    pb = _battery_power(il, ir, 0.5 * (wl0 + wl), 0.5 * (wr0 + wr), kl, kr, ra, regen)
    v0, yr0 = alpha_model(scl * wl0, scr * wr0, r, b, alpha)
    v, yaw_rate = alpha_model(scl * wl, scr * wr, r, b, alpha)
    return pb, v, yaw_rate, 0.5 * (v0 + v), 0.5 * (yr0 + yaw_rate), (wl - wl0) * inv_dt, (wr - wr0) * inv_dt


@jit_inline
def _stage1_start(wl0, wr0, dwl, dwr, h):
    """Where the SDIRK's stage 1 (length h [s]) starts its solve: the speeds the last
    step's end accelerations dwl, dwr [rad/s^2] predict, or wl0, wr0 [rad/s] where that
    goes through (or to) rest (the friction turns over there)."""
    gl = wl0 + h * dwl
    gr = wr0 + h * dwr
    if gl * wl0 <= 0.0 or gr * wr0 <= 0.0:
        return wl0, wr0
    return gl, gr


@jit_inline
def _stage2_setup(wl0, wr0, w1l, w1r, z1l, z1r, int_l, int_r, m11, m12, inv_dt):
    """Between the SDIRK's stages: stage 1 ended at w1l, w1r [rad/s] with integrals z1l,
    z1r. Returns stage 1's slopes in stage 2's equation (off_l, off_r: M (w1 - w0) (1 -
    gamma) / gamma with eq. 5's M = [[m11, m12], [m12, m11]]), stage 2's integrals' start
    (zbl, zbr), where stage 2's solve starts (gl, gr: stage 1's slope carried over the
    whole step, or stage 1's speeds where that goes through rest, then ``known``) and
    stage 1's slopes f1l, f1r [rad/s^2]."""
    sl = (1.0 - SDIRK_GAMMA) / SDIRK_GAMMA
    off_l = sl * (m11 * (w1l - wl0) + m12 * (w1r - wr0))
    off_r = sl * (m12 * (w1l - wl0) + m11 * (w1r - wr0))
    zbl = int_l + sl * (z1l - int_l)
    zbr = int_r + sl * (z1r - int_r)
    gl = wl0 + (w1l - wl0) * (1.0 / SDIRK_GAMMA)
    gr = wr0 + (w1r - wr0) * (1.0 / SDIRK_GAMMA)
    known = gl * wl0 <= 0.0 or gr * wr0 <= 0.0
    if known:
        gl = w1l
        gr = w1r
    f1l = (w1l - wl0) * inv_dt * (1.0 / SDIRK_GAMMA)
    f1r = (w1r - wr0) * inv_dt * (1.0 / SDIRK_GAMMA)
    return off_l, off_r, zbl, zbr, gl, gr, known, f1l, f1r


@jit_inline
def _sdirk_rates(i1l, i1r, w1l, w1r, il, ir, wl0, wr0, wl, wr, f1l, f1r, kl, kr, ra, regen, scl, scr, r, b, alpha,
                 inv_dt):
    """After the SDIRK's two stages (stage 1 at gamma dt: w1l, w1r [rad/s], i1l, i1r
    [A]; stage 2 at dt: wl, wr, il, ir): the battery power pb [W] by the stages'
    quadrature (weights 1 - gamma, gamma), eq. 1's speed v [m/s] and yaw rate [rad/s] at
    the end, their means over the step by the same quadrature, and the wheel
    accelerations at the end [rad/s^2] from stage 2's equation w = w0 + dt ((1 - gamma)
    f1 + gamma f2)."""
    gam = SDIRK_GAMMA
    pb = ((1.0 - gam) * _battery_power(i1l, i1r, w1l, w1r, kl, kr, ra, regen)
          + gam * _battery_power(il, ir, wl, wr, kl, kr, ra, regen))
    v1, yr1 = alpha_model(scl * w1l, scr * w1r, r, b, alpha)
    v, yaw_rate = alpha_model(scl * wl, scr * wr, r, b, alpha)
    return (pb, v, yaw_rate, (1.0 - gam) * v1 + gam * v, (1.0 - gam) * yr1 + gam * yaw_rate,
            ((wl - wl0) * inv_dt - (1.0 - gam) * f1l) * (1.0 / SDIRK_GAMMA),
            ((wr - wr0) * inv_dt - (1.0 - gam) * f1r) * (1.0 / SDIRK_GAMMA))


@jit_inline
def _advance_pose(x, y, z, yaw, vm, ym, sp, cp, dt):
    """Step 4, the kinematics (eq. 1 gave the mean speed vm [m/s] and yaw rate ym [rad/s]
    over the step): the speed is along the slope (sine sp, cosine cp of the pitch), the
    map position advances by vm cp along the midpoint heading. Returns the pose (x, y,
    z [m], yaw [rad]) at the step's end."""
    head = yaw + 0.5 * ym * dt
    return (x + vm * cp * math.cos(head) * dt, y + vm * cp * math.sin(head) * dt, z + vm * sp * dt,
            yaw + ym * dt)


@jit_inline
def _stall_test(win, ws_l, ws_r, wc_l, wc_r, stall_t, stalled, cmd_l, cmd_r, wl0, wr0, wl, wr, saturated, r, dt):
    """The stall test: the drive saturated, the commanded motion (driving or turning) not
    achieved and not being approached. The progress is the rim-speed vector along the
    commanded one (for a straight command the speed v, for a pivot the rim speed of the
    turn); the approach is how fast the rim speeds close in on the command (a vehicle
    that reverses, brakes or turns around closes in; one held by a hill does not). The
    test runs on windows of STALL_WINDOW whatever the step (a coarser step is its own
    window; one command per window): the approach is taken over the whole window, from
    the wheel speeds at its start, and the progress read at its end, so a 1 ms step and
    a 20 ms step see the same windows and a timer near STALL_TIME gives the same
    verdict. The time below the threshold is interpolated within the window.

    The window: ``win`` [s] into it, the wheel speeds at its start (ws_l, ws_r) and its
    commands (wc_l, wc_r) [rad/s]; the stall timer ``stall_t`` [s] and flag ``stalled``
    (1.0 once stalled); this step's commands, wheel speeds at its start and end
    [rad/s], whether the drive saturated, the wheel radius ``r`` [m]. Returns the seven
    first, advanced (the state's S_SWT ... S_STALLED)."""
    if win == 0.0 or cmd_l != wc_l or cmd_r != wc_r:
        # a new window: at the first step, after the last window, or where the
        # command changed within one (the part before the change is dropped, so a
        # window is never judged against a command it did not have throughout)
        win = 0.0
        ws_l = wl0
        ws_r = wr0
        wc_l = cmd_l
        wc_r = cmd_r
    win += dt
    if win + 0.5 * dt >= STALL_WINDOW:
        # the window is complete (at the step nearest its length where a step does
        # not divide it: 15 ms steps give 15 ms windows, 30 ms steps 30 ms ones):
        # test it as one step of its length, from the wheel speeds at its start (the
        # steps' approaches telescope: their sum is the distance to the command at
        # the window's start less that at its end)
        stalling = False
        cn = math.sqrt(0.5 * (cmd_l * cmd_l + cmd_r * cmd_r)) if saturated else 0.0
        if r * cn > 0.05:
            q = r / (2.0 * cn)
            p1 = q * (cmd_l * wl + cmd_r * wr)
            if p1 < STALL_SPEED:
                d0 = r * math.sqrt(0.5 * ((cmd_l - ws_l) ** 2 + (cmd_r - ws_r) ** 2))
                d1 = r * math.sqrt(0.5 * ((cmd_l - wl) ** 2 + (cmd_r - wr) ** 2))
                if d0 - d1 < STALL_ACCEL * win:
                    stalling = True
                    p0 = q * (cmd_l * ws_l + cmd_r * ws_r)
                    frac = 1.0 if p0 <= STALL_SPEED else (STALL_SPEED - p1) / (p0 - p1)
                    stall_t += frac * win
                    if stall_t >= STALL_TIME:
                        stalled = 1.0
        if not stalling:
            # the timer leaks at the rate it fills: dT/dt = +1 stalling, -1 not. A
            # stuck wheel's stick-slip at the regularised friction (a few steps of
            # apparent approach in every few ms at 1 kHz) does not reset it; real
            # progress does
            stall_t = max(0.0, stall_t - win)
        win = 0.0
    return win, ws_l, ws_r, wc_l, wc_r, stall_t, stalled


@jit
def _step(P, table, S, cmd_l, cmd_r, sp, cp, dt, open_loop, O, check):
    """One step of :func:`step_slope` (the pitch by its sine sp and cosine cp). With
    ``check``, a coarse step whose wheel speeds change sign is not taken: S is left as it
    was and the result is False (else True).

    Closed loop: the commands are desired wheel speeds [rad/s]; the reference approaches
    them at the rate limit ``ref_accel`` (:func:`_reference`). At the controller period
    (dt <= 1 / controller_rate) the step *is* the paper's digital PID (Fig. 4,
    :func:`_digital_pid`): the current command is computed from the measured speeds and
    held over the step (zero-order hold); the integral does not wind up while the output
    is saturated; the wheels advance by backward Euler (:func:`_solve`, then
    :func:`_euler_rates`). A coarser step cannot represent a 1 kHz controller sample by
    sample: it takes the loop's continuous-time limit and integrates the whole closed
    loop, PID, current window, friction and body, with an L-stable second-order implicit
    method (two-stage SDIRK: :func:`_stage1_start`, :func:`_solve`, :func:`_stage2_setup`,
    :func:`_solve`, :func:`_sdirk_rates`): stable at any step, free of the current chatter
    an explicit PID shows at coarse steps, and converging to the controller-rate
    solution (``dynamics.convergence`` measures how closely). Then the kinematics
    (:func:`_advance_pose`) and the stall test (:func:`_stall_test`).

    Open loop (``open_loop`` true): the commands are current commands [A] to the motor
    controllers (the paper's Fig. 16 drives the open-loop model with tau = K_tau V).
    """
    wl0 = S[S_WL]
    wr0 = S[S_WR]
    kl = P[P_K] * P[P_KSL]
    kr = P[P_K] * P[P_KSR]
    ra = P[P_RA]
    regen = P[P_REGEN] != 0.0
    vmax = P[P_VMAX] - P[P_SAG] * S[S_E]
    if vmax < 0.0:
        vmax = 0.0
    g = slope_gravity_torque(P[P_M], G, P[P_R], sp)
    g_l = g * P[P_SCL]
    g_r = g * P[P_SCR]
    # 1: the wheel-speed reference approaches the command at the rate limit
    dl = 0.0
    dr = 0.0
    ref_l0 = S[S_REFL]
    ref_r0 = S[S_REFR]
    if not open_loop:
        dl, dr = _reference(ref_l0, ref_r0, cmd_l, cmd_r, P[P_AREF], dt)
        S[S_REFL] += dl
        S[S_REFR] += dr
    inv_dt = 1.0 / dt
    rdl = dl * inv_dt
    rdr = dr * inv_dt
    scl = P[P_SCL]
    scr = P[P_SCR]
    if open_loop or dt <= P[P_TC] * (1.0 + 1e-9):
        u0 = _cached_friction(P, table, S)
        # 2: the digital PID samples the measured speeds; the command is held
        if open_loop:
            icl = cmd_l
            icr = cmd_r
        else:
            icl, icr, S[S_INTL], S[S_INTR] = _digital_pid(
                S[S_REFL] - wl0, S[S_REFR] - wr0, S[S_INTL], S[S_INTR], rdl, rdr, wl0, wr0, vmax, kl, kr, ra, P[P_IMAX],
                P[P_KP], P[P_KI], P[P_KD], dt)
        # 3: backward Euler on eq. 25 (resistance, gravity, mass matrix: _solve)
        wl, wr, il, ir, zl, zr, sat_l, sat_r, fl, fr, u = _solve(
            P, table, S, wl0, wr0, wl0, wr0, u0, True, 0.0, 0.0, dt, True, icl, icr, 0.0, 0.0,
            0.0, 0.0, 0.0, 0.0, vmax, cp, g_l, g_r)
        pb, v, yaw_rate, vm, ym, S[S_DWL], S[S_DWR] = _euler_rates(
            il, ir, wl0, wr0, wl, wr, kl, kr, ra, regen, scl, scr, P[P_R], P[P_B], P[P_ALPHA], inv_dt)
    else:
        # 2-3: the continuous loop, two-stage SDIRK: stage 1 ends at gamma dt, stage 2
        # at dt, each solved implicitly (_solve) for the speeds with the PID current at them
        gam = SDIRK_GAMMA
        h = gam * dt
        gl, gr = _stage1_start(wl0, wr0, S[S_DWL], S[S_DWR], h)
        # the friction there extrapolated from the step's start (its slopes)
        u0 = _extrapolated_friction(_cached_friction(P, table, S), scl * (gl - wl0), scr * (gr - wr0))
        w1l, w1r, i1l, i1r, z1l, z1r, s1l, s1r, fl, fr, u = _solve(
            P, table, S, wl0, wr0, gl, gr, u0, True, 0.0, 0.0, h, False, 0.0, 0.0,
            ref_l0 + gam * dl, ref_r0 + gam * dr, S[S_INTL], S[S_INTR], rdl, rdr, vmax, cp,
            g_l, g_r)
        off_l, off_r, zbl, zbr, gl, gr, known, f1l, f1r = _stage2_setup(
            wl0, wr0, w1l, w1r, z1l, z1r, S[S_INTL], S[S_INTR], P[P_M11], P[P_M12], inv_dt)
        wl, wr, il, ir, zl, zr, sat_l, sat_r, fl, fr, u = _solve(
            P, table, S, wl0, wr0, gl, gr, u, known, off_l, off_r, h, False, 0.0, 0.0, S[S_REFL],
            S[S_REFR], zbl, zbr, rdl, rdr, vmax, cp, g_l, g_r)
        if check and ((wl0 * wl <= 0.0 and wl != wl0) or (wr0 * wr <= 0.0 and wr != wr0)):
            S[S_REFL] = ref_l0          # nothing else was written: the caller splits the step
            S[S_REFR] = ref_r0
            return False
        S[S_INTL] = zl
        S[S_INTR] = zr
        sat_l = sat_l or s1l
        sat_r = sat_r or s1r
        pb, v, yaw_rate, vm, ym, S[S_DWL], S[S_DWR] = _sdirk_rates(
            i1l, i1r, w1l, w1r, il, ir, wl0, wr0, wl, wr, f1l, f1r, kl, kr, ra, regen, scl, scr, P[P_R], P[P_B],
            P[P_ALPHA], inv_dt)
    S[S_E] += pb * dt
    S[S_IL] = il
    S[S_IR] = ir
    S[S_FL] = fl
    S[S_FR] = fr
    S[S_WL] = wl
    S[S_WR] = wr
    S[S_CWL] = wl
    S[S_CWR] = wr
    S[S_CFL], S[S_CFR], S[S_CLL], S[S_CLR], S[S_CRL], S[S_CRR] = u
    # 4: kinematics (eq. 1) and pose
    S[S_X], S[S_Y], S[S_Z], S[S_YAW] = _advance_pose(S[S_X], S[S_Y], S[S_Z], S[S_YAW], vm, ym, sp, cp, dt)
    S[S_DIST] += abs(vm) * dt
    S[S_S] += vm * dt
    S[S_T] += dt
    if not open_loop:
        (S[S_SWT], S[S_SWL], S[S_SWR], S[S_SWCL], S[S_SWCR], S[S_STALLT], S[S_STALLED]) = _stall_test(
            S[S_SWT], S[S_SWL], S[S_SWR], S[S_SWCL], S[S_SWCR], S[S_STALLT], S[S_STALLED], cmd_l, cmd_r, wl0, wr0,
            wl, wr, sat_l or sat_r, P[P_R], dt)
    O[O_TAUL] = kl * il
    O[O_TAUR] = kr * ir
    O[O_IL] = il
    O[O_IR] = ir
    O[O_PL] = electrical_power(il, wl, kl, ra)
    O[O_PR] = electrical_power(ir, wr, kr, ra)
    O[O_PB] = pb
    O[O_V] = v
    O[O_YAWRATE] = yaw_rate
    O[O_SAT] = 1.0 if (sat_l or sat_r) else 0.0
    return True


@jit
def profile_pitch(profile, s0, ds, s):
    """Pitch [rad] at signed path distance s [m] of a profile sampled every ds from s0;
    flat (0) outside the profile."""
    if profile.shape[0] == 0:
        return 0.0
    i = int(math.floor((s - s0) / ds))
    if i < 0 or i >= profile.shape[0]:
        return 0.0
    return profile[i]


@jit
def state_outputs(P, S, O):
    """Fill the outputs O that follow from a state alone (speed, yaw rate, currents,
    torques), for the first recorded row of a rollout."""
    O[O_V], O[O_YAWRATE] = alpha_model(P[P_SCL] * S[S_WL], P[P_SCR] * S[S_WR], P[P_R], P[P_B], P[P_ALPHA])
    O[O_IL] = S[S_IL]
    O[O_IR] = S[S_IR]
    O[O_TAUL] = P[P_K] * P[P_KSL] * S[S_IL]
    O[O_TAUR] = P[P_K] * P[P_KSR] * S[S_IR]


@jit
def record(S, O, pitch, row):
    """Write the recorded channels (CHANNELS) of state S and outputs O into ``row``."""
    row[R_T] = S[S_T]
    row[R_X] = S[S_X]
    row[R_Y] = S[S_Y]
    row[R_Z] = S[S_Z]
    row[R_YAW] = S[S_YAW]
    row[R_V] = O[O_V]
    row[R_YAWRATE] = O[O_YAWRATE]
    row[R_WL] = S[S_WL]
    row[R_WR] = S[S_WR]
    row[R_TAUL] = O[O_TAUL]
    row[R_TAUR] = O[O_TAUR]
    row[R_IL] = O[O_IL]
    row[R_IR] = O[O_IR]
    row[R_PB] = O[O_PB]
    row[R_E] = S[S_E]
    row[R_PITCH] = pitch
    row[R_REFL] = S[S_REFL]
    row[R_REFR] = S[S_REFR]
    row[R_S] = S[S_S]


@jit
def rollout(P, table, S, cmd_l, cmd_r, pitch_t, profile, s0, ds, dt, open_loop, every, out):
    """Simulate len(cmd_l) steps from state S (modified in place), recording every
    ``every`` steps into ``out`` (NR, m), channel-major: column 0 is the initial state,
    each channel a contiguous row (one record of a 60 s replay at 1 kHz is 9 MB: copying
    its channels out of record-major rows took a fifth of a calibration's time).

    Pitch: from ``profile`` over the signed path distance (linear 3-D motion on Z = f(Y),
    Section III-B) when it is non-empty, else ``pitch_t[i]`` per step. Returns the number
    of rows written.
    """
    n = cmd_l.shape[0]
    O = np.zeros(NO)
    pitch = profile_pitch(profile, s0, ds, S[S_S]) if profile.shape[0] > 0 else pitch_t[0]
    state_outputs(P, S, O)
    record(S, O, pitch, out[:, 0])
    rows = 1
    for i in range(n):
        if profile.shape[0] > 0:
            pitch = profile_pitch(profile, s0, ds, S[S_S])
        else:
            pitch = pitch_t[i]
        step(P, table, S, cmd_l[i], cmd_r[i], pitch, dt, open_loop, O)
        if (i + 1) % every == 0 and rows < out.shape[1]:
            record(S, O, pitch, out[:, rows])
            rows += 1
    return rows


@jit
def rollout_batch(P, table, S0, cmds, n_steps, pitch, dt):
    """Final states of many closed-loop rollouts with constant commands: S0 is (n, NS),
    cmds is (n, 2) desired wheel speeds [rad/s]; constant pitch [rad]."""
    out = S0.copy()
    O = np.zeros(NO)
    for b in range(S0.shape[0]):
        S = out[b]
        for _ in range(n_steps):
            step(P, table, S, cmds[b, 0], cmds[b, 1], pitch, dt, CLOSED_LOOP, O)
    return out
