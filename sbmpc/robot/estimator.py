"""The model's state from what a robot measures (:class:`Estimator`).

A plan starts from the planner's state (:mod:`sbmpc.problems.skidsteer`: the closed-loop
model's 35 numbers, the wrapped heading and speed, the margin's twin): the pose, but also
the drive's loop states (wheel speeds, the rate-limited references, the PID integrals,
currents) that decide what the next second does. A robot measures some of them. The
estimator is a predictor corrected by measurement:

1. **Predict**: from the last estimate, the planning vehicle's closed-loop model (at its
   controller rate, the paper's 1 kHz) driven by the commands the controller issued
   since, up to the measurement's time (late by the vehicle's ``delay``, where it has one). This carries what no sensor gives: the
   references (the commands, rate-limited as the drive limits them), the stall timer,
   the friction's shear state.
2. **Correct** with what was measured: the pose (x, y, yaw; z, pitch and roll from the
   map: the map is the truth about the ground); the wheel speeds where joint states
   give them; each side's current (or effort / torque constant) where logged, which
   pins the PID integral (current = kp (ref - w) + ki integral + kd d(ref)/dt: a measured
   current off the predicted one moves the integral by the difference over ki) unless the
   drive is at a bound of its window (eq. 27: the current limit, and at speed the voltage
   limit), or its current lags (``Vehicle.lag``), where the integral is not observable and
   the prediction's is kept.

Assumptions, stated: the map frame of the pose is the map's; the wheels of a side turn
together (a side's joints averaged); without wheel speeds, the drive tracks its commands
as the model predicts (the prediction's speeds are kept); without currents, the
integrals are the prediction's. A stalled drive (``Measurement.stalled``, or inferred by
the controller) restarts from the measured speeds: references at the speeds, stall timer
cleared, as a drive's stall protection does.
"""
from __future__ import annotations

import math

import numpy as np

from dynamics import kernels as K
from dynamics.drive import current_window

from ..errors import InputError
from ..execution import Executor, protected
from ..planning import world as WO
from ..problems import skidsteer as SS
from .messages import Measurement


class Estimator:
    """The planner state of one world's vehicle from measurements (module doc).

    ``world``: the planning world (its vehicle predicts; its map gives z); ``cost``:
    'time' or 'energy' (the packed model's cost column). :meth:`reset` places it at a
    first measurement; :meth:`update` predicts through the commands issued since and
    corrects."""

    def __init__(self, world: WO.World, cost: str):
        self.world = world
        self.model = Executor(world, cost, world.vehicle.delay)   # a calibrated command delay: the drive gets the commands late
        self.X = None              # the estimate (planner state, SS.NX)
        self.stalled_now = False   # the last update found the drive stalled (and restarted it)
        self.t0 = None             # robot time of the first measurement [s]

    def planner_time(self, t: float) -> float:
        """The planner's time [s] (0 at the first measurement) of robot time t [s]."""
        return float(t - self.t0)

    def reset(self, t: float, m: Measurement) -> np.ndarray:
        """The estimate at a first measurement: the vehicle steady at its measured wheel
        speeds (at rest where none are measured) on the map's grade under it."""
        self._on_map(m)
        wl = m.wl if m.wl is not None else 0.0
        wr = m.wr if m.wr is not None else 0.0
        self.t0 = float(t)
        self.X = WO.steady_state(self.world, m.x, m.y, m.yaw, wl, wr, 0.5 * self.world.vehicle.wheel_radius * (wl + wr))
        return self._correct(m, self.X)

    def update(self, t: float, m: Measurement, issued: list) -> np.ndarray:
        """The estimate at robot time ``t`` [s]: predicted through ``issued`` [(wl, wr,
        duration_s)] (the commands since the last estimate, in order), corrected by ``m``."""
        if self.X is None:
            return self.reset(t, m)
        X = self.X
        for wl, wr, d in issued:
            if d <= 0.0:
                continue
            # a prediction cut short (it stalled, tipped or left the map in the model) is
            # taken where it ended: the measurement says where the vehicle is
            _, _, X = self.model.step(X, (wl, wr, d), record=False)
        X = X.copy()
        X[K.S_T] = self.planner_time(t)
        return self._correct(m, X)

    def _restarted(self, X: np.ndarray) -> None:
        """X after the drive's stall protection restarted it from the measured (else
        estimated) wheel speeds (:func:`sbmpc.execution.protected`), its stall test's
        window begun again."""
        protected(X, self.model)
        X[K.S_SWT] = 0.0

    def _on_map(self, m: Measurement) -> None:
        e = self.world.emap
        if not e.contains(m.x, m.y):
            x0, x1, y0, y1 = e.extent
            raise InputError(f"measurement: pose ({m.x:.2f}, {m.y:.2f}): expected a position on the map "
                             f"(x {x0:g}..{x1:g} m, y {y0:g}..{y1:g} m), found one off it")

    def _correct(self, m: Measurement, X: np.ndarray) -> np.ndarray:
        w = self.world
        v = w.vehicle
        self._on_map(m)
        X[K.S_X], X[K.S_Y], X[K.S_YAW] = m.x, m.y, m.yaw
        X[K.S_Z] = w.emap.height(m.x, m.y)
        X[SS.X_YAWW] = math.atan2(math.sin(m.yaw), math.cos(m.yaw))
        w_pred = (X[K.S_WL], X[K.S_WR])
        if m.wl is not None:
            X[K.S_WL], X[K.S_WR] = m.wl, m.wr
        currents = m.currents(v)
        if currents is not None and v.ki > 0.0 and v.lag == 0.0:
            for side, cur in enumerate(currents):
                wk, rk, ik, ck = ((K.S_WL, K.S_REFL, K.S_INTL, K.S_IL), (K.S_WR, K.S_REFR, K.S_INTR, K.S_IR))[side]
                # the delivered current is the PID's only inside the drive's window (eq. 27:
                # the current limit and, at speed, the voltage limit): at either bound the
                # integral is not observed
                k_side = v.torque_constant * (v.torque_scale_left, v.torque_scale_right)[side]
                lo, hi = current_window(float(X[wk]), v.v_max, k_side, v.armature_resistance, v.current_limit)
                tol = 0.02 * max(v.current_limit, abs(lo), abs(hi))
                inside = lo + tol < cur < hi - tol and lo + tol < X[ck] < hi - tol
                if inside:
                    # the PID's output is kp e + ki integral + kd d(ref)/dt: what the measured
                    # current differs from the predicted one by, less what the measured
                    # speed's error explains, is the integral's error (the gains are known)
                    X[ik] += (cur - X[ck] + v.kp * (X[wk] - w_pred[side])) / v.ki
                X[ck] = cur
        X[SS.X_V] = 0.5 * v.wheel_radius * (X[K.S_WL] * v.radius_scale_left + X[K.S_WR] * v.radius_scale_right)
        # a stall: the measurement says so (a driver's fault flag), or the model's stall test
        # on the estimate does
        self.stalled_now = bool(m.stalled or X[K.S_STALLED])
        if self.stalled_now:
            self._restarted(X)
        X[SS.X_TW:SS.X_TW + K.NS] = X[:K.NS]
        self.X = X
        return X.copy()


__all__ = ["Estimator"]
