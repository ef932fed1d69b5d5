"""Terrain identification (paper eq. 28): K, mu_sa, mu_op from steady-state wheel torques.

The paper drove circles at N commanded radii and solved
    min_{K, mu_sa, mu_op} sum_i (d tau_lRes^(i))^2 + (d tau_rRes^(i))^2
with MATLAB's lsqnonlin; here scipy.optimize.least_squares (trust-region reflective, with
bounds) on the exact form of the resistance (eq. 22).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from .kinematics import wheel_speeds
from .params import Terrain, Vehicle
from .resistance import steady_resistance

#: The paper's 31 commanded radii [m]: 0.2..1 by 0.1, 2..10 by 1, 10^1.2..10^2,
#: 10^2.2..10^3.2 by 10^0.2, then 10^3.6 and 10^4.
PAPER_RADII = np.concatenate([
    np.round(np.arange(0.2, 1.01, 0.1), 10), np.arange(2.0, 11.0),
    10.0 ** np.arange(1.2, 2.01, 0.2), 10.0 ** np.arange(2.2, 3.21, 0.2), [10.0 ** 3.6, 1e4]])


def circle_torques(vehicle: Vehicle, terrain: Terrain, radii, speed: float = 0.2, **quad):
    """Steady-state (left, right) torques [N m] on counter-clockwise circles of commanded
    radii [m] at desired speed [m/s] (eq. 22 at the commanded wheel speeds: in steady state
    the PID's integral makes the wheels turn exactly as commanded)."""
    radii = np.asarray(radii, float)
    wl, wr = wheel_speeds(speed, 1.0 / radii, vehicle.wheel_radius, vehicle.width, 1.0)
    return steady_resistance(wl, wr, vehicle, terrain, **quad)


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
    radii = np.asarray(radii, float)
    meas = np.concatenate([np.asarray(tau_l, float), np.asarray(tau_r, float)])
    quad = dict(n_long=64, n_lat=8)

    def residual(p):
        ter = terrain.replace(shear_modulus=p[0] * 1e-3, mu_sa=p[1], mu_op=p[2])
        tl, tr = circle_torques(vehicle, ter, radii, speed, **quad)
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
