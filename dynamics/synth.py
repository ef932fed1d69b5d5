"""Measured-looking runs from the closed-loop model, with one hidden effect.

:func:`synth_run` drives the model with commands that excite the vehicle (speed steps,
turns of both signs, stops; the drive's 1 m/s^2 reference ramps do the ramps), with
one effect of the vocabulary switched on at a strength drawn from the seed, samples
the result at 100 Hz and adds sensor noise. The logged commands are the ones sent (a
delay acts inside the drive), and the metadata say nothing of the effect (a hidden
grade is not in ``slope_deg``).
"""
from __future__ import annotations

import math

import numpy as np

from .params import Terrain, Vehicle
from .runs import Run
from .simulate import Model, simulate

# effect -> (parameter, strength range); wheel_radius and grade draw a side or sign too
STRENGTHS = {
    "none": None,
    "command_delay": ("delay_s", (0.08, 0.25)),
    "actuator_lag": ("lag_s", (0.02, 0.07)),         # >= 0.1 s the PID loop limit-cycles
    "wheel_radius": ("scale", (0.90, 0.95)),            # one side smaller (worn or flat tyre)
    "viscous_friction": ("c_Nms", (0.15, 0.5)),
    "no_load_current": ("i0_A", (0.3, 0.8)),          # the motors' own friction (a P-3AT's draws 3.62 A at most)
    "voltage_sag": ("sag_V_per_kJ", (0.5, 1.0)),
    "shear_relaxation": ("tau_s", (0.25, 0.6)),
    "grade": ("grade_deg", (3.0, 6.0)),
    "turning_friction": ("mu_scale", (0.6, 0.8)),      # sbmpc's own: the terrain turns easier than its file says
}
NOISE = {"wl": 0.05, "wr": 0.05, "tau_l": 0.08, "tau_r": 0.08, "i_l": 0.05, "i_r": 0.05,
         "x": 0.01, "y": 0.01, "yaw": 0.005}
RATE = 100.0          # Hz, logging rate


def hidden(effect: str, seed: int) -> dict:
    """The hidden parameters of ``effect`` drawn from ``seed`` (the names of
    :mod:`dynamics.discrepancy`'s candidates)."""
    if effect not in STRENGTHS:
        raise ValueError(f"effect: expected one of {', '.join(STRENGTHS)}, found {effect!r}")
    rng = np.random.default_rng([seed, 7])
    if effect == "none":
        return {}
    name, (lo, hi) = STRENGTHS[effect]
    x = float(rng.uniform(lo, hi))
    if effect == "wheel_radius":
        side = "left" if rng.random() < 0.5 else "right"
        return {"scale_left": x if side == "left" else 1.0, "scale_right": x if side == "right" else 1.0}
    if effect == "grade":
        return {"grade_deg": x if rng.random() < 0.5 else -x}
    return {name: x}


def apply(vehicle: Vehicle, effect: str, params: dict, terrain: Terrain | None = None) -> tuple:
    """(vehicle, terrain, pitch [rad]) with an effect's parameters switched on."""
    v, t, pitch = vehicle, terrain, 0.0
    if effect == "command_delay":
        v = v.replace(delay=params["delay_s"])
    elif effect == "actuator_lag":
        v = v.replace(lag=params["lag_s"])
    elif effect == "wheel_radius":
        v = v.replace(radius_scale_left=params["scale_left"], radius_scale_right=params["scale_right"])
    elif effect == "viscous_friction":
        v = v.replace(viscous=params["c_Nms"])
    elif effect == "no_load_current":
        v = v.replace(no_load_current=params["i0_A"])
    elif effect == "voltage_sag":
        v = v.replace(sag=params["sag_V_per_kJ"] / 1000.0)
    elif effect == "shear_relaxation":
        v = v.replace(shear_lag=params["tau_s"])
    elif effect == "grade":
        pitch = math.radians(params["grade_deg"])
    elif effect == "turning_friction":
        k = params["mu_scale"]
        t = t.replace(mu_sa=t.mu_sa * k, mu_op=t.mu_op * k)
    return v, t, pitch


def excitation(seed: int, duration: float, vehicle: Vehicle, dt: float) -> tuple:
    """Commanded wheel speeds (cmd_l, cmd_r) [rad/s] per step of dt: a random sequence
    of holds of 2.5-5 s: straight at 0.2-0.85 m/s, turns of radius 0.5-3 m either way,
    stops."""
    rng = np.random.default_rng([seed, 11])
    r, B = vehicle.wheel_radius, vehicle.width
    cl, cr = [], []
    t = 0.0
    while t < duration:
        hold = round(float(rng.uniform(2.5, 5.0)) * RATE) / RATE      # commands change on log samples
        kind = rng.choice(["straight", "turn", "turn", "stop"], p=[0.4, 0.25, 0.25, 0.1])
        v = float(rng.uniform(0.2, 0.85))
        if kind == "stop":
            wl = wr = 0.0
        elif kind == "straight":
            wl = wr = v / r
        else:
            radius = float(rng.uniform(0.5, 3.0)) * (1 if rng.random() < 0.5 else -1)
            w = v / radius
            wl, wr = (v - w * B / 2) / r, (v + w * B / 2) / r
        n = int(round(hold / dt))
        cl.append(np.full(n, wl))
        cr.append(np.full(n, wr))
        t += hold
    n_total = int(round(duration / dt))
    return np.concatenate(cl)[:n_total], np.concatenate(cr)[:n_total]


def synth_run(effect: str, seed: int, vehicle: Vehicle | None = None, terrain: Terrain | None = None,
              duration: float = 90.0, params: dict | None = None, noise: bool = True,
              step_s: float | None = None) -> tuple:
    """(Run, hidden parameters): a synthetic measured run with ``effect`` hidden (its
    parameters drawn from ``seed`` unless given). ``step_s``: the truth's integration
    step [s] (default the controller period, as the diagnosis replays; a coarser step
    integrates the same model differently: the continuous loop, two-stage SDIRK)."""
    from .params import load_terrain, load_vehicle
    vehicle = vehicle or load_vehicle("p3at")
    terrain = terrain or load_terrain("vinyl")
    params = hidden(effect, seed) if params is None else params
    truth, ground, pitch = apply(vehicle, effect, params, terrain)
    model = Model(truth, ground, step_s)
    cl, cr = excitation(seed, duration, vehicle, model.step_s)
    cols = measured(model, cl, cr, seed if noise else None, pitch)
    meta = {"vehicle": vehicle.name, "terrain": terrain.name, "slope_deg": "0",
            "note": f"synthetic run, seed {seed}"}
    return Run(cols, meta, f"synth:{effect}:{seed}"), params


def measured(model: Model, cl: np.ndarray, cr: np.ndarray, seed: int | None = None, pitch: float = 0.0) -> dict:
    """The run CSV's columns of ``model`` driven from rest by the commanded wheel speeds
    ``cl``, ``cr`` [rad/s, one per model step]: t, the commands, wheel speeds, torques,
    currents and pose sampled at ``RATE``, with the sensor noise ``NOISE`` drawn from
    ``seed`` (none when None). On a plane of grade ``pitch`` [rad]."""
    dt = model.step_s
    tr = simulate(model, cl, cr, state=model.state(0.0, 0.0, pitch), pitch=pitch, record_dt=1.0 / RATE)
    every = int(round(1.0 / RATE / dt))
    idx = np.minimum(np.arange(len(tr.t)) * every, len(cl) - 1)
    rng = np.random.default_rng([seed, 13]) if seed is not None else None
    cols = {"t": tr.t.copy(), "wl_cmd": cl[idx], "wr_cmd": cr[idx]}
    for name in ("wl", "wr", "tau_l", "tau_r", "i_l", "i_r", "x", "y", "yaw"):
        y = tr.data[name].copy()
        if rng is not None:
            y = y + rng.normal(0.0, NOISE[name], y.shape)
        cols[name] = y
    return cols
