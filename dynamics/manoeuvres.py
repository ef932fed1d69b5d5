"""Command sequences for the paper's test manoeuvres, ready for :func:`simulate`.

Each returns (cmd_l, cmd_r) arrays of desired wheel speeds [rad/s], one per step dt [s].
"""
from __future__ import annotations

import numpy as np

from .kinematics import wheel_speeds
from .params import ParameterError, checked_number
from .simulate import Model, check_step, simulate


def _steps(model: Model, duration: float, dt: float | None) -> tuple[float, int]:
    """(dt [s], number of steps) of a manoeuvre ``duration`` [s] long, both checked."""
    dt = model.step_s if dt is None else check_step(dt)
    duration = checked_number("duration", duration, "a number of seconds in [0, 1e6]", 0.0, 1e6)
    return dt, int(round(duration / dt))


def straight(model: Model, v: float, duration: float, dt: float | None = None):
    """Straight line at desired speed v [m/s]."""
    dt, n = _steps(model, duration, dt)
    w = v / model.vehicle.wheel_radius
    return np.full(n, w), np.full(n, w)


def circle(model: Model, v: float, radius: float, duration: float, dt: float | None = None):
    """Circle of *commanded* radius [m] (paper Section V: the radius the wheel speeds give
    through the no-slip kinematic model, eq. 1 with alpha = 1) at desired speed v [m/s].
    Positive radius turns left (counter-clockwise); an infinite one drives straight."""
    dt, n = _steps(model, duration, dt)
    if not (isinstance(radius, (int, float, np.number)) and not isinstance(radius, bool) and radius != 0.0
            and radius == radius):
        raise ParameterError(f"radius: expected a non-zero radius in metres (positive turns left, inf drives "
                             f"straight), found {radius!r:.40}")
    veh = model.vehicle
    wl, wr = wheel_speeds(float(v), 1.0 / float(radius), veh.wheel_radius, veh.width, 1.0)
    return np.full(n, wl), np.full(n, wr)


def lemniscate_path(t):
    """Eqs. 29, 30: the paper's lemniscate X(t) = 9 cos(t/50) / (1 + sin^2(t/50)),
    Y(t) = 27 sin(t/50) cos(t/50) / (1 + sin^2(t/50)) [m] at time t [s]."""
    s, c = np.sin(t / 50.0), np.cos(t / 50.0)
    d = 1.0 + s * s
    return 9.0 * c / d, 27.0 * s * c / d


def lemniscate_reference(t):
    """Desired linear speed v [m/s], curvature [1/m] and heading [rad] along eqs. 29, 30 at
    times t [s] (the derivatives of eqs. 29, 30 by central differences of 1 ms)."""
    h = 1e-3
    x0, y0 = lemniscate_path(t - h)
    x1, y1 = lemniscate_path(t)
    x2, y2 = lemniscate_path(t + h)
    dx, dy = (x2 - x0) / (2 * h), (y2 - y0) / (2 * h)
    ddx, ddy = (x2 - 2 * x1 + x0) / h ** 2, (y2 - 2 * y1 + y0) / h ** 2
    speed = np.hypot(dx, dy)
    return speed, (dx * ddy - dy * ddx) / speed ** 3, np.arctan2(dy, dx)


def lemniscate(model: Model, t0: float = 0.0, duration: float = 18.0, run_up: float = 3.0,
               dt: float | None = None):
    """The paper's Section V-C test: accelerate at the reference rate limit to the initial
    speed during ``run_up`` seconds, then follow eqs. 29, 30 from time t0 for ``duration``
    seconds through the inverse kinematic model with the terrain's alpha (Fig. 8)."""
    dt, n = _steps(model, duration, dt)
    veh = model.vehicle
    t = t0 + np.arange(max(n, 1)) * dt          # (at least one step: a duration under dt/2 rounds to none)
    v, kappa, _ = lemniscate_reference(t)
    wl, wr = wheel_speeds(v, kappa, veh.wheel_radius, veh.width, model.terrain.alpha)
    n_up = int(round(run_up / dt))
    return (np.concatenate([np.full(n_up, wl[0]), wl]), np.concatenate([np.full(n_up, wr[0]), wr]))


def ramp_profile(slope_deg: float, length: float, step: float = 0.01):
    """Pitch profile [rad] of a straight ramp of grade ``slope_deg`` and ``length`` [m]
    starting at path distance 0, sampled every ``step`` m (flat before and after)."""
    n = max(1, int(np.ceil(length / step)))
    return np.full(n, np.radians(slope_deg))


def ramp_run(model: Model, v: float, v0: float, slope_deg: float, length: float,
             duration: float = 20.0, dt: float | None = None):
    """The paper's hill-climbing test (Figs. 18-20): enter a straight ramp of grade
    ``slope_deg`` and ``length`` [m] at speed v0 [m/s] (drive in steady state on the flat),
    commanded to speed v [m/s]. Returns (trajectory, crossed, time to the top or None)."""
    dt = model.step_s if dt is None else dt
    w0 = v0 / model.vehicle.wheel_radius
    cmd_l, cmd_r = straight(model, v, duration, dt)
    traj = simulate(model, cmd_l, cmd_r, state=model.state(w0, w0), profile=ramp_profile(slope_deg, length),
                    profile_start=0.0, profile_step=0.01, dt=dt)
    over = np.nonzero(traj.s >= length)[0]
    crossed = over.size > 0
    return traj, crossed, (float(traj.t[over[0]]) if crossed else None)
