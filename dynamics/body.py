"""Rigid-body terms of the wheel-space dynamics M q'' + C(q, q') + G(q) = tau (eq. 4).

q = (theta_l, theta_r) are the wheel angles [rad]; torques are per side at the wheel [N m].
Compiled with numba; scalar arguments.
"""
from __future__ import annotations

import math

from ._jit import jit


@jit
def mass_matrix(mass, inertia, r, width, alpha):
    """Eq. 5: the symmetric mass matrix M [kg m^2], returned as (M11, M12) with M22 = M11,
    M21 = M12: M11 = m r^2 / 4 + r^2 I / (alpha B^2), M12 = m r^2 / 4 - r^2 I / (alpha B^2)."""
    a = mass * r * r / 4.0
    c = r * r * inertia / (alpha * width * width)
    return a + c, a - c


@jit
def gravity_torque(mass, g, r, pitch):
    """Eq. 24: gravity torque of each side, G = m g r sin(beta) / 2 [N m], for the pitch
    beta [rad] of the vehicle's heading (positive nose up: climbing costs torque)."""
    return slope_gravity_torque(mass, g, r, math.sin(pitch))


@jit
def slope_gravity_torque(mass, g, r, sin_pitch):
    """Eq. 24 with the pitch given by its sine: G = m g r sin(beta) / 2 [N m] (the
    planner's edges have the slope as a grade, not as an angle)."""
    return mass * g * r * sin_pitch / 2.0


@jit
def wheel_accelerations(m11, m12, tau_l, tau_r, res_l, res_r, grav):
    """Eqs. 23 (planar, grav = 0) and 25 (linear 3-D): solve M q'' = tau - C - G for the
    wheel accelerations (q''_l, q''_r) [rad/s^2]."""
    bl = tau_l - res_l - grav
    br = tau_r - res_r - grav
    det = m11 * m11 - m12 * m12
    return (m11 * bl - m12 * br) / det, (m11 * br - m12 * bl) / det


@jit
def newton_step(m11, m12, j_ll, j_lr, j_rl, j_rr, res_l, res_r, dt):
    """The Newton correction of an implicit step of eq. 25: solve (M + dt J) dw = -res
    [rad/s] for a residual res [N m s] of M (w - w0) - dt (tau - C - G), J [N m s/rad]
    the slope of the speed-dependent torques. With J = 0 and the residual taken at w0 it
    is dt times :func:`wheel_accelerations` (explicit Euler).

    A dissipative J (positive semi-definite symmetric part) can only make M + dt J better
    conditioned than M. Near standstill the tabulated friction's cross slopes can break
    that (det(M + dt J) < det M, up to a singular matrix and a blow-up); the step then
    keeps only the non-negative diagonal of J, which is always stable."""
    a11 = m11 + dt * j_ll
    a12 = m12 + dt * j_lr
    a21 = m12 + dt * j_rl
    a22 = m11 + dt * j_rr
    det = a11 * a22 - a12 * a21
    if det < m11 * m11 - m12 * m12:
        a11 = m11 + dt * max(j_ll, 0.0)
        a22 = m11 + dt * max(j_rr, 0.0)
        a12 = m12
        a21 = m12
        det = a11 * a22 - a12 * a21
    inv = 1.0 / det
    return (a12 * res_r - a22 * res_l) * inv, (a21 * res_l - a11 * res_r) * inv
