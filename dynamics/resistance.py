"""Wheel-ground resistance C(q, q-dot): shear-displacement friction (eqs. 7-22) and rolling.

Two forms of the same physics:

* the **exact** form integrates the shear stress of eq. 7 over the four contact patches
  with tensor Gauss-Legendre quadrature (reference and tests; NumPy, vectorised);
* the **fast** form, for the compiled hot path, rests on a property of eqs. 8-17: every
  sliding velocity and contact time scales with the wheel speeds, so the shear
  displacements, the sliding directions and hence the friction forces depend only on the
  *direction* of the wheel-speed vector (wl, wr), not on its magnitude. The friction per
  unit (pressure x friction coefficient) of the right side is one periodic function of
  that direction, tabulated once per (vehicle geometry, alpha, K) over the diamond angle
  (:func:`diamond_angle`, no transcendental function) and interpolated linearly; the left
  side is its mirror image, F_l(wl, wr) = F_r(wr, wl).

Sign convention: a *resistance torque* is the torque the motor must supply to hold the
wheel speed (eqs. 18, 21); it is positive when the ground pushes the tyre forward (the
side drives the vehicle) and negative when it pushes it back (the side brakes).

Singular cases (PARAMETERS.md) and the choices made:

* a wheel at rest (w = 0) while the vehicle turns: the contact time of eq. 8 is
  infinite, the tread particle is fully sheared, 1 - exp(-j/K) -> 1;
* rotation inside one patch: the closed forms of eqs. 12-16 are exact for any rotation
  angle theta = yaw_rate * t at constant rates (checked against a direct integration of
  the sliding velocity, to round-off); theta is capped at ``THETA_CAP`` = 0.2 rad
  (11.5 deg) for the wheel at rest (t -> infinity), where the shear displacement is
  already at least 0.12 m x 0.2 = 24 mm >> K (full shear). That holds for K of a few
  mm (the shipped terrains: at most 3 mm, where the cap changes the unit friction by
  4e-7 of its full value, the patch area); at K = 10 mm by up to 3 %, at 30 mm by 20 %;
* a wheel reversing (point turns, radii below alpha B / 2): the tread enters the patch
  from its other edge, the contact time counts from there;
* the vehicle at rest: the friction depends on the direction alone, a Coulomb-like
  discontinuity at the origin of the wheel-speed plane. Below a wheel-speed magnitude
  (|wl| + |wr| for the friction, |w| for rolling) of ``OMEGA_EPS`` the friction and the
  rolling resistance are scaled down linearly
  (a standard regularisation; 0.02 rad/s is 2 mm/s at the rim).
"""
from __future__ import annotations

import hashlib
import inspect
import os
from functools import lru_cache
from pathlib import Path

import numpy as np
from ._jit import jit_inline

from .params import G, Terrain, Vehicle

THETA_CAP = 0.2     # rad, largest rotation inside one contact patch (see module doc)
OMEGA_EPS = 0.02    # rad/s, regularisation of friction and rolling resistance at rest
TABLE_SIZE = 16384  # nodes of the fast table over the diamond angle t in [0, 4)


# ----------------------------------------------------------------------------------
# The paper's equations, one function each (NumPy arrays broadcast)
# ----------------------------------------------------------------------------------
def shear_stress(p, mu, j, K):
    """Eq. 7: shear stress tau_ss = p mu (1 - exp(-j / K)) [Pa] for pressure p [Pa],
    friction coefficient mu, shear displacement j [m] and shear modulus K [m]."""
    return p * mu * (1.0 - np.exp(-j / K))


def contact_time(y0, y, r_omega, yaw_rate):
    """Eq. 8: time [s] a tread particle at longitudinal position y [m] has been in contact
    since it entered the patch at y0 [m], t = (y0 - y) / (r w) for rim speed r w [m/s].

    Infinite for a wheel at rest; capped so that the rotation yaw_rate * t stays within
    ``THETA_CAP`` (module doc).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(r_omega != 0.0, (y0 - y) / r_omega, np.inf)
        cap = np.where(yaw_rate != 0.0, THETA_CAP / np.abs(yaw_rate), np.inf)
    return np.minimum(t, cap)


def sliding_velocity(xw, y, v, yaw_rate, r_omega):
    """Eqs. 9, 10: sliding velocity (v_x, v_y) [m/s] of the tread particle at body-frame
    lateral position xw (from the centre of gravity) and longitudinal position y [m].

    v_x = -y yaw_rate, v_y = (R + xw) yaw_rate - r w, written with v = R yaw_rate so that
    straight motion (R infinite) needs no special case. Its angle is gamma of eq. 10.
    """
    return -y * yaw_rate, v + xw * yaw_rate - r_omega


def shear_displacement(xw, y, y0, v, t, yaw_rate):
    """Eqs. 12, 13 (front patch, y0 = L/2) and 15, 16 (rear patch, y0 = -C/2): shear
    displacement (j_X, j_Y) [m] of a tread particle after contact time t [s].

    j_X = (R + xw)(cos th - 1) - y sin th,  j_Y = (R + xw) sin th + y cos th - y0,
    th = yaw_rate t. Evaluated in the form R th = v t, with sin th = th S(th) and
    1 - cos th = th^2 S(th/2)^2 / 2 (S = sin x / x), finite for straight motion.
    """
    th = yaw_rate * t
    s1 = np.sinc(th / np.pi)
    s2 = np.sinc(th / (2.0 * np.pi))
    jx = -(v * t * th / 2.0 + xw * th * th / 2.0) * s2 * s2 - y * th * s1
    jy = v * t * s1 + xw * th * s1 + y * np.cos(th) - y0
    return jx, jy


def resistance_torque(r, friction, rolling):
    """Eqs. 18, 21: resistance torque of one side [N m], tau_Res = r (F_f + f_r)."""
    return r * (friction + rolling)


def rolling_resistance(mu_roll, mass, pitch, omega):
    """Rolling resistance of one side [N]: f_r = mu_roll m g cos(pitch) / 2 sign(w)
    (PARAMETERS.md; regularised below ``OMEGA_EPS``)."""
    return mu_roll * mass * G * np.cos(pitch) / 2.0 * np.clip(omega / OMEGA_EPS, -1.0, 1.0)


def drive_friction(vehicle: Vehicle, omega, side: int = 0):
    """The drive's own friction torque at one side's wheels [N m] (model extensions, 0 in
    the paper's model): the viscous c w and the motors' no-load current i0 [A], a Coulomb
    torque k s i0 sign(w) (k the torque constant at the wheel, s the side's torque scale:
    side 0 left, 1 right) that the drive supplies on top of the load, so that a motor
    turning freely draws i0 (regularised below ``OMEGA_EPS`` as the rolling resistance is).
    The compiled step's ``_resistance`` adds the same; the viscous term also enters eq.
    22's choice of coefficient (:func:`side_force`'s load), the no-load current does not:
    it stays inside the drive."""
    v = vehicle
    w = np.asarray(omega, float)
    k = v.torque_constant * (v.torque_scale_left, v.torque_scale_right)[side]
    return v.viscous * w + k * v.no_load_current * np.clip(w / OMEGA_EPS, -1.0, 1.0)


def patch_pressure(vehicle: Vehicle, pitch=0.0):
    """Normal pressure [Pa] of each of the four equal patches: m g cos(pitch) / (2 b (L - C))."""
    v = vehicle
    return v.mass * G * np.cos(pitch) / (2.0 * v.patch_width * (v.patch_outer - v.patch_inner))


@lru_cache(maxsize=8)
def _gauss(n_long: int, n_lat: int):
    return np.polynomial.legendre.leggauss(n_long), np.polynomial.legendre.leggauss(n_lat)


def unit_friction_right(wl, wr, vehicle: Vehicle, terrain: Terrain, n_long=96, n_lat=12):
    """Eq. 17 per unit p mu: longitudinal friction of the right wheels divided by p mu [m^2].

    Integrates (1 - exp(-j/K)) times the longitudinal component of the unit friction
    direction (opposite to the sliding velocity, eq. 10) over the front and rear patches
    with Gauss-Legendre quadrature of ``n_long`` x ``n_lat`` points per patch.
    ``wl``, ``wr`` [rad/s] broadcast. Positive: the ground pushes the tyre forward.
    """
    veh = vehicle
    r, B, L, C, b = veh.wheel_radius, veh.width, veh.patch_outer, veh.patch_inner, veh.patch_width
    wl = np.asarray(wl, float)[..., None, None]
    wr = np.asarray(wr, float)[..., None, None]
    v = r * (wl + wr) / 2.0
    yaw_rate = r * (wr - wl) / (terrain.alpha * B)
    r_omega = r * wr
    (gy, wy), (gx, wx) = _gauss(n_long, n_lat)
    xw = (B / 2.0 + gx * b / 2.0)[None, :]
    wxs = wx * b / 2.0
    total = 0.0
    for lo, hi in ((C / 2.0, L / 2.0), (-L / 2.0, -C / 2.0)):
        y = ((lo + hi) / 2.0 + gy * (hi - lo) / 2.0)[:, None]
        wys = wy * (hi - lo) / 2.0
        y0 = np.where(r_omega > 0.0, hi, lo)            # entry edge of the patch
        t = contact_time(y0, y, r_omega, yaw_rate)
        jx, jy = shear_displacement(xw, y, y0, v, t, yaw_rate)
        vx, vy = sliding_velocity(xw, y, v, yaw_rate, r_omega)
        speed = np.hypot(vx, vy)
        with np.errstate(invalid="ignore", divide="ignore"):
            direction = np.where(speed > 0.0, -vy / speed, 0.0)
        f = (1.0 - np.exp(-np.hypot(jx, jy) / terrain.shear_modulus)) * direction
        total = total + np.einsum("...ij,i,j->...", f, wys, wxs)
    return total


def friction_forces(wl, wr, vehicle: Vehicle, terrain: Terrain, mu_left, mu_right, pitch=0.0, **quad):
    """Eqs. 17 and 20: longitudinal sliding friction (F_lf, F_rf) [N] of both sides, exact.

    The left side is the mirror image of the right: F_lf(wl, wr) = F_rf(wr, wl).
    """
    p = patch_pressure(vehicle, pitch)
    scale = np.clip((np.abs(wl) + np.abs(wr)) / OMEGA_EPS, 0.0, 1.0)
    fr = unit_friction_right(wl, wr, vehicle, terrain, **quad)
    fl = unit_friction_right(wr, wl, vehicle, terrain, **quad)
    return p * mu_left * fl * scale, p * mu_right * fr * scale


def steady_resistance(wl, wr, vehicle: Vehicle, terrain: Terrain, pitch=0.0, **quad):
    """Eq. 22: C(q, q-dot) = (tau_lRes, tau_rRes) [N m] at constant wheel speeds, exact form.

    The friction coefficient of each side is mu_sa where its motor drives (torque and
    speed of one sign) and mu_op where it brakes, by the one rule of :func:`side_force`.
    With the radius-scale extension each side rolls on r times its scale, as in the
    compiled step: the patches see the scaled rim speeds, and each side's torques (its
    friction's and eq. 24's gravity) scale with it.
    """
    wl = np.asarray(wl, float)
    wr = np.asarray(wr, float)
    el = vehicle.radius_scale_left * wl
    er = vehicle.radius_scale_right * wr
    scale = np.clip((np.abs(el) + np.abs(er)) / OMEGA_EPS, 0.0, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):     # (at rest the patch integrals are 0/0)
        left = np.where(scale > 0.0, unit_friction_right(er, el, vehicle, terrain, **quad) * scale, 0.0)
        right = np.where(scale > 0.0, unit_friction_right(el, er, vehicle, terrain, **quad) * scale, 0.0)
    return _side_torques(left, right, wl, wr, vehicle, terrain, pitch)


@jit_inline
def side_force(unit, roll, w, press, mu_sa, mu_op, load, rim):
    """Eq. 22's choice of friction coefficient for one side, as a ground force [N].

    The side's longitudinal ground force is F(mu) = press mu unit + roll (eqs. 17/20 per
    unit p mu times p mu, plus the signed rolling resistance ``roll`` [N]); its resistance
    torque is ``rim`` F (eqs. 18, 21; ``rim`` the rolling radius r [m]). At steady speed
    the motor supplies rim F + load, where ``load`` [N m] is the rest of what it holds:
    gravity (eq. 24) and the viscous extension, G + c w. The coefficient is mu_sa where
    the side's motor *drives* (torque and wheel speed of one sign: (rim F(mu_sa) + load)
    w > 0) and mu_op where it *brakes* ((rim F(mu_op) + load) w < 0). A climb's inner
    wheel can be pushed back by the ground and still driven by its motor: mu_sa. With
    mu_sa >= mu_op both tests can fail at once where the ground pushes the side back,
    in a narrow band where mu_sa would make the motor brake and mu_op make it drive.
    There the coefficient lies between the two and the motor neither drives nor brakes:
    F = -load / rim (on flat ground without the viscous term, F = 0), continuous across
    the band. Where the ground pushes the side forward on a descent both tests can
    pass: mu_sa is taken, and F jumps to the mu_op value where rim F(mu_sa) + load
    reaches zero (docs/model.md). So a driving torque never takes the braking
    coefficient, and the choice depends on the state (wheel speeds, slope) alone,
    never on the sign of a current. A wheel at rest holds (mu_op).

    Returns (F [N], dF/d unit [N/m^2], dF/d roll [-], dF/d load [1/m]) for the implicit
    integrator.
    """
    f_sa = press * mu_sa * unit + roll
    if (f_sa * rim + load) * w > 0.0:
        return f_sa, press * mu_sa, 1.0, 0.0
    f_op = press * mu_op * unit + roll
    if (f_op * rim + load) * w < 0.0 or w == 0.0:
        return f_op, press * mu_op, 1.0, 0.0
    return -load / rim, 0.0, 0.0, -1.0 / rim


_side_force_array = np.vectorize(lambda u, roll, w, p, sa, op, load, rim: side_force(u, roll, w, p, sa, op, load, rim)[0],
                                 otypes=[float])


def _side_torques(unit_l, unit_r, wl, wr, vehicle: Vehicle, terrain: Terrain, pitch):
    """Eqs. 18, 21 and 22 for both sides from unit frictions: the resistance torques
    [N m] with each side's coefficient chosen by :func:`side_force` (gravity of eq. 24 on
    ``pitch`` [rad] and the viscous term in its load), the same rule as the compiled
    closed loop. The drive's own friction (:func:`drive_friction`) is not in them."""
    r = vehicle.wheel_radius
    p = patch_pressure(vehicle, pitch)
    grav = vehicle.mass * G * r * np.sin(pitch) / 2.0          # eq. 24, per side [N m]
    out = []
    for unit, w, sc in ((unit_l, wl, vehicle.radius_scale_left), (unit_r, wr, vehicle.radius_scale_right)):
        roll = rolling_resistance(terrain.mu_roll, vehicle.mass, pitch, w)
        load = sc * grav + vehicle.viscous * np.asarray(w, float)
        out.append(r * sc * _side_force_array(unit, roll, w, p, terrain.mu_sa, terrain.mu_op, load, r * sc))
    return out[0], out[1]


# ----------------------------------------------------------------------------------
# The fast form
# ----------------------------------------------------------------------------------
@jit_inline
def diamond_angle(wl, wr):
    """Direction coordinate of the wheel-speed vector, t in [0, 4): the position on the
    diamond |a| + |b| = 1 of (a, b) = (wl, wr) / (|wl| + |wr|), counter-clockwise from
    (1, 0). Monotone in atan2(wr, wl) and free of transcendental functions; straight ahead
    is t = 0.5, point turns 1.5 and 3.5, straight back 2.5. Returns (t, dt/dwl, dt/dwr);
    (0, 0, 0) within 1e-9 rad/s of the origin."""
    awl = abs(wl)
    awr = abs(wr)
    d = awl + awr
    if d < 1e-9:                     # at rest (the friction is regularised to 0 there)
        return 0.0, 0.0, 0.0
    sl = 1.0 if wl >= 0.0 else -1.0
    sr = 1.0 if wr >= 0.0 else -1.0
    if wl >= 0.0 and wr >= 0.0:      # t = wr / d
        c, sig, k = 0.0, 1.0, 1
    elif wl < 0.0 and wr >= 0.0:     # t = 1 - wl / d
        c, sig, k = 1.0, -1.0, 0
    elif wl < 0.0:                   # t = 2 - wr / d
        c, sig, k = 2.0, -1.0, 1
    else:                            # t = 3 + wl / d
        c, sig, k = 3.0, 1.0, 0
    wk = wr if k == 1 else wl
    t = c + sig * wk / d
    d2 = d * d
    # d(wk/d)/dwj = delta_kj / d - wk sign(wj) / d^2
    dl = sig * ((1.0 / d if k == 0 else 0.0) - wk * sl / d2)
    dr = sig * ((1.0 / d if k == 1 else 0.0) - wk * sr / d2)
    return t, dl, dr


def diamond_point(t):
    """Inverse of :func:`diamond_angle`: the point (wl, wr) of the unit diamond at t."""
    t = np.mod(np.asarray(t, float), 4.0)
    q = np.floor(t)
    f = t - q
    wl = np.select([q == 0, q == 1, q == 2, q == 3], [1 - f, -f, -(1 - f), f])
    wr = np.select([q == 0, q == 1, q == 2, q == 3], [f, 1 - f, -f, -(1 - f)])
    return wl, wr


def _cache_dir() -> Path:
    """Where computed friction tables are kept between runs: $SBMPC_CACHE_DIR, else
    $XDG_CACHE_HOME/sbmpc, else ~/.cache/sbmpc."""
    d = os.environ.get("SBMPC_CACHE_DIR")
    if d:
        return Path(d)
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "sbmpc"


@lru_cache(maxsize=1)
def _code_hash() -> str:
    """Hash of the source of everything a friction table is computed from: a change of
    the physics makes new tables instead of reading stale ones."""
    src = "".join(inspect.getsource(f) for f in (unit_friction_right, shear_displacement, contact_time,
                                                 sliding_velocity, diamond_point, _compute_table, _gauss))
    return hashlib.sha256(src.encode()).hexdigest()[:16]


@lru_cache(maxsize=64)
def _table_cached(r, B, L, C, b, alpha, K, size):
    """The table of a geometry, alpha and K: read from the disk cache (:func:`_cache_dir`)
    when it holds it, else computed (about 0.3 s) and written there (best effort: a
    cache that cannot be written is skipped)."""
    key = hashlib.sha256(repr((r, B, L, C, b, alpha, K, size, _code_hash())).encode()).hexdigest()[:24]
    path = _cache_dir() / f"friction-{key}.npy"
    try:
        values = np.load(path)
        if values.shape == (size + 1,) and values.dtype == np.float64 and np.all(np.isfinite(values)):
            values.setflags(write=False)
            return values
    except (OSError, ValueError):
        pass
    values = _compute_table(r, B, L, C, b, alpha, K, size)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npy")
        np.save(tmp, values)
        os.replace(tmp, path)
    except OSError:
        pass
    return values


def _compute_table(r, B, L, C, b, alpha, K, size):
    veh = Vehicle(wheel_radius=r, width=B, patch_outer=L, patch_inner=C, patch_width=b)
    ter = Terrain(alpha=alpha, shear_modulus=K)
    half = size // 2
    t = 4.0 * np.arange(half) / size
    values = np.empty(size + 1)
    for s in range(0, half, 1024):
        wl, wr = diamond_point(t[s:s + 1024])
        values[s:s + len(wl)] = unit_friction_right(wl, wr, veh, ter)
    values[half:size] = -values[:half]    # reversing every wheel reverses every force
    values[size] = values[0]              # periodic closure for the interpolation
    values.setflags(write=False)
    return values


def friction_table(vehicle: Vehicle, terrain: Terrain, size: int = TABLE_SIZE) -> np.ndarray:
    """The fast form: unit friction of the right side [m^2] at diamond angles
    t_k = 4 k / size, k = 0..size (the last node closes the period; see
    :func:`diamond_angle`). Cached per geometry, alpha and K.

    Only half the circle is integrated; the other half follows exactly from reversing
    every wheel (all sliding velocities change sign, the patches swap their entry edges).
    """
    v = vehicle
    return _table_cached(v.wheel_radius, v.width, v.patch_outer, v.patch_inner, v.patch_width,
                         terrain.alpha, terrain.shear_modulus, int(size))


@jit_inline
def table_lookup(table, t):
    """Linear interpolation of a friction table at diamond angle t in [0, 4]; returns
    (value, slope d value / d t)."""
    n = table.shape[0] - 1
    u = t * (n / 4.0)
    i = int(u)
    if i < 0:
        i = 0
    elif i >= n:
        i = n - 1
    frac = u - i
    slope = (table[i + 1] - table[i]) * (n / 4.0)
    return table[i] + frac * (table[i + 1] - table[i]), slope


@jit_inline
def unit_friction_fast(table, wl, wr):
    """Fast form of eqs. 17 and 20 per unit p mu [m^2], including the rest regularisation:
    returns (fl, fr, dfl_dwl, dfl_dwr, dfr_dwl, dfr_dwr), the last four the Jacobian
    [m^2 s/rad] used by the linearly implicit integrator."""
    if abs(wl) + abs(wr) < 1e-9:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    t, tl, tr = diamond_angle(wl, wr)
    fr, sr = table_lookup(table, t)
    m, ml, mr = diamond_angle(wr, wl)          # mirror image: swap the wheels
    fl, sl = table_lookup(table, m)
    dfr_dwl = sr * tl
    dfr_dwr = sr * tr
    dfl_dwl = sl * mr                           # d m / d wl = (d/d second argument)
    dfl_dwr = sl * ml
    rho1 = abs(wl) + abs(wr)
    if rho1 < OMEGA_EPS:
        s = rho1 / OMEGA_EPS
        ds_dwl = (1.0 if wl >= 0.0 else -1.0) / OMEGA_EPS
        ds_dwr = (1.0 if wr >= 0.0 else -1.0) / OMEGA_EPS
        dfr_dwl = dfr_dwl * s + fr * ds_dwl
        dfr_dwr = dfr_dwr * s + fr * ds_dwr
        dfl_dwl = dfl_dwl * s + fl * ds_dwl
        dfl_dwr = dfl_dwr * s + fl * ds_dwr
        fr *= s
        fl *= s
    return fl, fr, dfl_dwl, dfl_dwr, dfr_dwl, dfr_dwr


def steady_resistance_fast(wl, wr, vehicle: Vehicle, terrain: Terrain, pitch=0.0):
    """Eq. 22 with the fast form (same conventions as :func:`steady_resistance`)."""
    table = friction_table(vehicle, terrain)
    wl = np.asarray(wl, float)
    wr = np.asarray(wr, float)
    flat_l, flat_r = np.broadcast_arrays(wl, wr)
    fl = np.empty(flat_l.shape)
    fr = np.empty(flat_l.shape)
    sl, sr = vehicle.radius_scale_left, vehicle.radius_scale_right
    for idx in np.ndindex(flat_l.shape):
        res = unit_friction_fast(table, sl * float(flat_l[idx]), sr * float(flat_r[idx]))
        fl[idx], fr[idx] = res[0], res[1]
    return _side_torques(fl, fr, flat_l, flat_r, vehicle, terrain, pitch)
