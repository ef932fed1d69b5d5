"""Readers of public measured datasets into :class:`dynamics.runs.Run`.

* Norlab DRIVE (Baril et al., arXiv 2309.10718; github.com/norlab-ulaval/DRIVE, BSD-3):
  Clearpath Warthog calibration runs, converted to CSV windows of 40 samples at 20 Hz
  (columns ``window, calib_step, steady, k, t, cmd_left, cmd_right, left_wheel_vel,
  right_wheel_vel, icp_*, imu_*``). Consecutive windows are contiguous in time, so they
  are joined into one timeline (window w starts at 2 w seconds); a new segment starts
  only where the wheel speeds jump across a window boundary (the log is not continuous
  there).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from dynamics.runs import Run, RunError

DRIVE_WINDOW_S = 2.0
JUMP = 2.0     # rad/s: a wheel-speed jump across a window boundary that breaks the timeline


def read_drive_windows(path: Path | str, terrain: str = "") -> Run:
    """A DRIVE windows CSV as a run: t, wl_cmd, wr_cmd, wl, wr, x/y/yaw (ICP, relative to
    each window's start), segment."""
    path = Path(path)
    try:
        d = np.genfromtxt(path, delimiter=",", names=True)
    except (OSError, ValueError) as exc:
        raise RunError(f"{path}: expected a DRIVE windows CSV, found a file that cannot be read ({exc})") from None
    need = ("window", "t", "cmd_left", "cmd_right", "left_wheel_vel", "right_wheel_vel")
    missing = [c for c in need if c not in (d.dtype.names or ())]
    if missing:
        raise RunError(f"{path}: expected the DRIVE columns {', '.join(need)}, found no {', '.join(missing)}")
    win = d["window"].astype(int)
    t = win * DRIVE_WINDOW_S + d["t"]
    order = np.argsort(t, kind="stable")
    d, win, t = d[order], win[order], t[order]
    wl, wr = d["left_wheel_vel"], d["right_wheel_vel"]
    first = np.r_[True, win[1:] != win[:-1]]
    jump = np.r_[False, (np.abs(np.diff(wl)) > JUMP) | (np.abs(np.diff(wr)) > JUMP)]
    seg = np.cumsum(first & jump)
    cols = {"t": t, "wl_cmd": d["cmd_left"], "wr_cmd": d["cmd_right"], "wl": wl, "wr": wr,
            "x": d["icp_x"], "y": d["icp_y"], "yaw": d["icp_yaw"], "segment": seg.astype(float)}
    meta = {"vehicle": "warthog", "terrain": terrain, "slope_deg": "0",
            "note": f"Norlab DRIVE Warthog windows, {path.name}"}
    return Run(cols, meta, str(path))
