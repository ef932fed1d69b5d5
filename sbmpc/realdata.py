"""Readers of public measured datasets into :class:`dynamics.runs.Run`.

* Norlab DRIVE (Baril et al., arXiv 2309.10718; github.com/norlab-ulaval/DRIVE, BSD-3):
  Clearpath Warthog calibration runs, converted to CSV windows of 40 samples at 20 Hz
  (columns ``window, calib_step, steady, k, t, cmd_left, cmd_right, left_wheel_vel,
  right_wheel_vel, icp_*, imu_*``). Consecutive windows are contiguous in time, so they
  are joined into one timeline (window w starts at 2 w seconds); a new segment starts
  only where the wheel speeds jump across a window boundary (the log is not continuous
  there).
* BorealTC (github.com/norlab-ulaval/BorealTC, CC0): Clearpath Husky A200 on six
  terrains, files ``pro_XX.csv`` with ``time, curL, curR, velL, velR``: motor currents
  [A, unsigned] and wheel linear speeds [m/s, quantised to 1/127 m/s] at about 6.5 Hz;
  no commands and no pose: :func:`read_borealtc` and :func:`steady_samples` feed the
  eq. 28 identification of the terrain's friction; :func:`read_borealtc_run` makes a
  run of it for ``sbmpc diagnose``, the measured speeds standing in for the commands.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from dynamics.runs import Run, RunError

DRIVE_WINDOW_S = 2.0
JUMP = 2.0     # rad/s: a wheel-speed jump across a window boundary that breaks the timeline


def _columns(path: Path, dataset: str, kind: str, need: tuple) -> np.ndarray:
    """The named columns of a CSV file with a header row (a byte-order mark allowed), as
    a one-dimensional structured array (one row included), or a RunError naming the
    file, what it should be (``kind``, from ``dataset``) and what is missing."""
    import warnings
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")             # (an empty file: 'no data', said below)
            d = np.atleast_1d(np.genfromtxt(path, delimiter=",", names=True, encoding="utf-8-sig"))
    except (OSError, ValueError, IndexError) as exc:
        why = " ".join(str(exc).split())               # genfromtxt's message spans lines
        m = re.search(r"Line #(\d+) \(got (\d+) columns instead of (\d+)\)", why)
        if m:
            why = f"line {m.group(1)} has {m.group(2)} cells where the header names {m.group(3)}"
        elif isinstance(exc, IndexError) or not why:
            why = "no header row"
        raise RunError(f"{path}: expected {kind}, found a file that cannot be read ({why[:200]})") from None
    missing = [c for c in need if c not in (d.dtype.names or ())]
    if missing:
        raise RunError(f"{path}: expected the {dataset} columns {', '.join(need)}, found no {', '.join(missing)}")
    if d.size == 0:
        raise RunError(f"{path}: expected {kind} with data rows, found the header alone")
    return d


def _finite(path: Path, d: np.ndarray, columns: tuple) -> None:
    """A RunError naming the first row (its line in the file) and column of ``d``, the
    file's rows as read by :func:`_columns`, whose cell is empty, not a number or infinite."""
    for col in columns:
        bad = np.flatnonzero(~np.isfinite(np.asarray(d[col], float)))
        if bad.size:
            with open(path, encoding="utf-8-sig", errors="replace") as f:     # the lines genfromtxt reads:
                lines = [(k, t.lstrip()) for k, t in enumerate(f, 1) if t.strip()]   # the first is the header,
            rows = [k for k, t in lines[1:] if not t.startswith("#")]            # even behind a '#'
            line = rows[int(bad[0])] if int(bad[0]) < len(rows) else int(bad[0]) + 2
            raise RunError(f"{path}, line {line}, column {col}: expected a finite number, found an empty, "
                           f"non-numeric or infinite cell ({bad.size} such row{'s' if bad.size > 1 else ''} in the column)")


def read_drive_windows(path: Path | str, terrain: str = "") -> Run:
    """A DRIVE windows CSV as a run: t, wl_cmd, wr_cmd, wl, wr, x/y/yaw (the ICP pose,
    given relative to each window's start, chained into one pose: see
    :func:`_chain_windows`), segment."""
    path = Path(path)
    need = ("window", "t", "cmd_left", "cmd_right", "left_wheel_vel", "right_wheel_vel", "icp_x", "icp_y", "icp_yaw")
    d = _columns(path, "DRIVE", "a DRIVE windows CSV", need)
    _finite(path, d, need)
    win = d["window"].astype(int)
    t = win * DRIVE_WINDOW_S + d["t"]
    order = np.argsort(t, kind="stable")
    d, win, t = d[order], win[order], t[order]
    same = np.flatnonzero(np.diff(t) <= 0)
    if same.size:                       # (a row written twice: the run's time would stand still)
        k = int(order[same[0] + 1])
        raise RunError(f"{path}: expected one row per time, found window {int(win[same[0] + 1])} t = "
                       f"{float(d['t'][same[0] + 1]):g} s twice ({same.size} such row{'s' if same.size > 1 else ''}; "
                       f"the second is data row {k + 1})")
    wl, wr = d["left_wheel_vel"], d["right_wheel_vel"]
    first = np.r_[True, win[1:] != win[:-1]]
    jump = np.r_[False, (np.abs(np.diff(wl)) > JUMP) | (np.abs(np.diff(wr)) > JUMP)]
    seg = np.cumsum(first & jump)
    x, y, yaw = _chain_windows(win, d["icp_x"], d["icp_y"], d["icp_yaw"])
    cols = {"t": t, "wl_cmd": d["cmd_left"], "wr_cmd": d["cmd_right"], "wl": wl, "wr": wr,
            "x": x, "y": y, "yaw": yaw, "segment": seg.astype(float)}
    meta = {"vehicle": "warthog", **({"terrain": terrain} if terrain else {}), "slope_deg": "0",
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


BOREALTC_QUANTUM = 1.0 / 127.0     # m/s: resolution of the logged wheel speeds
HUSKY_WHEEL_RADIUS = 0.13           # m, BorealTC's code: its linear speeds back to angular ones (the tyre: 0.1651 m)


def read_borealtc(path: Path | str, wheel_radius: float = HUSKY_WHEEL_RADIUS) -> dict:
    """One BorealTC ``pro_XX.csv`` as arrays: t [s], wl, wr [rad/s] (the logged wheel
    linear speeds over ``wheel_radius``), i_l, i_r [A] (motor currents, unsigned)."""
    path = Path(path)
    if isinstance(wheel_radius, bool) or not isinstance(wheel_radius, (int, float)) or not 0 < wheel_radius <= 5:
        raise RunError(f"wheel_radius: expected a radius in (0, 5] m, found {wheel_radius!r:.40}")
    need = ("time", "curL", "curR", "velL", "velR")
    d = _columns(path, "BorealTC", "a BorealTC CSV", need)
    _finite(path, d, need)
    return {"t": d["time"], "wl": d["velL"] / wheel_radius, "wr": d["velR"] / wheel_radius,
            "i_l": d["curL"], "i_r": d["curR"]}


# BorealTC's terrain folders and the nearest shipped terrain (none is icy or snowy)
BOREALTC_TERRAINS = {"ASPHALT": "asphalt", "FLOORING": "vinyl", "MIXED": "packed_dirt", "SANDY_LOAM": "grass",
                     "ICE": "vinyl", "SNOW": "grass"}


def read_borealtc_run(path: Path | str, terrain: str = "") -> Run:
    """A BorealTC ``pro_XX.csv`` as a run for ``sbmpc diagnose``: t, wl, wr [rad/s],
    i_l, i_r [A], and wl_cmd, wr_cmd. The dataset logs no commands: the measured wheel
    speeds stand in for them, so what the replay tests is the current it takes to
    follow them (the terrain's resistance, the motor), not the speed loop (a command
    delay or lag cannot be seen). The logged currents are magnitudes and stay so
    (``# currents: unsigned``): the replay's currents are compared as magnitudes
    (:func:`dynamics.runs.currents_unsigned`)."""
    rec = read_borealtc(path)
    if not terrain:                  # the dataset's folder names the terrain; else none (not vinyl silently)
        terrain = BOREALTC_TERRAINS.get(Path(path).resolve().parent.name.upper(), "")
    t = rec["t"]
    if t.size < 2 or np.any(np.diff(t) <= 0):
        if t.size < 2:
            raise RunError(f"{path}, column time: expected strictly increasing times, found fewer than 2 rows")
        k = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise RunError(f"{path}, data row {k + 1}, column time: expected strictly increasing times, found "
                       f"{t[k]:.6g} after {t[k - 1]:.6g}")
    wl, wr = rec["wl"], rec["wr"]
    cols = {"t": t - t[0], "wl_cmd": wl.copy(), "wr_cmd": wr.copy(), "wl": wl, "wr": wr,
            "i_l": rec["i_l"], "i_r": rec["i_r"]}
    meta = {"vehicle": "husky", **({"terrain": terrain} if terrain else {}), "slope_deg": "0", "currents": "unsigned",
            "note": f"BorealTC Husky {Path(path).resolve().parent.name}/{Path(path).name}: no commands logged "
                    "(the measured wheel speeds stand in for them: a command delay or lag cannot be seen), "
                    "currents unsigned (magnitudes, as logged)"}
    return Run(cols, meta, str(path))


def steady_samples(rec: dict, hold_s: float = 1.0, tol: float = 1.5 * BOREALTC_QUANTUM / HUSKY_WHEEL_RADIUS) -> dict:
    """Stretches where both wheel speeds stay within ``tol`` [rad/s] of their first value
    for at least ``hold_s`` [s]: the steady state of eq. 22 (constant wheel speeds, the
    currents balancing the resistance). Returns the mean wl, wr [rad/s] and i_l, i_r [A]
    of each stretch, its duration [s] and its number of samples."""
    t, wl, wr = rec["t"], rec["wl"], rec["wr"]
    out = {k: [] for k in ("wl", "wr", "i_l", "i_r", "duration_s", "n")}
    a = 0
    n = len(t)
    for b in range(1, n + 1):
        if b == n or abs(wl[b] - wl[a]) > tol or abs(wr[b] - wr[a]) > tol:
            if b - a >= 3 and t[b - 1] - t[a] >= hold_s:
                for k in ("wl", "wr", "i_l", "i_r"):
                    out[k].append(float(np.mean(rec[k][a:b])))
                out["duration_s"].append(float(t[b - 1] - t[a]))
                out["n"].append(b - a)
            a = b
    return {k: np.array(v) for k, v in out.items()}
