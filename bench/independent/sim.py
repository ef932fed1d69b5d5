#!/usr/bin/env python3
"""Independent closed-loop simulator of a skid-steered wheeled vehicle.

Model: Yu, Chuy, Collins, Hollis, "Analysis and experimental verification for dynamic
modeling of a skid-steered wheeled vehicle", IEEE Trans. Robotics 26(2), 2010.
Written from the paper's text and the project's table of default parameters only (by a
helper that did not read the project's model code, dynamics/): a second implementation
against which `sbmpc diagnose` is checked (bench/bench_independent.py).

  kinematics (eq. 1)   v = (r_l wl + r_r wr)/2,  yaw rate = (r_r wr - r_l wl)/(alpha B)
  dynamics (eq. 4/25)  M qdd + C(q, qd) + G = tau,  M from eq. 5 (r_i r_j (m/4 +- I/(alpha B^2)))
  resistance           tau_Res = r (F_f + f_r)  (eqs. 18, 21, 22)
  friction             shear stress p mu (1 - exp(-j/K)) (eq. 7), opposite to the sliding
                       velocity (eqs. 9, 10), shear displacement j of a tread particle since
                       it entered its patch (eqs. 8, 12, 13, 15, 16), integrated over the 4
                       contact patches (eqs. 17, 20) by Gauss-Legendre quadrature; the same
                       integral gives the lateral force and the turning-resistance moment
                       (reported only: in the paper's wheel-space model they are absorbed by
                       the kinematic constraint, eq. 1).
  gravity (eq. 24)     G_i = m g r_i sin(beta) / 2: a constant grade beta along the body axis
                       or, with grade_dir_deg, a plane rising grade_deg towards the heading
                       grade_dir_deg: beta = atan(tan(grade) cos(psi - dir)) at heading psi
  motor (eq. 26, 27)   current-controlled; |I| <= I_max and |R_a I + k w| <= V_max (torque-speed
                       line); tau = k I
  PID (Fig. 4)         discrete at 1 kHz, derivative on the (rate-limited) reference,
                       conditional-integration anti-windup
  energy               P = sum_sides (R_a I^2 + k w I), clipped at >= 0 (no regeneration)

Continuous part integrated with classical RK4 at the controller's 1 ms step, the
controller's current command held over each step (zero-order hold).

Usage:
  python sim.py                 # regenerate runs/*.csv and runs/manifest.json
  python sim.py --sanity        # physics sanity checks
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np
import numba as nb

G0 = 9.81
HERE = os.path.dirname(os.path.abspath(__file__))

# ---------------------------------------------------------------- parameters
P3AT = dict(m=31.0, I=0.67, r=0.11, B=0.40, L=0.31, C=0.24, b=0.05,
            Vmax=12.0, k=1.3825, Ra=0.706, Imax=3.62,
            Kp=2.0, Ki=20.0, Kd=0.09, a_ref=1.0)
TERRAINS = {
    'vinyl': dict(alpha=1.5, mu_roll=0.0371, mu_sa=0.4437, mu_op=0.3093, K=0.00054),
}

# effect parameters (defaults = the paper's model)
EFFECT_DEFAULTS = dict(scale_left=1.0, scale_right=1.0, sag_V_per_kJ=0.0, tau_s=0.0,
                       c_Nms=0.0, grade_deg=0.0, mu_scale=1.0, delay_s=0.0, grade_dir_deg=math.nan)

# numerical regularisations (documented choices)
T_CAP = 1.0      # s: longest time a tread particle is counted in contact (wheel at rest)
W_EPS = 0.02     # rad/s: rolling resistance sign(w) -> clip(w / W_EPS, -1, 1)
V_EPS = 1e-4     # m/s: sliding direction v/|v| -> v / sqrt(|v|^2 + V_EPS^2)

NP = 28
(iM, iI, iR, iB, iL, iC, iBW, iVMAX, iK, iRA, iIMAX, iKP, iKI, iKD, iAREF,
 iALPHA, iMUROLL, iMUSA, iMUOP, iKS,
 iSCL, iSCR, iSAG, iTAU, iVISC, iBETA, iMUSC, iGDIR) = range(NP)


def pack(vehicle, terrain, eff):
    P = np.zeros(NP)
    v, t = vehicle, terrain
    P[iM], P[iI], P[iR], P[iB], P[iL], P[iC], P[iBW] = v['m'], v['I'], v['r'], v['B'], v['L'], v['C'], v['b']
    P[iVMAX], P[iK], P[iRA], P[iIMAX] = v['Vmax'], v['k'], v['Ra'], v['Imax']
    P[iKP], P[iKI], P[iKD], P[iAREF] = v['Kp'], v['Ki'], v['Kd'], v['a_ref']
    P[iALPHA], P[iMUROLL], P[iMUSA], P[iMUOP], P[iKS] = t['alpha'], t['mu_roll'], t['mu_sa'], t['mu_op'], t['K']
    P[iSCL], P[iSCR] = eff['scale_left'], eff['scale_right']
    P[iSAG], P[iTAU], P[iVISC] = eff['sag_V_per_kJ'], eff['tau_s'], eff['c_Nms']
    P[iBETA] = math.radians(eff['grade_deg'])
    P[iMUSC] = eff['mu_scale']
    P[iGDIR] = math.radians(eff['grade_dir_deg'])      # NaN: the grade is along the body axis
    return P


# ---------------------------------------------------------------- friction
@nb.njit(cache=True, fastmath=False)
def side_forces(w, rs, xc, v, phid, L, C, bw, K, gy, wy, gx, wx):
    """Ground forces on one side's two contact patches, per unit p*mu.

    Body frame: x lateral (to the right), y forward, origin at the CG; a positive yaw rate
    is counter-clockwise (left turn). xc: lateral position of the side (-B/2 left, +B/2 right).
    Returns (Fy, Fx, Mz): longitudinal force on the tyres (+ forward = resists forward
    spin), lateral force, and moment about the CG (+ CCW).
    """
    rw = rs * w
    Fy = 0.0
    Fx = 0.0
    Mz = 0.0
    half = 0.25 * (L - C)          # half length of one patch
    for patch in range(2):
        if patch == 0:             # front patch, y in [C/2, L/2]
            yc = 0.25 * (L + C)
            ye = 0.5 * L if rw >= 0.0 else 0.5 * C
        else:                      # rear patch, y in [-L/2, -C/2]
            yc = -0.25 * (L + C)
            ye = -0.5 * C if rw >= 0.0 else -0.5 * L
        for iy in range(gy.shape[0]):
            y = yc + half * gy[iy]
            d = ye - y             # the particle entered at ye and moves at -rw in the body
            if abs(rw) * T_CAP > abs(d):
                t = d / rw         # eq. 8 (positive)
            else:
                t = T_CAP          # (nearly) stopped wheel: contact since at least T_CAP
            y0 = y + rw * t        # where the particle was t ago (= ye unless capped)
            th = phid * t          # body rotation while in contact
            cth = math.cos(th)
            sth = math.sin(th)
            if abs(th) < 1e-5:
                c1 = 0.5 * th
                c2 = 1.0 - th * th / 6.0
            else:
                c1 = (1.0 - cth) / th
                c2 = sth / th
            for ix in range(gx.shape[0]):
                x = xc + 0.5 * bw * gx[ix]
                # displacement since entry, current body axes (eqs. 12-13, 15-16)
                jx = v * t * c1 + x * (1.0 - cth) - y0 * sth
                jy = v * t * c2 + y + x * sth - y0 * cth
                j = math.sqrt(jx * jx + jy * jy)
                g = 1.0 - math.exp(-j / K)                      # eq. 7
                vsx = -phid * y                                  # eq. 9
                vsy = v + phid * x - rw
                inv = 1.0 / math.sqrt(vsx * vsx + vsy * vsy + V_EPS * V_EPS)
                wgt = wy[iy] * wx[ix] * half * 0.5 * bw
                fx = -g * vsx * inv * wgt                        # opposite to sliding (eq. 10)
                fy = -g * vsy * inv * wgt
                Fx += fx
                Fy += fy
                Mz += x * fy - y * fx
    return Fy, Fx, Mz


@nb.njit(cache=True)
def motor_current(Icmd, w, Veff, P):
    """Current the drive delivers: controller limit, then the voltage limit (eq. 26/27)."""
    Imax = P[iIMAX]
    I = min(max(Icmd, -Imax), Imax)
    hi = (Veff - P[iK] * w) / P[iRA]
    lo = (-Veff - P[iK] * w) / P[iRA]
    return min(max(I, lo), hi)


@nb.njit(cache=True)
def deriv(s, Icl, Icr, P, gy, wy, gx, wx, ds):
    wl = s[0]
    wr = s[1]
    psi = s[4]
    E = s[5]
    m = P[iM]
    r = P[iR]
    B = P[iB]
    alpha = P[iALPHA]
    beta = P[iBETA]
    if P[iGDIR] == P[iGDIR]:                      # a plane fixed in the world: the grade felt
        beta = math.atan(math.tan(beta) * math.cos(psi - P[iGDIR]))   # along the heading
    k = P[iK]
    Ra = P[iRA]
    rl = r * P[iSCL]
    rr = r * P[iSCR]
    v = 0.5 * (rl * wl + rr * wr)                 # eq. 1
    phid = (rr * wr - rl * wl) / (alpha * B)
    Veff = max(P[iVMAX] - P[iSAG] * E / 1000.0, 0.0)
    Il = motor_current(Icl, wl, Veff, P)
    Ir = motor_current(Icr, wr, Veff, P)
    N = m * G0 * math.cos(beta)
    p = N / (2.0 * P[iBW] * (P[iL] - P[iC]))      # normal pressure per patch
    Fyl, Fxl, Mzl = side_forces(wl, rl, -0.5 * B, v, phid, P[iL], P[iC], P[iBW], P[iKS], gy, wy, gx, wx)
    Fyr, Fxr, Mzr = side_forces(wr, rr, 0.5 * B, v, phid, P[iL], P[iC], P[iBW], P[iKS], gy, wy, gx, wx)
    mul = P[iMUSA] if Il * wl > 0.0 else P[iMUOP]
    mur = P[iMUSA] if Ir * wr > 0.0 else P[iMUOP]
    Fl_ss = p * mul * P[iMUSC] * Fyl              # eqs. 20, 17
    Fr_ss = p * mur * P[iMUSC] * Fyr
    tau = P[iTAU]
    if tau > 0.0:
        Fl = s[6]
        Fr = s[7]
        ds[6] = (Fl_ss - Fl) / tau
        ds[7] = (Fr_ss - Fr) / tau
    else:
        Fl = Fl_ss
        Fr = Fr_ss
        ds[6] = 0.0
        ds[7] = 0.0
    froll = P[iMUROLL] * 0.5 * N
    resl = rl * (Fl + froll * min(max(wl / W_EPS, -1.0), 1.0))   # eq. 21
    resr = rr * (Fr + froll * min(max(wr / W_EPS, -1.0), 1.0))   # eq. 18
    gl = m * G0 * math.sin(beta) * rl * 0.5                       # eq. 24
    gr = m * G0 * math.sin(beta) * rr * 0.5
    hl = k * Il - resl - gl - P[iVISC] * wl
    hr = k * Ir - resr - gr - P[iVISC] * wr
    a = 0.25 * m + P[iI] / (alpha * B * B)                          # eq. 5
    b = 0.25 * m - P[iI] / (alpha * B * B)
    M11 = rl * rl * a
    M12 = rl * rr * b
    M22 = rr * rr * a
    det = M11 * M22 - M12 * M12
    ds[0] = (M22 * hl - M12 * hr) / det
    ds[1] = (M11 * hr - M12 * hl) / det
    vg = v * math.cos(beta)
    ds[2] = vg * math.cos(psi)
    ds[3] = vg * math.sin(psi)
    ds[4] = phid
    ds[5] = max(Ra * Il * Il + k * wl * Il + Ra * Ir * Ir + k * wr * Ir, 0.0)
    return Il, Ir


@nb.njit(cache=True)
def run_core(cmdl, cmdr, P, delay_steps, dt, log_every, gy, wy, gx, wx):
    """Closed loop: discrete PID at 1/dt, RK4 body dynamics. Logs every log_every steps:
    t, wl, wr, Il, Ir, x, y, yaw, E, refl, refr."""
    nsteps = cmdl.shape[0] - 1
    nlog = nsteps // log_every + 1
    out = np.zeros((nlog, 11))
    s = np.zeros(8)
    k1 = np.zeros(8)
    k2 = np.zeros(8)
    k3 = np.zeros(8)
    k4 = np.zeros(8)
    tmp = np.zeros(8)
    refl = 0.0
    refr = 0.0
    intl = 0.0
    intr = 0.0
    dmax = P[iAREF] / P[iR] * dt        # reference rate limit (nominal radius)
    Kp = P[iKP]
    Ki = P[iKI]
    Kd = P[iKD]
    Imax = P[iIMAX]
    for kk in range(nsteps + 1):
        # ---- controller tick
        kc = kk - delay_steps
        cl = cmdl[kc] if kc >= 0 else 0.0
        cr = cmdr[kc] if kc >= 0 else 0.0
        Veff = max(P[iVMAX] - P[iSAG] * s[5] / 1000.0, 0.0)
        nl = refl + min(max(cl - refl, -dmax), dmax)
        nr = refr + min(max(cr - refr, -dmax), dmax)
        drl = (nl - refl) / dt
        drr = (nr - refr) / dt
        refl = nl
        refr = nr
        el = refl - s[0]
        er = refr - s[1]
        Iul = Kp * el + Ki * intl + Kd * drl
        Iur = Kp * er + Ki * intr + Kd * drr
        Isl = motor_current(Iul, s[0], Veff, P)
        Isr = motor_current(Iur, s[1], Veff, P)
        # anti-windup: no integration into a saturated direction
        if not ((Iul > Isl and el > 0.0) or (Iul < Isl and el < 0.0)):
            intl += el * dt
        if not ((Iur > Isr and er > 0.0) or (Iur < Isr and er < 0.0)):
            intr += er * dt
        Icl = min(max(Iul, -Imax), Imax)   # voltage limit acts continuously in deriv
        Icr = min(max(Iur, -Imax), Imax)
        if kk % log_every == 0:
            row = kk // log_every
            out[row, 0] = kk * dt
            out[row, 1] = s[0]
            out[row, 2] = s[1]
            out[row, 3] = Isl
            out[row, 4] = Isr
            out[row, 5] = s[2]
            out[row, 6] = s[3]
            out[row, 7] = s[4]
            out[row, 8] = s[5]
            out[row, 9] = refl
            out[row, 10] = refr
        if kk == nsteps:
            break
        # ---- RK4 over one controller period
        deriv(s, Icl, Icr, P, gy, wy, gx, wx, k1)
        for i in range(8):
            tmp[i] = s[i] + 0.5 * dt * k1[i]
        deriv(tmp, Icl, Icr, P, gy, wy, gx, wx, k2)
        for i in range(8):
            tmp[i] = s[i] + 0.5 * dt * k2[i]
        deriv(tmp, Icl, Icr, P, gy, wy, gx, wx, k3)
        for i in range(8):
            tmp[i] = s[i] + dt * k3[i]
        deriv(tmp, Icl, Icr, P, gy, wy, gx, wx, k4)
        for i in range(8):
            s[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    return out


def quad(ny=16, nx=4):
    gy, wy = np.polynomial.legendre.leggauss(ny)
    gx, wx = np.polynomial.legendre.leggauss(nx)
    return gy, wy, gx, wx


def simulate(cmdl, cmdr, vehicle=P3AT, terrain='vinyl', effects=None, dt=1e-3, log_every=10,
             ny=16, nx=4):
    """cmdl, cmdr: commanded wheel speeds per controller tick (length N+1, tick k at k*dt)."""
    eff = dict(EFFECT_DEFAULTS)
    eff.update(effects or {})
    P = pack(vehicle, TERRAINS[terrain], eff)
    delay_steps = int(round(eff['delay_s'] / dt))
    out = run_core(np.ascontiguousarray(cmdl, float), np.ascontiguousarray(cmdr, float), P,
                   delay_steps, dt, log_every, *quad(ny, nx))
    keys = ['t', 'wl', 'wr', 'i_l', 'i_r', 'x', 'y', 'yaw', 'E', 'ref_l', 'ref_r']
    res = {k: out[:, i].copy() for i, k in enumerate(keys)}
    res['tau_l'] = vehicle['k'] * res['i_l']
    res['tau_r'] = vehicle['k'] * res['i_r']
    return res


def steady_resistance(wl, wr, vehicle=P3AT, terrain='vinyl', mu_l=None, mu_r=None, ny=16, nx=4,
                      mu_scale=1.0):
    """Steady-state torques tau_Res (eqs. 18, 21) plus lateral force and moment, flat ground.
    mu per side: mu_sa if the side drives (tau_Res w > 0), else mu_op (unless given)."""
    v, t = vehicle, TERRAINS[terrain]
    r, B = v['r'], v['B']
    vel = 0.5 * r * (wl + wr)
    phid = r * (wr - wl) / (t['alpha'] * B)
    N = v['m'] * G0
    p = N / (2 * v['b'] * (v['L'] - v['C']))
    gy, wy, gx, wx = quad(ny, nx)
    out = {}
    for side, w, xc, mu in (('l', wl, -B / 2, mu_l), ('r', wr, B / 2, mu_r)):
        Fy, Fx, Mz = side_forces(w, r, xc, vel, phid, v['L'], v['C'], v['b'], t['K'], gy, wy, gx, wx)
        fr = t['mu_roll'] * N / 2 * np.clip(w / W_EPS, -1, 1)
        if mu is None:
            mu = t['mu_sa'] if r * (p * t['mu_sa'] * Fy + fr) * w > 0 else t['mu_op']
        mu *= mu_scale
        out['tau_' + side] = r * (p * mu * Fy + fr)
        out['Flat_' + side] = p * mu * Fx
        out['Mz_' + side] = p * mu * Mz
        out['mu_' + side] = mu
    return out


# ---------------------------------------------------------------- commands & runs
def inverse_kinematics(v, R, vehicle=P3AT, terrain='vinyl'):
    """Fig. 8: desired speed and radius -> wheel speeds through eq. 1 (R=inf: straight)."""
    r, aB = vehicle['r'], TERRAINS[terrain]['alpha'] * vehicle['B']
    phid = 0.0 if not np.isfinite(R) else v / R
    return (v - phid * aB / 2) / r, (v + phid * aB / 2) / r


def random_commands(rng, duration, dt=1e-3, log_dt=0.01, w_cap=8.5, vehicle=P3AT, terrain='vinyl'):
    """Random holds of 2.5-5 s: straights, turns of 0.5-3 m radius either way, stops.
    Hold boundaries lie on the log grid. Speed 0.2-0.7 m/s, reduced in a turn so that the
    outer wheel is commanded at most w_cap rad/s."""
    n = int(round(duration / dt))
    cl = np.zeros(n + 1)
    cr = np.zeros(n + 1)
    holds = []
    t = 0.0
    while t < duration:
        hold = round(rng.uniform(2.5, 5.0) / log_dt) * log_dt
        u = rng.uniform()
        v = rng.uniform(0.2, 0.7)
        if u < 0.2:
            kind, v, R = 'stop', 0.0, np.inf
        elif u < 0.45:
            kind, R = 'straight', np.inf
        else:
            R = math.exp(rng.uniform(math.log(0.5), math.log(3.0))) * (1 if rng.uniform() < 0.5 else -1)
            kind = 'left' if R > 0 else 'right'
        wl, wr = inverse_kinematics(v, R, vehicle, terrain)
        wmax = max(abs(wl), abs(wr))
        if wmax > w_cap:
            wl, wr, v = wl * w_cap / wmax, wr * w_cap / wmax, v * w_cap / wmax
        a = int(round(t / dt))
        b = min(int(round((t + hold) / dt)), n + 1)
        cl[a:b] = wl
        cr[a:b] = wr
        holds.append(dict(t=round(t, 3), kind=kind, v=round(v, 4), R=None if not np.isfinite(R) else round(R, 4)))
        t = round(t + hold, 6)
    return cl, cr, holds


NOISE = dict(w=0.05, tau=0.08, i=0.05, pos=0.01, yaw=0.005)


def write_csv(path, res, cl, cr, log_every, rng, meta):
    idx = np.arange(res['t'].shape[0]) * log_every
    n = idx.shape[0]
    cols = {
        't': res['t'],
        'wl_cmd': cl[idx], 'wr_cmd': cr[idx],
        'wl': res['wl'] + rng.normal(0, NOISE['w'], n),
        'wr': res['wr'] + rng.normal(0, NOISE['w'], n),
        'tau_l': res['tau_l'] + rng.normal(0, NOISE['tau'], n),
        'tau_r': res['tau_r'] + rng.normal(0, NOISE['tau'], n),
        'i_l': res['i_l'] + rng.normal(0, NOISE['i'], n),
        'i_r': res['i_r'] + rng.normal(0, NOISE['i'], n),
        'x': res['x'] + rng.normal(0, NOISE['pos'], n),
        'y': res['y'] + rng.normal(0, NOISE['pos'], n),
    }
    yaw = res['yaw'] + rng.normal(0, NOISE['yaw'], n)
    cols['yaw'] = (yaw + np.pi) % (2 * np.pi) - np.pi     # wrapped, like a measured heading
    cols['segment'] = np.zeros(n, dtype=int)
    names = list(cols)
    with open(path, 'w') as f:
        for k, val in meta.items():
            f.write(f'# {k}: {val}\n')
        f.write(','.join(names) + '\n')
        data = np.column_stack([cols[k] for k in names])
        fmt = ['%.2f'] + ['%.6f'] * (len(names) - 2) + ['%d']
        np.savetxt(f, data, fmt=fmt, delimiter=',')


CASES = [
    # file stem, effect, {param: value} (the simulator's effect parameters), manifest params
    ('none_a', 'none', {}, {}),
    ('none_b', 'none', {}, {}),
    ('wheel_radius_left_7pct', 'wheel_radius', {'scale_left': 0.93}, {'scale_left': 0.93, 'scale_right': 1.0}),
    ('wheel_radius_right_5pct', 'wheel_radius', {'scale_right': 0.95}, {'scale_left': 1.0, 'scale_right': 0.95}),
    ('voltage_sag_1.0', 'voltage_sag', {'sag_V_per_kJ': 1.0}, {'sag_V_per_kJ': 1.0}),
    ('shear_relaxation_0.15', 'shear_relaxation', {'tau_s': 0.15}, {'tau_s': 0.15}),
    ('command_delay_0.08', 'command_delay', {'delay_s': 0.08}, {'delay_s': 0.08}),
    ('command_delay_0.05', 'command_delay', {'delay_s': 0.05}, {'delay_s': 0.05}),
    ('viscous_0.3', 'viscous_friction', {'c_Nms': 0.3}, {'c_Nms': 0.3}),
    ('turning_friction_0.75', 'turning_friction', {'mu_scale': 0.75}, {'mu_scale': 0.75}),
    ('grade_4deg', 'grade', {'grade_deg': 4.0}, {'grade_deg': 4.0}),
    ('grade_2.5deg_world', 'grade', {'grade_deg': 2.5, 'grade_dir_deg': 30.0},
     {'grade_deg': 2.5, 'toward_deg': 30.0}),
]


def write_case(stem, outdir, duration=90.0, base_seed=20240):
    """Case ``stem`` of CASES simulated and written to OUTDIR/STEM.csv as generate writes
    it: (path, the simulation, the command holds, the case's seed)."""
    i = next(k for k, c in enumerate(CASES) if c[0] == stem)
    seed = base_seed + 17 * i
    cl, cr, holds = random_commands(np.random.default_rng([seed, 1]), duration)
    res = simulate(cl, cr, effects=CASES[i][2])
    path = os.path.join(outdir, stem + '.csv')
    meta = {'vehicle': 'p3at', 'terrain': 'vinyl', 'slope_deg': 0,
            'note': 'synthetic run, independent simulator'}
    write_csv(path, res, cl, cr, 10, np.random.default_rng([seed, 2]), meta)
    return path, res, holds, seed


def generate(outdir, duration=90.0, base_seed=20240):
    os.makedirs(outdir, exist_ok=True)
    manifest = {'generator': 'python bench/independent/sim.py', 'duration_s': duration, 'log_hz': 100,
                'noise_sd': NOISE, 'vehicle': 'p3at', 'terrain': 'vinyl', 'header_slope_deg': 0,
                'runs': []}
    for i, (stem, effect, eff, mparams) in enumerate(CASES):
        t0 = time.time()
        path, res, holds, seed = write_case(stem, outdir, duration, base_seed)
        el = time.time() - t0
        E = res['E']
        entry = dict(file=stem + '.csv', effect=effect,
                     param=None if not mparams else (next(iter(eff)) if eff else None),
                     value=None if not eff else next(iter(eff.values())),
                     params=mparams, seed=seed, energy_J=round(float(E[-1]), 1),
                     energy_monotonic=bool(np.all(np.diff(E) >= 0)), holds=holds)
        manifest['runs'].append(entry)
        print(f'{stem:26s} {effect:17s} {json.dumps(mparams):40s} E={E[-1]:7.1f} J  '
              f'max|I|={max(abs(res["i_l"]).max(), abs(res["i_r"]).max()):.2f} A  sim {el:.1f} s')
    with open(os.path.join(outdir, 'manifest.json'), 'w') as f:
        json.dump(manifest, f, indent=1)


# ---------------------------------------------------------------- sanity checks
def hold_cmd(wl, wr, duration, dt=1e-3):
    n = int(round(duration / dt))
    return np.full(n + 1, float(wl)), np.full(n + 1, float(wr))


def sanity():
    r = P3AT['r']
    print('== steady resistance (eqs. 18, 21), v = 0.3 m/s, commanded radius via eq. 1 ==')
    print(f'{"R m":>7s} {"tau_l":>7s} {"tau_r":>7s} {"Flat N":>7s} {"Mz Nm":>7s}')
    for R in (0.2, 0.3, 0.5, 1, 2, 3, 10, 100, np.inf):
        wl, wr = inverse_kinematics(0.3, R)
        o = steady_resistance(wl, wr)
        print(f'{R:7.1f} {o["tau_l"]:7.3f} {o["tau_r"]:7.3f} {o["Flat_l"] + o["Flat_r"]:7.3f} '
              f'{o["Mz_l"] + o["Mz_r"]:7.3f}')
    print('quadrature check (R=1, v=0.3): 16x4 vs 64x8:')
    wl, wr = inverse_kinematics(0.3, 1.0)
    a, b = steady_resistance(wl, wr), steady_resistance(wl, wr, ny=64, nx=8)
    print(f'  tau_l {a["tau_l"]:.4f} / {b["tau_l"]:.4f}   tau_r {a["tau_r"]:.4f} / {b["tau_r"]:.4f}')
    wl, wr = inverse_kinematics(0.3, 3.0)
    a, b = steady_resistance(wl, wr), steady_resistance(wl, wr, ny=64, nx=8)
    print(f'  (R=3) tau_l {a["tau_l"]:.4f} / {b["tau_l"]:.4f}   tau_r {a["tau_r"]:.4f} / {b["tau_r"]:.4f}')
    print(f'expected rolling torque r mu_roll m g / 2 = {r * 0.0371 * 31 * G0 / 2:.3f} N m')

    print('== closed loop ==')
    def last(res, key, T=3.0):
        return float(np.mean(res[key][res['t'] > res['t'][-1] - T]))
    wl, wr = inverse_kinematics(0.5, np.inf)
    res = simulate(*hold_cmd(wl, wr, 10))
    print(f'straight 0.5 m/s: w {last(res, "wl"):.3f}/{last(res, "wr"):.3f} rad/s, '
          f'tau {last(res, "tau_l"):.3f}/{last(res, "tau_r"):.3f} N m, P={np.diff(res["E"])[-1] / 0.01:.1f} W')
    for R in (1.0, -1.0, 0.5):
        wl, wr = inverse_kinematics(0.4, R)
        res = simulate(*hold_cmd(wl, wr, 10))
        vv = 0.5 * r * (last(res, 'wl') + last(res, 'wr'))
        print(f'turn R={R:+.1f} m v=0.4: w {last(res, "wl"):.3f}/{last(res, "wr"):.3f} (cmd {wl:.3f}/{wr:.3f}), '
              f'tau {last(res, "tau_l"):.3f}/{last(res, "tau_r"):.3f} N m, v={vv:.3f}, '
              f'P={np.diff(res["E"])[-1] / 0.01:.1f} W')
    wl, wr = inverse_kinematics(1.5, np.inf)
    res = simulate(*hold_cmd(wl, wr, 8))
    print(f'straight, 1.5 m/s commanded: settles at {r * last(res, "wl"):.3f} m/s (paper Fig. 17: ~0.93)')
    for deg in (5.4, 15.0):
        wl, wr = inverse_kinematics(0.7, np.inf)
        res = simulate(*hold_cmd(wl, wr, 8), effects={'grade_deg': deg})
        print(f'grade {deg}: commanded 0.7 m/s -> {r * last(res, "wl", 1):.3f} m/s, '
              f'I {last(res, "i_l", 1):.2f} A')
    rng = np.random.default_rng(5)
    cl, cr, _ = random_commands(rng, 90.0)
    t0 = time.time()
    res = simulate(cl, cr)
    el = time.time() - t0
    dE = np.diff(res['E'])
    print(f'random 90 s run: sim {el:.1f} s, E = {res["E"][-1]:.0f} J, min dE = {dE.min():.3g} J '
          f'(monotonic: {bool(np.all(dE >= 0))}), max|tau| {max(abs(res["tau_l"]).max(), abs(res["tau_r"]).max()):.2f} N m')
    res2 = simulate(cl, cr, ny=32, nx=6)
    print(f'  quadrature 16x4 vs 32x6 on that run: max|dw| {np.abs(res["wl"] - res2["wl"]).max():.4f} rad/s, '
          f'max|dtau| {np.abs(res["tau_l"] - res2["tau_l"]).max():.4f} N m')


if __name__ == '__main__':
    ap = argparse.ArgumentParser()
    ap.add_argument('--sanity', action='store_true')
    ap.add_argument('--out', default=os.path.join(HERE, 'runs'))
    ap.add_argument('--duration', type=float, default=90.0)
    a = ap.parse_args()
    if a.sanity:
        sanity()
    else:
        generate(a.out, a.duration)
