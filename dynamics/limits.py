"""What the drive can do, from the model's equations: grades and speeds.

Straight motion at constant speed needs, per side (eqs. 24, 25 with q'' = 0 and no
sliding friction), tau = r m g (sin beta + mu_roll cos beta) / 2 + c_visc w, while the
drive delivers at most min(k I_max, k (V_max - k w) / R_a) (eqs. 26, 27).
"""
from __future__ import annotations

import math

from scipy.optimize import brentq

from .drive import current_window
from .params import G, Terrain, Vehicle, checked_number


def available_torque(vehicle: Vehicle, omega: float) -> float:
    """Largest torque [N m] of one side at wheel speed omega >= 0 [rad/s]: k times the top
    of the current window (eq. 27 and the continuous current limit,
    :func:`dynamics.drive.current_window`; past the no-load speed it is negative)."""
    v = vehicle
    omega = checked_number("omega", omega, "a number in [0, inf] rad/s", 0.0)
    k = v.torque_constant
    return k * current_window(omega, v.v_max, k, v.armature_resistance, v.current_limit)[1]


def required_torque(vehicle: Vehicle, terrain: Terrain, grade: float, omega: float) -> float:
    """Torque [N m] of one side that holds wheel speed omega [rad/s] straight up a grade [rad]
    (the drive's own friction with it: the viscous term and, climbing at any speed, the
    motors' no-load current at the nominal torque constant: a symmetric drive)."""
    v = vehicle
    return (v.wheel_radius * v.mass * G * (math.sin(grade) + terrain.mu_roll * math.cos(grade)) / 2.0
            + v.viscous * omega + v.torque_constant * v.no_load_current)


def steepest_grade(vehicle: Vehicle, terrain: Terrain, speed: float = 0.0) -> float:
    """Steepest grade [rad] on which ``speed`` [m/s] can be held straight uphill (at speed 0:
    the steepest grade climbable at any constant speed). Negative if none; pi/2 when the
    drive holds it even straight up a wall (a light or strong vehicle: the grade then does
    not limit it, tipping over and wheel grip do)."""
    omega = checked_number("speed", speed, "a number in [0, inf] m/s", 0.0) / vehicle.wheel_radius
    tau = available_torque(vehicle, omega)
    if tau <= required_torque(vehicle, terrain, 0.0, omega):
        return -1.0
    # sin b + mu cos b, what the grade asks, is largest at tan b = 1 / mu (short of 90 deg)
    peak = math.atan2(1.0, terrain.mu_roll)
    if tau >= required_torque(vehicle, terrain, peak, omega):
        return 0.5 * math.pi
    # the one root lies below the peak; bracketed by 90 deg where the wall is also too steep
    # (the bracket the root finder always had: its last digits, and the plans, stay as they were)
    top = 0.5 * math.pi if tau < required_torque(vehicle, terrain, 0.5 * math.pi, omega) else peak
    return brentq(lambda b: required_torque(vehicle, terrain, b, omega) - tau, 0.0, top)


def steepest_braked_grade(vehicle: Vehicle, terrain: Terrain, omega: float) -> float:
    """Steepest downhill grade [rad, <= 0] on which the drive holds wheel speed omega
    [rad/s] straight down, braking at most its continuous torque (eqs. 24, 25 with
    q'' = 0, the braking torque -required_torque); -pi/2 if it holds it on any."""
    brake = lambda b: -required_torque(vehicle, terrain, b, omega) - vehicle.continuous_torque
    return -0.5 * math.pi if brake(-0.5 * math.pi) <= 0.0 else brentq(brake, -0.5 * math.pi, 0.0)


def top_speed(vehicle: Vehicle, terrain: Terrain, grade: float = 0.0) -> float:
    """Highest constant straight speed [m/s] on a grade [rad]; 0 if the grade cannot be held,
    the no-load speed's when gravity down a slope pulls harder than the drive's losses."""
    grade = checked_number("grade", grade, "a number in [-1.5708, 1.5708] rad", -0.5 * math.pi, 0.5 * math.pi)
    f = lambda w: available_torque(vehicle, w) - required_torque(vehicle, terrain, grade, w)
    w_hi = vehicle.no_load_speed
    if f(0.0) <= 0.0:
        return 0.0
    if f(w_hi) >= 0.0:
        return w_hi * vehicle.wheel_radius
    return brentq(f, 0.0, w_hi) * vehicle.wheel_radius


def holds_turn(vehicle: Vehicle, terrain: Terrain, wl: float, wr: float, margin: float = 1.0) -> bool:
    """Whether the drive holds wheel speeds (wl, wr) [rad/s] in a steady turn on level
    ground: eq. 22's steady resistance of each side, times ``margin``, within what the
    drive delivers at that side's speed (eqs. 26, 27 and the current limit)."""
    from .resistance import drive_friction, steady_resistance
    tl, tr = steady_resistance(wl, wr, vehicle, terrain)
    tl = tl + drive_friction(vehicle, wl, 0)
    tr = tr + drive_friction(vehicle, wr, 1)
    return (margin * abs(tl) <= available_torque(vehicle, abs(wl))
            and margin * abs(tr) <= available_torque(vehicle, abs(wr)))


TURN_RADII = (0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 7.5, 10.0, 15.0, 20.0, 30.0, 50.0, 75.0, 100.0, 150.0, 200.0)


def tightest_turn(vehicle: Vehicle, terrain: Terrain, speeds=(0.3, 0.6, 1.0)) -> float:
    """Smallest turning radius [m] of TURN_RADII (0: a pivot) that the vehicle holds at a
    constant speed of ``speeds`` [m/s] on level ground: eq. 22's steady resistance of
    each side (sliding friction of the turn plus rolling) within what its drive delivers
    (eqs. 26, 27 and the current limit). ``inf`` when no radius up to 200 m can be held:
    the drive saturates in any steady turn (a heavy vehicle on a grippy surface)."""
    from .kinematics import wheel_speeds
    r = vehicle.wheel_radius
    for R in TURN_RADII:
        for v in speeds:
            if R == 0.0:
                w = v / r
                wl, wr = -w, w
            else:
                wl, wr = wheel_speeds(v, 1.0 / R, r, vehicle.width, terrain.alpha)
            if max(abs(wl), abs(wr)) > vehicle.no_load_speed:
                continue
            if holds_turn(vehicle, terrain, wl, wr):
                return R
    return math.inf
