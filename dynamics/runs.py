"""Measured runs: the run CSV of docs/formats.md, read and written.

A header row of column names, optionally preceded by ``# key: value`` metadata lines
(vehicle, terrain, slope_deg, note). Required columns: ``t``, ``wl_cmd``, ``wr_cmd``,
``wl``, ``wr``; optional: ``tau_l``, ``tau_r``, ``i_l``, ``i_r``, ``x``, ``y``, ``yaw``,
``z``, ``pitch``, ``roll``, ``v_batt``, ``segment``. Empty or NaN cells are gaps. Units
are SI (s, rad/s, N m, A, m, rad, V).

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
OPTIONAL = ("tau_l", "tau_r", "i_l", "i_r", "x", "y", "yaw", "z", "pitch", "roll", "v_batt", "segment")
GAP_FACTOR = 10.0


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
            seg = self.columns["segment"]
            breaks[1:] |= seg[1:] != seg[:-1]
        starts = np.flatnonzero(breaks)
        stops = np.r_[starts[1:], n]
        return [(int(a), int(b)) for a, b in zip(starts, stops) if b - a >= 2]

    def slice(self, a: int, b: int) -> "Run":
        return Run({k: v[a:b] for k, v in self.columns.items()}, self.meta, self.source)


def read_run(path: Path | str) -> Run:
    """Read a run CSV; raises :class:`RunError` with file and line on any problem. The
    file is only read."""
    path = Path(path)
    if not path.is_file():
        raise RunError(f"{path}: expected a run CSV file, found no such file")
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise RunError(f"{path}: expected a text CSV file, found binary data") from None
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
        if len(row) != len(header):
            raise RunError(f"{path} line {ln}: expected {len(header)} cells, found {len(row)}")
        vals = []
        for name, cell in zip(header, row):
            c = cell.strip()
            if c == "" or c.lower() == "nan":
                vals.append(math.nan)
                continue
            try:
                vals.append(float(c))
            except ValueError:
                raise RunError(f"{path} line {ln}, column {name}: expected a number, found {c!r}") from None
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
    return Run(cols, meta, str(path))


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
