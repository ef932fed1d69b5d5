"""Closed-loop and open-loop rollouts (paper Fig. 3) in plain Python around the kernels.

:class:`Model` is the small immutable system object (a vehicle on a terrain with its
packed arrays); :func:`simulate` runs it over command sequences and returns a
:class:`Trajectory` of NumPy arrays.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from . import kernels as K
from .params import Terrain, Vehicle, load_terrain, load_vehicle
from .resistance import drive_friction, friction_table, steady_resistance_fast
from .body import gravity_torque
from .params import G, checked_number


def check_step(dt, what: str = "dt") -> float:
    """``dt`` [s] as a float when it is an integration step the model can take: positive,
    finite, at most 1 s; else a ParameterError naming ``what``."""
    return checked_number(what, dt, "an integration step in (0, 1] s", 0.0, 1.0, lo_open=True)


@dataclass(frozen=True)
class Model:
    """A vehicle on a terrain: the closed-loop model of the paper, ready to simulate.

    ``dt`` is the default integration step [s]; the default is the controller period
    (1 ms for the P3-AT), which reproduces the paper's digital PID exactly.
    """

    vehicle: Vehicle = field(default_factory=Vehicle)
    terrain: Terrain = field(default_factory=Terrain)
    dt: float | None = None

    def __post_init__(self):
        from .params import ParameterError
        for name, cls in (("vehicle", Vehicle), ("terrain", Terrain)):
            if not isinstance(getattr(self, name), cls):
                raise ParameterError(f"Model.{name}: expected a {cls.__name__} (dynamics.load_{name}), "
                                     f"found {type(getattr(self, name)).__name__}")
        if self.dt is not None:
            check_step(self.dt, "Model.dt")

    @classmethod
    def load(cls, vehicle="p3at", terrain="vinyl", dt=None) -> "Model":
        """A model from shipped names or paths of parameter files."""
        return cls(load_vehicle(vehicle), load_terrain(terrain), dt)

    @property
    def step_s(self) -> float:
        return self.dt if self.dt is not None else 1.0 / self.vehicle.controller_rate

    @cached_property
    def P(self) -> np.ndarray:
        return K.pack(self.vehicle, self.terrain)

    @cached_property
    def table(self) -> np.ndarray:
        # a writable copy of the shared (read-only) table: numba types a read-only array
        # apart, and compiled the model's step once more for it than the planner's
        # (writable) tables need (K.CHECK: a fresh clone's first compile)
        return np.array(friction_table(self.vehicle, self.terrain))

    def with_(self, vehicle: Vehicle | None = None, terrain: Terrain | None = None, dt=None) -> "Model":
        return Model(vehicle or self.vehicle, terrain or self.terrain, dt if dt is not None else self.dt)

    # ------------------------------------------------------------------------------
    def state(self, wl: float = 0.0, wr: float | None = None, pitch: float = 0.0,
              x: float = 0.0, y: float = 0.0, yaw: float = 0.0, z: float = 0.0,
              steady: bool = True) -> np.ndarray:
        """A state vector (length NS) at wheel speeds (wl, wr) [rad/s] and pose.

        With ``steady`` the controller is in steady state at those speeds on that pitch:
        the references equal the speeds and the integrals hold the current that balances
        resistance and gravity, so that a constant command keeps the state constant.
        """
        wr = wl if wr is None else wr
        for name, value in (("wl", wl), ("wr", wr), ("x", x), ("y", y), ("yaw", yaw), ("z", z)):
            checked_number(name, value, "a finite number")
        checked_number("pitch", pitch, "a grade in [-pi/2, pi/2] rad", -np.pi / 2, np.pi / 2)
        S = np.zeros(K.NS)
        S[K.S_WL], S[K.S_WR] = wl, wr
        S[K.S_REFL], S[K.S_REFR] = wl, wr
        S[K.S_X], S[K.S_Y], S[K.S_Z], S[K.S_YAW] = x, y, z, yaw
        if steady and (wl != 0.0 or wr != 0.0):
            v = self.vehicle
            tl, tr = steady_resistance_fast(wl, wr, v, self.terrain, pitch)
            g = gravity_torque(v.mass, G, v.wheel_radius, pitch)     # (times each side's radius scale)
            il = (float(tl) + g * v.radius_scale_left + float(drive_friction(v, wl, 0))) / (
                v.torque_constant * v.torque_scale_left)
            ir = (float(tr) + g * v.radius_scale_right + float(drive_friction(v, wr, 1))) / (
                v.torque_constant * v.torque_scale_right)
            S[K.S_IL], S[K.S_IR] = il, ir
            if v.ki > 0:
                S[K.S_INTL], S[K.S_INTR] = il / v.ki, ir / v.ki
        return S


@dataclass(frozen=True)
class Trajectory:
    """A simulated run: arrays of equal length, SI units, one row per recorded instant.

    ``t`` s, ``x y z`` m, ``yaw`` rad, ``v`` m/s (along the surface), ``yaw_rate`` rad/s,
    ``wl wr`` rad/s, ``tau_l tau_r`` N m, ``i_l i_r`` A, ``power_W`` battery power,
    ``energy_J`` cumulative, ``pitch`` rad, ``ref_l ref_r`` rad/s (the rate-limited
    references), ``s`` m (signed distance along the path). ``stalled`` tells whether the
    drive saturated without achieving the commanded motion for 0.25 s.
    """

    data: dict
    stalled: bool
    final_state: np.ndarray

    def __getattr__(self, name):
        try:
            return self.__dict__["data"][name]
        except KeyError:
            raise AttributeError(name) from None

    def __len__(self):
        return len(self.data["t"])

    def to_json(self) -> dict:
        """The ``trajectory`` object of the plan/simulate JSON (docs/formats.md)."""
        keys = ("t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r",
                "power_W", "energy_J")
        return {k: [round(float(x), 6) for x in self.data[k]] for k in keys}


def simulate(model: Model, cmd_l, cmd_r, *, state=None, pitch=0.0, profile=None,
             profile_start: float = 0.0, profile_step: float = 0.01, open_loop: bool = False,
             record_dt: float = 0.01, dt: float | None = None) -> Trajectory:
    """Roll the model out over per-step commands.

    cmd_l, cmd_r: arrays (n,) of desired wheel speeds [rad/s] (closed loop) or current
    commands [A] (``open_loop``), one per step of ``dt`` (default ``model.step_s``).
    pitch: constant [rad] or an array (n,) per step; or ``profile``: pitch [rad] sampled
    every ``profile_step`` m of signed path distance from ``profile_start`` (flat outside).
    The vehicle's ``delay`` extension shifts the commands by round(delay / dt) steps.
    """
    from .params import ParameterError
    dt = model.step_s if dt is None else check_step(dt)
    cmd_l, cmd_r = _finite_array(cmd_l, "cmd_l"), _finite_array(cmd_r, "cmd_r")
    if cmd_l.shape != cmd_r.shape or cmd_l.ndim != 1:
        raise ParameterError(f"cmd_l, cmd_r: expected 1-D arrays of equal length, found shapes {cmd_l.shape} "
                             f"and {cmd_r.shape}")
    S = model.state() if state is None else _finite_array(state, "state").copy()
    if S.shape != (K.NS,):
        raise ParameterError(f"state: expected a model state of {K.NS} numbers (Model.state), found shape {S.shape}")
    n = len(cmd_l)
    if profile is not None:
        if np.any(np.asarray(pitch, float) != 0.0):
            raise ParameterError("pitch, profile: expected one of them (a profile sets the pitch along the path), "
                                 "found both")
        profile = _finite_array(profile, "profile")
        if profile.ndim != 1:
            raise ParameterError(f"profile: expected a 1-D array of pitches [rad], found shape {profile.shape}")
        checked_number("profile_step", profile_step, "a positive finite distance in metres", 0.0, lo_open=True)
        checked_number("profile_start", profile_start, "a finite distance in metres")
    else:
        p = _finite_array(pitch, "pitch")
        if p.shape not in ((), (n,)):
            raise ParameterError(f"pitch: expected one grade [rad] or one per command ({n}), found shape {p.shape}")
        if np.any(np.abs(p) > np.pi / 2):
            raise ParameterError(f"pitch: expected grades in [-pi/2, pi/2] rad, found {float(np.max(np.abs(p))):.4g} "
                                 "(in degrees? radians are expected)")
    checked_number("record_dt", record_dt, "a positive recording interval in seconds", 0.0, lo_open=True)
    lag_steps = int(round(model.vehicle.delay / dt))
    if lag_steps > 0:
        hold_l = S[K.S_IL] if open_loop else S[K.S_REFL]
        hold_r = S[K.S_IR] if open_loop else S[K.S_REFR]
        cmd_l = np.concatenate([np.full(lag_steps, hold_l), cmd_l])[:n]
        cmd_r = np.concatenate([np.full(lag_steps, hold_r), cmd_r])[:n]
    pitch_t = np.broadcast_to(np.asarray(pitch, float), (n,)).copy() if profile is None else np.zeros(1)
    prof = np.zeros(0) if profile is None else np.ascontiguousarray(profile, dtype=float)
    every = max(1, int(round(record_dt / dt)))
    out = np.empty((K.NR, n // every + 1))       # channel-major: each channel a contiguous row
    rows = K.rollout(model.P, model.table, S, cmd_l, cmd_r, pitch_t, prof, float(profile_start),
                     float(profile_step), float(dt), bool(open_loop), every, out)
    data = {name: out[i, :rows] for i, name in enumerate(K.CHANNELS)}
    return Trajectory(data=data, stalled=bool(S[K.S_STALLED] > 0.5), final_state=S)


def _finite_array(x, name: str) -> np.ndarray:
    """``x`` as a contiguous float array, or a ParameterError naming ``name`` when it is
    not numbers or holds NaN or inf."""
    from .params import ParameterError
    try:
        a = np.array(x, dtype=float)              # (a 0-d array stays one: a constant pitch)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}: expected numbers, found {type(x).__name__}") from None
    if not np.all(np.isfinite(a)):
        raise ParameterError(f"{name}: expected finite numbers, found NaN or inf")
    return a


def hold(value: float, duration: float, dt: float) -> np.ndarray:
    """A constant command of ``duration`` seconds at step dt."""
    return np.full(int(round(duration / dt)), float(value))
