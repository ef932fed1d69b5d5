"""Terrain identification (paper eq. 28): K, mu_sa, mu_op from steady-state wheel torques.

The paper drove circles at N commanded radii and solved
    min_{K, mu_sa, mu_op} sum_i (d tau_lRes^(i))^2 + (d tau_rRes^(i))^2
with MATLAB's lsqnonlin; here scipy.optimize.least_squares (trust-region reflective, with
bounds) on the exact form of the resistance (eq. 22).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .kinematics import wheel_speeds
from .params import Terrain, Vehicle
from .resistance import steady_resistance
from .runs import pose_updates

#: The paper's 31 commanded radii [m]: 0.2..1 by 0.1, 2..10 by 1, 10^1.2..10^2,
#: 10^2.2..10^3.2 by 10^0.2, then 10^3.6 and 10^4.
PAPER_RADII = np.concatenate([
    np.round(np.arange(0.2, 1.01, 0.1), 10), np.arange(2.0, 11.0),
    10.0 ** np.arange(1.2, 2.01, 0.2), 10.0 ** np.arange(2.2, 3.21, 0.2), [10.0 ** 3.6, 1e4]])


def circle_torques(vehicle: Vehicle, terrain: Terrain, radii, speed: float = 0.2, check: bool = True, **quad):
    """Steady-state (left, right) torques [N m] on counter-clockwise circles of commanded
    radii [m] at desired speed [m/s] (eq. 22 at the commanded wheel speeds: in steady state
    the PID's integral makes the wheels turn exactly as commanded, which it can only where
    the drive delivers the torque). ``check``: a ParameterError naming the radii whose
    torque lies outside the drive's window at its wheel speed (eq. 27 and the current
    limit: at 0.2 m/s the outer side of a 0.2-3 m circle on asphalt asks 6.5-10.1 N m of
    the P3-AT's 5 N m, of a 0.2-1 m circle on the lemniscate's vinyl 5.3-6.4 N m; on the
    paper's vinyl every radius holds, 4.72 N m at 0.2 m), where the steady state eq. 28
    compares with does not exist."""
    from .drive import current_window
    from .params import ParameterError
    radii = np.asarray(radii, float)
    wl, wr = wheel_speeds(speed, 1.0 / radii, vehicle.wheel_radius, vehicle.width, 1.0)
    tl, tr = steady_resistance(wl, wr, vehicle, terrain, **quad)
    if check:
        k = vehicle.torque_constant
        bad = np.zeros(radii.shape, bool)
        for w, tau in ((wl, tl), (wr, tr)):
            for i, (wi, ti) in enumerate(zip(np.ravel(w), np.ravel(tau))):
                lo, hi = current_window(float(wi), vehicle.v_max, k, vehicle.armature_resistance, vehicle.current_limit)
                if not k * lo - 1e-9 <= ti <= k * hi + 1e-9:
                    bad.flat[i] = True
        if bad.any():
            worst = float(np.max(np.abs(np.concatenate([np.ravel(tl)[bad.ravel()], np.ravel(tr)[bad.ravel()]]))))
            raise ParameterError(
                f"radii: the drive cannot hold {int(bad.sum())} of the circles at {speed:g} m/s (radii "
                f"{', '.join(f'{x:g}' for x in radii[bad][:6])}{' ...' if bad.sum() > 6 else ''} m ask steady torques "
                f"up to {worst:.3g} N m; it delivers {vehicle.continuous_torque:.3g} N m at most, eq. 27): no "
                "steady state exists there to compare with; drop those radii or lower the speed")
    return tl, tr


@dataclass(frozen=True)
class TerrainFit:
    """Result of eq. 28: fitted parameters, their standard errors, the RMS residual [N m]."""

    shear_modulus: float
    mu_sa: float
    mu_op: float
    stderr: tuple
    rms: float
    n: int

    def terrain(self, base: Terrain) -> Terrain:
        return base.replace(shear_modulus=self.shear_modulus, mu_sa=self.mu_sa, mu_op=self.mu_op)


def fit_terrain(vehicle: Vehicle, terrain: Terrain, radii, tau_l, tau_r, speed: float = 0.2,
                guess=(0.001, 0.5, 0.5)) -> TerrainFit:
    """Eq. 28: fit K, mu_sa, mu_op of ``terrain`` (alpha and mu_roll kept) to measured
    steady-state torques tau_l, tau_r [N m] at commanded radii [m]."""
    from .params import ParameterError
    radii = np.asarray(radii, float)
    tau_l, tau_r = np.asarray(tau_l, float), np.asarray(tau_r, float)
    if radii.ndim != 1 or tau_l.shape != radii.shape or tau_r.shape != radii.shape or len(radii) < 2:
        raise ParameterError(f"radii, tau_l, tau_r: expected 1-D arrays of one equal length, at least 2 (three "
                             f"parameters from two torques per circle), found shapes {radii.shape}, {tau_l.shape}, "
                             f"{tau_r.shape}")
    if not (np.all(np.isfinite(radii)) and np.all(radii != 0) and np.all(np.isfinite(tau_l))
            and np.all(np.isfinite(tau_r))):
        raise ParameterError("radii, tau_l, tau_r: expected finite numbers and non-zero radii, found NaN, inf or 0")
    meas = np.concatenate([tau_l, tau_r])
    quad = dict(n_long=64, n_lat=8)

    def residual(p):
        ter = terrain.replace(shear_modulus=p[0] * 1e-3, mu_sa=p[1], mu_op=p[2])
        tl, tr = circle_torques(vehicle, ter, radii, speed, check=False, **quad)
        return np.concatenate([tl, tr]) - meas

    x0 = np.array([guess[0] * 1e3, guess[1], guess[2]])
    sol = least_squares(residual, x0, bounds=([1e-3, 0.0, 0.0], [50.0, 5.0, 5.0]), x_scale=[0.5, 0.1, 0.1])
    dof = max(1, len(meas) - 3)
    s2 = float(sol.fun @ sol.fun) / dof
    try:
        cov = np.linalg.inv(sol.jac.T @ sol.jac) * s2
        se = np.sqrt(np.abs(np.diag(cov)))
    except np.linalg.LinAlgError:
        se = np.full(3, np.inf)
    return TerrainFit(sol.x[0] * 1e-3, float(sol.x[1]), float(sol.x[2]),
                      (se[0] * 1e-3, float(se[1]), float(se[2])), float(np.sqrt(np.mean(sol.fun ** 2))), len(radii))


def table_one_study(vehicle: Vehicle, truth: Terrain, noise: float = 0.05, seed: int = 0,
                    counts=range(2, 32)):
    """The paper's Table I study on generated data: torques of ``truth`` at the 31 paper radii
    plus Gaussian noise (std ``noise`` N m), fitted with N evenly spaced radii for every N in
    ``counts``. Returns a list of (N, TerrainFit)."""
    rng = np.random.default_rng(seed)
    tl, tr = circle_torques(vehicle, truth, PAPER_RADII)
    tl = tl + rng.normal(0.0, noise, tl.shape)
    tr = tr + rng.normal(0.0, noise, tr.shape)
    rows = []
    for n in counts:
        idx = np.unique(np.round(np.linspace(0, len(PAPER_RADII) - 1, n)).astype(int))
        rows.append((n, fit_terrain(vehicle, truth, PAPER_RADII[idx], tl[idx], tr[idx])))
    return rows


def fit_kinematics(t, wl, wr, x, y, yaw, r: float, width: float, mask=None, span_s: float = 1.0,
                   segment=None) -> dict:
    """Eq. 1 identified from a measured pose: the ICR factor alpha and a forward scale s
    in  v = s r (wl + wr) / 2,  yaw_rate = r (wr - wl) / (alpha B).

    Integral form, robust to a pose that is updated irregularly (scan matching holds its
    last value between updates, so differentiating it gives spikes; a held pose is
    dated at its update): the run is cut into
    spans of ``span_s`` [s] (aligned to t[0], within one ``segment``); over each span the
    measured heading change is compared with the integral of r (wr - wl) / B, and, on
    nearly straight spans (heading change < 0.1 rad), the distance between the span's end
    poses with the integral of r (wl + wr) / 2. Both are least-squares slopes through the
    origin, refitted without outliers (:func:`_trimmed_slope`). t [s], wheel speeds
    [rad/s], x, y [m], yaw [rad] (continuous) are equal-length arrays; ``mask`` selects
    the spans (by their first sample), e.g. the training part.

    Returns {"alpha", "v_scale", "yaw_rmse" [rad] and "dist_rmse" [m] per span (kept
    spans), "spans", "straight_spans", "kept" (fraction)}."""
    t, wl, wr, x, y, yaw = (np.asarray(a, float) for a in (t, wl, wr, x, y, yaw))
    seg = np.zeros(t.size) if segment is None else np.asarray(segment, float)
    k = np.floor((t - t[0]) / span_s).astype(int)
    dt = np.r_[np.diff(t), 0.0]
    uw = r * (wr - wl) / width
    uv = r * (wr + wl) / 2.0
    # a pose held between updates belongs to the time of its update: integrate between those
    _, upd = pose_updates(x, y, yaw)
    dyaw, iw, dist, iv = [], [], [], []
    starts = np.flatnonzero(np.r_[True, (np.diff(k) != 0) | (np.diff(seg) != 0)])
    ends = np.r_[starts[1:], t.size]
    for a, b in zip(starts, ends):
        if b - a < 3 or (mask is not None and not mask[a]):
            continue
        sl = slice(upd[a], upd[b - 1])      # integrate over the times of the two poses
        q = np.r_[yaw[a], yaw[b - 1], x[a], x[b - 1], y[a], y[b - 1]]
        iu = float(np.sum(uw[sl] * dt[sl]))
        iuv = float(np.sum(uv[sl] * dt[sl]))
        if not (np.all(np.isfinite(q)) and np.isfinite(iu) and np.isfinite(iuv)):
            continue
        dyaw.append(yaw[b - 1] - yaw[a])
        iw.append(iu)
        if abs(yaw[b - 1] - yaw[a]) < 0.1:
            dist.append(math.copysign(math.hypot(x[b - 1] - x[a], y[b - 1] - y[a]), iuv))
            iv.append(iuv)
    dyaw, iw, dist, iv = (np.array(a) for a in (dyaw, iw, dist, iv))
    if dyaw.size < 10 or float(np.dot(iw, dyaw)) <= 0.0 or dist.size < 5:
        raise ValueError(f"expected at least 10 spans with turning and 5 straight ones, found {dyaw.size} "
                         f"and {dist.size}")
    inv_alpha, kw = _trimmed_slope(iw, dyaw)
    sv, kv = _trimmed_slope(iv, dist)
    return {"alpha": 1.0 / inv_alpha, "v_scale": sv, "spans": int(dyaw.size), "straight_spans": int(dist.size),
            "yaw_rmse": float(np.sqrt(np.mean((dyaw - inv_alpha * iw)[kw] ** 2))),
            "dist_rmse": float(np.sqrt(np.mean((dist - sv * iv)[kv] ** 2))),
            "kept": float(min(kw.mean(), kv.mean()))}


def _trimmed_slope(u, y, rounds: int = 3, k: float = 4.0):
    """Least-squares slope of y = a u through the origin over the samples where u is
    not negligible, refitted without those beyond k robust standard deviations (1.4826
    MAD) of the residual (never more than half). Returns (a, mask of the samples kept)."""
    informative = np.abs(u) > 0.02 * float(np.max(np.abs(u)))      # spans with u ~ 0 say nothing of a
    u, y = u[informative], y[informative]
    keep = np.ones(u.size, bool)
    a = float(np.dot(u, y) / np.dot(u, u))
    for _ in range(rounds):
        e = y - a * u
        sd = max(1.4826 * float(np.median(np.abs(e - np.median(e)))), 1e-9 * float(np.sqrt(np.mean(y * y))), 1e-300)
        keep = np.abs(e) <= k * sd
        if keep.sum() < max(3, u.size // 2):        # never trim more than half
            keep = np.abs(e) <= np.quantile(np.abs(e), 0.5)
        a = float(np.dot(u[keep], y[keep]) / np.dot(u[keep], u[keep]))
    out = np.zeros(informative.size, bool)
    out[np.flatnonzero(informative)[keep]] = True
    return a, out


def fit_friction(vehicle: Vehicle, terrain: Terrain, wl, wr, tau_l, tau_r, magnitudes: bool = False) -> dict:
    """Eq. 28 on steady samples at any wheel speeds: the terrain's mu_roll, mu_sa and
    mu_op (shear modulus K and alpha kept) that minimise the squared differences between
    the steady resistance torques of eq. 22 at wheel speeds (wl, wr) [rad/s] and the
    measured torques tau_l, tau_r [N m]. With ``magnitudes`` the measurement is unsigned
    (motor currents logged without sign) and |tau| is compared. Returns {"terrain",
    "mu_roll", "mu_sa", "mu_op", "stderr", "rms" [N m], "n"}."""
    from .resistance import steady_resistance_fast
    wl, wr = np.asarray(wl, float), np.asarray(wr, float)
    meas = np.concatenate([np.asarray(tau_l, float), np.asarray(tau_r, float)])

    def model(p):
        ter = terrain.replace(mu_roll=p[0], mu_sa=p[1], mu_op=p[2])
        tl, tr = steady_resistance_fast(wl, wr, vehicle, ter)
        out = np.concatenate([tl, tr])
        return np.abs(out) if magnitudes else out

    x0 = np.array([terrain.mu_roll, terrain.mu_sa, terrain.mu_op])
    sol = least_squares(lambda p: model(p) - meas, x0, bounds=([0.0, 0.0, 0.0], [1.0, 5.0, 5.0]),
                        x_scale=[0.02, 0.1, 0.1])
    dof = max(1, len(meas) - 3)
    s2 = float(sol.fun @ sol.fun) / dof
    try:
        se = np.sqrt(np.abs(np.diag(np.linalg.inv(sol.jac.T @ sol.jac) * s2)))
    except np.linalg.LinAlgError:
        se = np.full(3, np.inf)
    p = sol.x
    return {"terrain": terrain.replace(mu_roll=float(p[0]), mu_sa=float(p[1]), mu_op=float(p[2])),
            "mu_roll": float(p[0]), "mu_sa": float(p[1]), "mu_op": float(p[2]),
            "stderr": [float(a) for a in se], "rms": float(np.sqrt(np.mean(sol.fun ** 2))), "n": int(wl.size)}
