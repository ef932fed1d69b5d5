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
    """A DRIVE windows CSV as a run: t, wl_cmd, wr_cmd, wl, wr, x/y/yaw (the ICP pose,
    given relative to each window's start, chained into one pose: see
    :func:`_chain_windows`), segment."""
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
    x, y, yaw = _chain_windows(win, d["icp_x"], d["icp_y"], d["icp_yaw"])
    cols = {"t": t, "wl_cmd": d["cmd_left"], "wr_cmd": d["cmd_right"], "wl": wl, "wr": wr,
            "x": x, "y": y, "yaw": yaw, "segment": seg.astype(float)}
    meta = {"vehicle": "warthog", "terrain": terrain, "slope_deg": "0",
            "note": f"Norlab DRIVE Warthog windows, {path.name}"}
    return Run(cols, meta, str(path))


def _chain_windows(win, x, y, yaw):
    """One continuous pose from poses relative to each window's start: a window starts
    where the previous one's last sample ended (the windows are contiguous; the step
    between the last sample and the next window's first, 0.05 s, is not covered, so the
    chained pose drifts slowly; use it over short spans, as the relative pose error does)."""
    X, Y, YAW = np.empty_like(x), np.empty_like(y), np.empty_like(yaw)
    gx = gy = gyaw = 0.0
    start = 0
    n = len(win)
    while start < n:
        end = start
        while end < n and win[end] == win[start]:
            end += 1
        c, s_ = np.cos(gyaw), np.sin(gyaw)
        X[start:end] = gx + c * x[start:end] - s_ * y[start:end]
        Y[start:end] = gy + s_ * x[start:end] + c * y[start:end]
        YAW[start:end] = gyaw + yaw[start:end]
        gx, gy, gyaw = X[end - 1], Y[end - 1], YAW[end - 1]
        start = end
    return X, Y, np.unwrap(YAW)
