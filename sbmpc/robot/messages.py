"""What a robot measures and what the controller commands (:class:`Measurement`,
:class:`Command`), and the conversion between per-side wheel speeds and ``cmd_vel``.

Units are SI throughout: m, rad, s, rad/s for wheel speeds (positive forwards), A, V.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

import numpy as np

from dynamics import kernels as K

from ..errors import InputError
from ..problems import skidsteer as SS


@dataclass(frozen=True)
class Measurement:
    """One sample of what a robot knows about itself, at one time.

    Pose (from odometry or localisation, in the map's frame): ``x``, ``y`` [m], ``yaw``
    [rad]; required. Everything else is optional (None: not measured):

    * ``v`` [m/s], ``omega`` [rad/s]: the body twist (odometry); kept for the record,
      the estimator takes the wheel speeds where there are any;
    * ``wl``, ``wr`` [rad/s]: measured wheel speeds per side (joint states, a side's
      wheels averaged);
    * ``il``, ``ir`` [A]: each side's motor current at the wheel's torque constant (or
      ``tau_l``, ``tau_r`` [N m]: the joint efforts, a side's wheels summed); either
      pins the drive's PID integral;
    * ``voltage`` [V]: the battery's;
    * ``pitch``, ``roll`` [rad]: the body's attitude (an IMU's; pitch nose-up positive,
      roll as the map's ``pitch_roll`` gives it): where they show the ground steeper
      than the map says, the tip-over guard takes its limits that much lower;
    * ``stalled``: the drive's own stall protection tripped (a motor driver's fault
      flag); the controller also infers a stall from the wheel speeds.
    """

    x: float
    y: float
    yaw: float
    v: float | None = None
    omega: float | None = None
    wl: float | None = None
    wr: float | None = None
    il: float | None = None
    ir: float | None = None
    tau_l: float | None = None
    tau_r: float | None = None
    voltage: float | None = None
    pitch: float | None = None
    roll: float | None = None
    stalled: bool = False

    def currents(self, vehicle) -> tuple | None:
        """Each side's motor current (il, ir) [A]: as measured, or the efforts over the
        vehicle's torque constants; None where neither was measured."""
        if self.il is not None:
            return self.il, self.ir
        if self.tau_l is not None:
            return (self.tau_l / (vehicle.torque_constant * vehicle.torque_scale_left),
                    self.tau_r / (vehicle.torque_constant * vehicle.torque_scale_right))
        return None

    def checked(self, where: str = "measurement") -> "Measurement":
        """Itself; an InputError naming the field when the pose is missing or a value is
        not a finite number."""
        for f in fields(self):
            val = getattr(self, f.name)
            if f.name == "stalled":
                continue
            if val is None:
                if f.name in ("x", "y", "yaw"):
                    raise InputError(f"{where}: field '{f.name}': expected the pose (x, y, yaw), found none")
                continue
            if isinstance(val, (bool, np.bool_)) or not isinstance(val, numbers.Real) or not math.isfinite(val):
                raise InputError(f"{where}: field '{f.name}': expected a finite number, found {val!r:.40}")
        for a, b in (("wl", "wr"), ("il", "ir"), ("tau_l", "tau_r"), ("pitch", "roll")):
            if (getattr(self, a) is None) != (getattr(self, b) is None):
                both = "both" if a == "pitch" else "both sides"
                raise InputError(f"{where}: fields '{a}', '{b}': expected {both} or neither, found one")
        return self


@dataclass(frozen=True)
class Command:
    """What the controller commands for the next control period.

    ``wl``, ``wr`` [rad/s]: per-side wheel-speed references; ``v`` [m/s], ``omega``
    [rad/s]: the same as a ``cmd_vel`` Twist (:func:`to_twist`, with the vehicle's
    command track); ``status``: what the controller is doing (:data:`STATUSES`);
    ``plan_age_s``: how long ago the plan it comes from was made [s] (inf: none);
    ``done``: the run is over (reached, or stopped for good: ``reason`` says why).
    """

    wl: float
    wr: float
    v: float
    omega: float
    status: str
    plan_age_s: float = math.inf
    done: bool = False
    reason: str | None = None


STATUSES = {
    "planning": "the first plan is being made; the wheels are held at rest",
    "horizon": "driving a horizon plan (the next one is made while this period is driven)",
    "settling": "the wheels held at rest for a period: the horizon plan found no way on from a saturated drive",
    "waiting": "at rest, waiting for a plan from the measured state (off the prediction, stalled or held back)",
    "tracking": "driving a horizon plan that leads onto and along the whole-route plan made beside from the start "
                "(the horizon saw no way on or made no progress)",
    "whole-route": "following a whole-route plan (the horizon saw no way on or made no progress)",
    "held": "at rest: the guard held the period back (it would come within half the tip-over margin or leave the map)",
    "backing": "driving back along the way it came before it re-plans (the guard held back every way on)",
    "reached": "in the goal disc; the wheels are held at rest",
    "stopped": "stopped for good, and says why (reason)",
}


def measured(X: np.ndarray, vehicle, stalled: bool = False) -> Measurement:
    """What a robot measures of the simulated truth's state X: the pose, wheel speeds,
    currents and the battery voltage (:class:`sbmpc.robot.Measurement`); ``stalled``: the
    drive's stall protection tripped."""
    return Measurement(float(X[K.S_X]), float(X[K.S_Y]), float(X[K.S_YAW]),
                       v=float(X[SS.X_V]) if len(X) > SS.X_V else None,
                       wl=float(X[K.S_WL]), wr=float(X[K.S_WR]), il=float(X[K.S_IL]), ir=float(X[K.S_IR]),
                       voltage=float(vehicle.v_max), stalled=stalled)


def to_twist(wl: float, wr: float, vehicle) -> tuple:
    """(v [m/s], omega [rad/s]) of per-side wheel speeds, as a differential-drive
    controller computes them: v = r (wl + wr) / 2, omega = r (wr - wl) / B with B the
    vehicle's command track (``Vehicle.command_track``: the driver's wheel separation
    times its separation multiplier)."""
    r, B = vehicle.wheel_radius, vehicle.command_track
    return 0.5 * r * (wl + wr), r * (wr - wl) / B


def to_wheels(v: float, omega: float, vehicle) -> tuple:
    """(wl, wr) [rad/s] of a twist (v [m/s], omega [rad/s]): the inverse of :func:`to_twist`."""
    r, B = vehicle.wheel_radius, vehicle.command_track
    return (v - 0.5 * B * omega) / r, (v + 0.5 * B * omega) / r


__all__ = ["Measurement", "Command", "STATUSES", "measured", "to_twist", "to_wheels"]
