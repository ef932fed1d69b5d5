"""A plan's trajectory: the channels recorded along it and what is read off them."""
from __future__ import annotations

import numpy as np

RECORD_EVERY = 0.05   # s: trajectory samples in the plan JSON

TRAJECTORY_KEYS = ("t", "x", "y", "z", "yaw", "v", "yaw_rate", "wl", "wr", "tau_l", "tau_r", "power_W",
                   "energy_J", "pitch", "i_l", "i_r")


def trajectory_json(traj: dict) -> dict:
    """The JSON ``trajectory`` object (docs/formats.md keys plus pitch and currents)."""
    return {k: [float(a) for a in traj[k]] for k in TRAJECTORY_KEYS if k in traj}


def trajectory_span(tr: dict, key: str) -> float | None:
    """Last minus first sample of channel ``key`` of a trajectory (None if it has none)."""
    return float(tr[key][-1] - tr[key][0]) if len(tr.get(key, ())) else None


def trajectory_length(tr: dict) -> float | None:
    """Length of a trajectory's xy path, m (None if it has no samples)."""
    return float(np.sum(np.hypot(np.diff(tr["x"]), np.diff(tr["y"])))) if len(tr.get("x", ())) else None
