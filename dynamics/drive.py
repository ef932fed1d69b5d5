"""The drive of one side: modified PID (Fig. 4), current-controlled motor controller
(eq. 27), DC motor (eq. 26), electrical power. Lumped at the wheel: k is the torque
constant and back-EMF constant at the wheel [N m/A = V s/rad]. Compiled with numba.
"""
from __future__ import annotations

from ._jit import jit


@jit
def pid_current(error, integral, ref_rate, kp, ki, kd):
    """Fig. 4, the modified PID: current command [A] = kp e + ki integral(e) + kd d(ref)/dt.

    The derivative acts on the reference (ref_rate [rad/s^2]), not on the error, so a
    step in the measured speed does not kick the output. e [rad/s], integral [rad].
    """
    return kp * error + ki * integral + kd * ref_rate


@jit
def motor_torque(voltage, omega, k, r_a):
    """Eq. 26, the DC motor torque-speed line tau/tau_s + w/w_s = 1 with tau_s = V k / R_a and
    w_s = V / k: tau = k (V - k w) / R_a [N m] for voltage V [V] and speed w [rad/s]."""
    return k * (voltage - k * omega) / r_a


@jit
def current_window(omega, v_max, k, r_a, i_max):
    """Eq. 27 (its one implementation): the currents [A] the drive can deliver at wheel
    speed omega [rad/s], the continuous limit |I| <= I_max intersected with the
    controller's voltage limit V_m,max = PWM (VCC - U_loss) - (dn/dtau) K_T I / K_n,
    i.e. |k w + R_a I| <= V_max [V] (the speed-torque gradient term is the armature drop
    R_a I: a driving motor's back-EMF is held below V_max - R_a |I|, a braking one's
    below V_max + R_a |I|).
    When the back-EMF alone exceeds V_max (over-speed) the window is the single current at
    the nearest voltage bound."""
    bemf = k * omega                  # eq. 26 at the voltage bounds, over k
    lo = (-v_max - bemf) / r_a
    hi = (v_max - bemf) / r_a
    if lo < -i_max:
        lo = -i_max
    if hi > i_max:
        hi = i_max
    if lo > hi:                       # back-EMF beyond the supply: voltage bound wins
        if omega > 0.0:
            lo = hi
        else:
            hi = lo
    return lo, hi


@jit
def window_share(current, omega, v_max, k, r_a, i_max):
    """The share [-] of the drive's reach (eq. 27's window at wheel speed omega [rad/s],
    :func:`current_window`) that a delivered current [A] uses in its own direction: 0 at
    no current, 1 at the bound (the continuous limit or the voltage bound); 1 also where
    the window holds no current of that sign (over-speed). A side at share s can still
    deliver 1 / s times its current: what a heavier vehicle, or one with more grip, would
    ask of it."""
    lo, hi = current_window(omega, v_max, k, r_a, i_max)
    if current > 0.0:
        return current / hi if hi > 0.0 else 1.0
    if current < 0.0:
        return current / lo if lo < 0.0 else 1.0
    return 0.0


@jit
def electrical_power(current, omega, k, r_a):
    """Electrical power drawn by one side [W]: P = R_a I^2 + k w I (copper loss plus
    mechanical power; negative when the side regenerates)."""
    return r_a * current * current + k * omega * current
