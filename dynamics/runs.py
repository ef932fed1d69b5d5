"""Measured runs: the run CSV of docs/formats.md, read and written.

A header row of column names, optionally preceded by ``# key: value`` metadata lines
(vehicle, terrain, slope_deg, currents, note). Required columns: ``t``, ``wl_cmd``, ``wr_cmd``,
``wl``, ``wr``; optional: ``tau_l``, ``tau_r``, ``i_l``, ``i_r``, ``x``, ``y``, ``yaw``,
``z``, ``pitch``, ``roll``, ``v_batt``, ``segment``. Empty or NaN cells are gaps. Units
are SI (s, rad/s, N m, A, m, rad, V). ``# currents: unsigned`` says the current columns
hold magnitudes (a driver that logs no sign): the replay's currents are compared as
magnitudes too (:func:`currents_unsigned`).

Segments: the ``segment`` column when present; a jump in time larger than
``GAP_FACTOR`` times the median step also starts a new segment (the state does not carry
over a logging gap).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REQUIRED = ("t", "wl_cmd", "wr_cmd", "wl", "wr")
MIN_STEP_S = 1e-5        # median sample spacing: at most 100 kHz ...
MAX_STEP_S = 0.5         # ... and at least 2 Hz (a replay at the controller rate needs the commands)
MAX_ROWS = 5_000_000     # rows of a run file (about 3 h at 500 Hz); SBMPC_MAX_RUN_ROWS raises it
MAX_SPAN_S = 4 * 3600.0  # replayed time (sum of the segments' spans); SBMPC_MAX_RUN_S raises it
OPTIONAL = ("tau_l", "tau_r", "i_l", "i_r", "x", "y", "yaw", "z", "pitch", "roll", "v_batt", "segment")
GAP_FACTOR = 10.0
CURRENTS = ("signed", "unsigned")   # the metadata key currents: what the current columns hold


class RunError(ValueError):
    """A run file is wrong; the message names the file, the line or column, what was
    expected and what was found."""


@dataclass(frozen=True, eq=False)
class Run:
    """A measured run: ``columns`` name -> float array (NaN = gap), ``meta`` from the
    ``# key: value`` lines, ``source`` the file."""

    columns: dict
    meta: dict = field(default_factory=dict)
    source: str = ""

    def __getitem__(self, name) -> np.ndarray:
        return self.columns[name]

    def __contains__(self, name) -> bool:
        return name in self.columns and np.any(np.isfinite(self.columns[name]))

    def __len__(self) -> int:
        return len(self.columns["t"])

    @property
    def t(self) -> np.ndarray:
        return self.columns["t"]

    def segments(self) -> list:
        """Index ranges (start, stop) of the segments, in time order."""
        t = self.t
        n = len(t)
        breaks = np.zeros(n, bool)
        breaks[0] = True
        if n > 1:
            dt = np.diff(t)
            med = float(np.median(dt))
            breaks[1:] |= dt > GAP_FACTOR * med
        if "segment" in self.columns:
            seg = self.columns["segment"].copy()
            ok = np.isfinite(seg)
            if ok.any():          # a gap in the column continues the segment before it
                idx = np.maximum.accumulate(np.where(ok, np.arange(n), 0))
                seg = seg[idx]
                seg[: int(np.argmax(ok))] = seg[int(np.argmax(ok))]
                breaks[1:] |= seg[1:] != seg[:-1]
        starts = np.flatnonzero(breaks)
        stops = np.r_[starts[1:], n]
        return [(int(a), int(b)) for a, b in zip(starts, stops) if b - a >= 2]

    def slice(self, a: int, b: int) -> "Run":
        return Run({k: v[a:b] for k, v in self.columns.items()}, self.meta, self.source)


def _limit(name: str, default: float, whole: bool = False) -> float:
    """A positive, finite limit from the environment variable ``name`` (``default`` when
    unset); a RunError naming it otherwise."""
    import math
    import os
    text = os.environ.get(name)
    if text is None:
        return float(default)
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0 and (not whole or v.is_integer())):
        raise RunError(f"environment variable {name}: expected a positive {'whole number' if whole else 'number'}, "
                       f"found {text!r:.40}")
    return v


def read_run(path: Path | str) -> Run:
    """Read a run CSV; raises :class:`RunError` with file and line on any problem. The
    file is only read."""
    path = Path(path)
    if path.is_dir():
        raise RunError(f"{path}: expected a run CSV file, found a folder")
    if not path.is_file():
        raise RunError(f"{path}: expected a run CSV file, found no such file")
    try:
        text = path.read_text(encoding="utf-8-sig")        # (a byte-order mark, as spreadsheets write it)
    except UnicodeDecodeError:
        raise RunError(f"{path}: expected a text CSV file, found binary data") from None
    max_rows = int(_limit("SBMPC_MAX_RUN_ROWS", MAX_ROWS, whole=True))
    max_span = _limit("SBMPC_MAX_RUN_S", MAX_SPAN_S)
    lines = text.splitlines()
    meta: dict = {}
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        body = lines[i].lstrip("#").strip()
        if ":" in body:
            k, v = body.split(":", 1)
            meta[k.strip()] = v.strip()
        i += 1
    if i >= len(lines):
        raise RunError(f"{path}: expected a header row of column names, found an empty file")
    header = [h.strip() for h in next(csv.reader([lines[i]]))]
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise RunError(f"{path} line {i + 1}: expected the columns {', '.join(REQUIRED)}, "
                       f"found no {', '.join(missing)} (header: {', '.join(header)})")
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise RunError(f"{path} line {i + 1}: expected each column once, found {', '.join(dup)} twice")
    rows = []
    for ln, row in enumerate(csv.reader(lines[i + 1:]), start=i + 2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(rows) >= max_rows:
            raise RunError(f"{path}: expected at most {max_rows} rows, found more (split the log into files, "
                           "or raise the limit with the environment variable SBMPC_MAX_RUN_ROWS)")
        if len(row) != len(header):
            raise RunError(f"{path} line {ln}: expected {len(header)} cells, found {len(row)}")
        vals = []
        for name, cell in zip(header, row):
            c = cell.strip()
            if c == "" or c.lower() == "nan":
                vals.append(math.nan)
                continue
            try:
                x = float(c)
            except ValueError:
                raise RunError(f"{path} line {ln}, column {name}: expected a number, found {c!r:.40}") from None
            if not -1e12 < x < 1e12 and not math.isnan(x):
                raise RunError(f"{path} line {ln}, column {name}: expected a finite number of at most 1e12, "
                               f"found {c!r:.40}")
            vals.append(x)
        rows.append(vals)
    if not rows:
        raise RunError(f"{path}: expected data rows after the header, found none")
    data = np.array(rows, float)
    cols = {name: data[:, j].copy() for j, name in enumerate(header)}
    t = cols["t"]
    if not np.all(np.isfinite(t)):
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise RunError(f"{path} line {_line_of(lines, i, k)}, column t: expected a time, found an empty cell")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise RunError(f"{path} line {_line_of(lines, i, k)}, column t: expected time to increase, "
                       f"found {t[k]:g} after {t[k - 1]:g}")
    for name in REQUIRED[1:]:
        n_ok = int(np.isfinite(cols[name]).sum())
        if n_ok < max(2, len(t) // 2):
            raise RunError(f"{path}, column {name}: expected numbers in at least half of the rows, "
                           f"found {n_ok} of {len(t)}")
    if len(t) > 1:
        med = float(np.median(np.diff(t)))
        if not MIN_STEP_S <= med <= MAX_STEP_S:
            raise RunError(f"{path}, column t: expected a median sample spacing between {MIN_STEP_S:g} and "
                           f"{MAX_STEP_S:g} s, found {med:.3g} s")
    cur = meta.get("currents")
    if cur is not None and cur.lower() not in CURRENTS:
        raise RunError(f"{path}, metadata currents: expected {' or '.join(CURRENTS)}, found {cur!r:.40}")
    run = Run(cols, meta, str(path))
    span = sum(float(t[b - 1] - t[a]) for a, b in run.segments())
    if span > max_span:
        raise RunError(f"{path}: expected at most {max_span:g} s of driving to replay, found {span:.0f} s "
                       "(split the log, or raise the limit with the environment variable SBMPC_MAX_RUN_S)")
    return run


def currents_unsigned(run: Run) -> bool:
    """Whether the run's current columns hold magnitudes (``# currents: unsigned``: a
    driver that logs no sign, as BorealTC's Husky)."""
    return str(run.meta.get("currents", "signed")).lower() == "unsigned"


def _line_of(lines, header_index, k):
    """File line number (1-based) of data row k (skipping blank lines)."""
    seen = -1
    for ln in range(header_index + 1, len(lines)):
        if lines[ln].strip():
            seen += 1
            if seen == k:
                return ln + 1
    return header_index + 2 + k


def write_run(path: Path | str, run: Run) -> None:
    """Write a run CSV (metadata lines, header, rows; NaN as empty cells)."""
    names = [c for c in REQUIRED + OPTIONAL if c in run.columns] + \
            [c for c in run.columns if c not in REQUIRED + OPTIONAL]
    with open(path, "w", newline="") as f:
        for k, v in run.meta.items():
            f.write(f"# {k}: {v}\n")
        w = csv.writer(f)
        w.writerow(names)
        data = np.column_stack([run.columns[c] for c in names])
        for row in data:
            w.writerow(["" if not np.isfinite(x) else (f"{int(x)}" if c == "segment" else f"{x:.6g}")
                        for c, x in zip(names, row)])


def pose_updates(x, y, yaw) -> tuple:
    """Where a logged pose was updated: (fresh, upd), ``fresh[i]`` true when sample i
    changed the pose, ``upd[i]`` the index of the update that sample i still holds.
    Scan-matched poses are logged at the sensor rate but updated irregularly and held in
    between; a held pose belongs to the time of its update."""
    x, y, yaw = (np.asarray(a, float) for a in (x, y, yaw))
    fresh = np.r_[True, (np.diff(x) != 0) | (np.diff(y) != 0) | (np.diff(yaw) != 0)]
    return fresh, np.maximum.accumulate(np.where(fresh, np.arange(fresh.size), 0))
