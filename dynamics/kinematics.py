"""Terrain-dependent kinematics of a skid-steered vehicle (paper Section II, Fig. 8).

Wheel speeds are in rad/s, linear speeds in m/s, yaw rates in rad/s, lengths in m.
A positive yaw rate (and a positive turning radius) is a left turn: right wheels faster.
Every function is compiled with numba and works on floats (and on NumPy arrays when
called from Python).
"""
from __future__ import annotations

from ._jit import jit


@jit
def alpha_model(wl, wr, r, width, alpha):
    """Eq. 1, the ICR ("alpha") kinematic model: wheel speeds -> body velocities.

    v = r (wl + wr) / 2 [m/s], yaw_rate = r (wr - wl) / (alpha B) [rad/s].
    A skid-steered vehicle of width B behaves like a differential drive of width alpha B;
    alpha = 1 is rolling without slip.
    """
    return r * (wl + wr) / 2.0, r * (wr - wl) / (alpha * width)


@jit
def slip_model(wl, wr, il, ir, r, width):
    """Eq. 2, the slip-ratio kinematic model: wheel speeds and slip ratios -> (v, yaw_rate).

    v = r (wl (1 - il) + wr (1 - ir)) / 2, yaw_rate = r (-wl (1 - il) + wr (1 - ir)) / B,
    with the longitudinal slip ratio i = (r w - v_actual) / (r w) of each side (unitless).
    """
    vl = r * wl * (1.0 - il)
    vr = r * wr * (1.0 - ir)
    return (vl + vr) / 2.0, (vr - vl) / width


@jit
def slip_ratios_for_alpha(wl, wr, alpha):
    """Eq. 3: slip ratios (il, ir) under which eq. 2 equals eq. 1 for the given alpha.

    Eq. 3 requires il / ir = -wr / wl and alpha = 1 / (1 - 2 il ir / (il + ir)); solving both
    gives il = -wr c, ir = wl c with c = (1 - 1/alpha) (wr - wl) / (2 wl wr).
    Undefined (division by zero) when a wheel is at rest.
    """
    c = (1.0 - 1.0 / alpha) * (wr - wl) / (2.0 * wl * wr)
    return -wr * c, wl * c


@jit
def alpha_from_slip_ratios(il, ir):
    """Eq. 3, right-hand part: alpha = 1 / (1 - 2 il ir / (il + ir)) (unitless)."""
    return 1.0 / (1.0 - 2.0 * il * ir / (il + ir))


@jit
def wheel_speeds(v, curvature, r, width, alpha):
    """Inverse of eq. 1 (paper Fig. 8): desired v [m/s] and path curvature 1/rho [1/m]
    -> desired wheel speeds (wl, wr) [rad/s].

    wl = v/r (1 - alpha B kappa / 2), wr = v/r (1 + alpha B kappa / 2). With alpha = 1 the
    curvature is the paper's *commanded* one (no-slip model, as in the definition of the
    commanded turning radius of Section V); with the terrain's alpha it is the curvature
    the vehicle actually drives.
    """
    half = alpha * width * curvature / 2.0
    return v / r * (1.0 - half), v / r * (1.0 + half)


@jit
def commanded_curvature(wl, wr, width):
    """Curvature [1/m] of the commanded radius (Section V): the no-slip model of wheel
    speeds, 1/R = 2 (wr - wl) / (B (wr + wl)). Infinite for a point turn."""
    return 2.0 * (wr - wl) / (width * (wr + wl))
