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
   give the wheel accelerations of eq. 25, integrated *linearly implicitly*:
   (M + dt dC/dw) dw = dt (tau - C - G). The friction is stiff near straight motion at
   low speed (its slope grows like 1 / |w|); the implicit treatment keeps the step
   stable at the planner's coarse steps and exact in the limit dt -> 0;
4. the kinematic model (eq. 1) advances the pose: the speed v is along the slope, the
   map position advances by v cos(pitch) along the heading (midpoint heading).

With dt = 1 / controller_rate the PID is exactly the paper's 1 kHz digital controller.
"""
from __future__ import annotations

import math

import numpy as np
from ._jit import jit

from .body import gravity_torque, implicit_wheel_step, mass_matrix
from .drive import current_window, electrical_power, pid_current
from .kinematics import alpha_model
from .params import G, Terrain, Vehicle
from .resistance import OMEGA_EPS, unit_friction_fast

# ---- parameter vector P ----------------------------------------------------------
(P_M, P_I, P_R, P_B, P_ALPHA, P_MUROLL, P_MUSA, P_MUOP, P_PRESS, P_VMAX, P_K, P_RA,
 P_IMAX, P_KP, P_KI, P_KD, P_AREF, P_REGEN, P_SCL, P_SCR, P_VISC, P_LAG, P_SAG,
 P_SHEARLAG, P_M11, P_M12) = range(26)
NP = 26

# ---- state vector S --------------------------------------------------------------
(S_WL, S_WR, S_REFL, S_REFR, S_INTL, S_INTR, S_IL, S_IR, S_FL, S_FR, S_X, S_Y, S_Z,
 S_YAW, S_T, S_E, S_DIST, S_S, S_STALLT, S_STALLED) = range(20)
NS = 20

# ---- step outputs O --------------------------------------------------------------
(O_TAUL, O_TAUR, O_IL, O_IR, O_PL, O_PR, O_PB, O_V, O_YAWRATE, O_SAT) = range(10)
NO = 10

# ---- recorded channels of a rollout ----------------------------------------------
CHANNELS = ("t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r",
            "i_l", "i_r", "power_W", "energy_J", "pitch", "ref_l", "ref_r", "s")
(R_T, R_X, R_Y, R_Z, R_YAW, R_V, R_YAWRATE, R_WL, R_WR, R_TAUL, R_TAUR, R_IL, R_IR,
 R_PB, R_E, R_PITCH, R_REFL, R_REFR, R_S) = range(19)
NR = 19

STALL_SPEED = 0.02   # m/s: below this in the commanded direction, with a saturated drive ...
STALL_TIME = 0.25    # s: ... for this long, the vehicle has stalled


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
    return P


@jit
def _clip(x, lo, hi):
    return lo if x < lo else (hi if x > hi else x)


@jit
def step(P, table, S, cmd_l, cmd_r, pitch, dt, open_loop, O):
    """Advance state S by dt [s] under commands (cmd_l, cmd_r) and pitch [rad]; outputs in O.

    Closed loop: the commands are desired wheel speeds [rad/s]. Open loop
    (``open_loop`` true): the commands are current commands [A] to the motor controllers
    (the paper's Fig. 16 drives the open-loop model with tau = K_tau V).
    """
    wl = S[S_WL]
    wr = S[S_WR]
    k = P[P_K]
    ra = P[P_RA]
    vmax = P[P_VMAX] - P[P_SAG] * S[S_E]
    if vmax < 0.0:
        vmax = 0.0
    # 1-2: reference, PID, saturation, anti-windup
    if open_loop:
        icl = cmd_l
        icr = cmd_r
        el = 0.0
        er = 0.0
    else:
        aref = P[P_AREF]
        dl = cmd_l - S[S_REFL]
        dr = cmd_r - S[S_REFR]
        if aref > 0.0:
            dl = _clip(dl, -aref * dt, aref * dt)
            dr = _clip(dr, -aref * dt, aref * dt)
        S[S_REFL] += dl
        S[S_REFR] += dr
        el = S[S_REFL] - wl
        er = S[S_REFR] - wr
        icl = pid_current(el, S[S_INTL], dl / dt, P[P_KP], P[P_KI], P[P_KD])
        icr = pid_current(er, S[S_INTR], dr / dt, P[P_KP], P[P_KI], P[P_KD])
    lo_l, hi_l = current_window(wl, vmax, k, ra, P[P_IMAX])
    lo_r, hi_r = current_window(wr, vmax, k, ra, P[P_IMAX])
    il = _clip(icl, lo_l, hi_l)
    ir = _clip(icr, lo_r, hi_r)
    sat_l = il != icl
    sat_r = ir != icr
    if not open_loop:
        if not (sat_l and el * (icl - il) > 0.0):
            S[S_INTL] += el * dt
        if not (sat_r and er * (icr - ir) > 0.0):
            S[S_INTR] += er * dt
    # voltage-bound currents fall with speed: their slope enters the implicit step
    dvl = k * k / ra if (sat_l and abs(il) < P[P_IMAX]) else 0.0
    dvr = k * k / ra if (sat_r and abs(ir) < P[P_IMAX]) else 0.0
    lag = P[P_LAG]
    if lag > 0.0:
        a = 1.0 - math.exp(-dt / lag)
        S[S_IL] += a * (il - S[S_IL])
        S[S_IR] += a * (ir - S[S_IR])
        il = S[S_IL]
        ir = S[S_IR]
        dvl = 0.0
        dvr = 0.0
    else:
        S[S_IL] = il
        S[S_IR] = ir
    tau_l = k * il
    tau_r = k * ir
    # 3: resistance (fast form of eqs. 17-22), gravity (eq. 24), implicit eq. 25
    scl = P[P_SCL]
    scr = P[P_SCR]
    r = P[P_R]
    cp = math.cos(pitch)
    sp = math.sin(pitch)
    fl, fr, dll, dlr, drl, drr = unit_friction_fast(table, scl * wl, scr * wr)
    tl = P[P_SHEARLAG]
    if tl > 0.0:
        a = 1.0 - math.exp(-dt / tl)
        S[S_FL] += a * (fl - S[S_FL])
        S[S_FR] += a * (fr - S[S_FR])
        fl = S[S_FL]
        fr = S[S_FR]
        dll *= a
        dlr *= a
        drl *= a
        drr *= a
    else:
        S[S_FL] = fl
        S[S_FR] = fr
    press = P[P_PRESS] * cp
    mu_l = P[P_MUSA] if il * wl > 0.0 else P[P_MUOP]
    mu_r = P[P_MUSA] if ir * wr > 0.0 else P[P_MUOP]
    roll = P[P_MUROLL] * P[P_M] * G * cp / 2.0
    droll_l = roll / OMEGA_EPS if abs(wl) < OMEGA_EPS else 0.0
    droll_r = roll / OMEGA_EPS if abs(wr) < OMEGA_EPS else 0.0
    visc = P[P_VISC]
    res_l = r * scl * (press * mu_l * fl + roll * _clip(wl / OMEGA_EPS, -1.0, 1.0)) + visc * wl
    res_r = r * scr * (press * mu_r * fr + roll * _clip(wr / OMEGA_EPS, -1.0, 1.0)) + visc * wr
    grav = gravity_torque(P[P_M], G, r, pitch)
    g_l = grav * scl
    g_r = grav * scr
    j_ll = r * scl * (press * mu_l * dll * scl + droll_l) + visc + dvl
    j_lr = r * scl * press * mu_l * dlr * scr
    j_rl = r * scr * press * mu_r * drl * scl
    j_rr = r * scr * (press * mu_r * drr * scr + droll_r) + visc + dvr
    dwl, dwr = implicit_wheel_step(P[P_M11], P[P_M12], j_ll, j_lr, j_rl, j_rr,
                                   tau_l, tau_r, res_l, res_r, g_l, g_r, dt)
    wl = wl + dwl
    wr = wr + dwr
    S[S_WL] = wl
    S[S_WR] = wr
    # 4: kinematics (eq. 1) and pose
    v, yaw_rate = alpha_model(scl * wl, scr * wr, r, P[P_B], P[P_ALPHA])
    # alpha_model takes one radius: scaled speeds give the per-side rim speeds
    head = S[S_YAW] + 0.5 * yaw_rate * dt
    S[S_X] += v * cp * math.cos(head) * dt
    S[S_Y] += v * cp * math.sin(head) * dt
    S[S_Z] += v * sp * dt
    S[S_YAW] += yaw_rate * dt
    S[S_DIST] += abs(v) * dt
    S[S_S] += v * dt
    S[S_T] += dt
    # energy (PARAMETERS.md: battery power, no regeneration by default)
    p_l = electrical_power(il, wl, k, ra)
    p_r = electrical_power(ir, wr, k, ra)
    pb = p_l + p_r
    if pb < 0.0 and P[P_REGEN] == 0.0:
        pb = 0.0
    S[S_E] += pb * dt
    # stall: commanded forward (or backward) motion, none achieved, drive saturated
    if not open_loop:
        vd = r * (cmd_l + cmd_r) / 2.0
        if abs(vd) > 0.05 and v * np.sign(vd) < STALL_SPEED and (sat_l or sat_r):
            S[S_STALLT] += dt
            if S[S_STALLT] >= STALL_TIME:
                S[S_STALLED] = 1.0
        else:
            S[S_STALLT] = 0.0
    O[O_TAUL] = tau_l
    O[O_TAUR] = tau_r
    O[O_IL] = il
    O[O_IR] = ir
    O[O_PL] = p_l
    O[O_PR] = p_r
    O[O_PB] = pb
    O[O_V] = v
    O[O_YAWRATE] = yaw_rate
    O[O_SAT] = 1.0 if (sat_l or sat_r) else 0.0


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
    O[O_TAUL] = P[P_K] * S[S_IL]
    O[O_TAUR] = P[P_K] * S[S_IR]


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
    ``every`` steps into ``out`` (row 0 is the initial state).

    Pitch: from ``profile`` over the signed path distance (linear 3-D motion on Z = f(Y),
    Section III-B) when it is non-empty, else ``pitch_t[i]`` per step. Returns the number
    of rows written.
    """
    n = cmd_l.shape[0]
    O = np.zeros(NO)
    pitch = profile_pitch(profile, s0, ds, S[S_S]) if profile.shape[0] > 0 else pitch_t[0]
    state_outputs(P, S, O)
    record(S, O, pitch, out[0])
    rows = 1
    for i in range(n):
        if profile.shape[0] > 0:
            pitch = profile_pitch(profile, s0, ds, S[S_S])
        else:
            pitch = pitch_t[i]
        step(P, table, S, cmd_l[i], cmd_r[i], pitch, dt, open_loop, O)
        if (i + 1) % every == 0 and rows < out.shape[0]:
            record(S, O, pitch, out[rows])
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
            step(P, table, S, cmds[b, 0], cmds[b, 1], pitch, dt, False, O)
    return out
