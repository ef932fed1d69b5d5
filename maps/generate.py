"""Seeded generators of hills, ramps, ridges and valleys, described as plain data (YAML).

A description is a mapping::

    size: [60, 60]          # metres (x, y)
    resolution: 0.25        # metres per cell
    origin: [0, 0]          # optional, world (x, y) of cell [0, 0]
    seed: 7                 # for random features
    base: 0.0               # metres
    features:
      - {type: hill, x: 20, y: 30, height: 3.0, radius: 6.0}        # Gaussian bump (radius = sigma)
      - {type: plateau, x: 40, y: 20, height: 2.0, radius: 5.0, edge: 1.0}
      - {type: ramp, x0: 10, y0: 5, x1: 14, y1: 5, height: 1.0, width: 4.0}  # rises from (x0,y0) to (x1,y1), then stays
      - {type: ridge, x0: 5, y0: 50, x1: 55, y1: 50, height: 2.0, width: 3.0}
      - {type: valley, x0: 5, y0: 10, x1: 55, y1: 10, depth: 1.5, width: 4.0}
      - {type: random_hills, count: 12, height: [0.5, 3.0], radius: [2.0, 6.0]}

Heights add up. The same description and seed always give the same map.
"""
from __future__ import annotations

import numpy as np

from .grid import ElevationMap


def unknown_key(where: str, key, known, note: str = "") -> str:
    """The message for an unknown key of a mapping at ``where``, in the scenario's form:
    what was expected (the known keys), what was found, the closest known key."""
    import difflib
    close = difflib.get_close_matches(str(key), sorted(map(str, known)), n=1, cutoff=0.6)
    mean = f" (did you mean '{close[0]}'?)" if close else ""
    return (f"{where}.{key}: expected one of the keys {', '.join(sorted(map(str, known)))}{note}, "
            f"found an unknown key{mean}")

FEATURE_KEYS = {
    "hill": {"x", "y", "height", "radius"},
    "plateau": {"x", "y", "height", "radius", "edge"},
    "ramp": {"x0", "y0", "x1", "y1", "height", "width"},
    "ridge": {"x0", "y0", "x1", "y1", "height", "width"},
    "valley": {"x0", "y0", "x1", "y1", "depth", "width"},
    "random_hills": {"count", "height", "radius"},
}


TOP_KEYS = {"size", "resolution", "origin", "seed", "base", "features", "name"}


class GeneratorError(ValueError):
    """A generator description is wrong; the message gives the key path."""


def text_number_hint(value) -> str:
    """For an error message: a note when a YAML value that should be a number is text
    that reads as one. YAML 1.1 (PyYAML) takes 1e3 or 1.0e300, an exponent without a
    dot and a sign, as a string."""
    if not isinstance(value, str) or len(value) > 40 or not any(c in value for c in "eE"):
        return ""
    try:
        float(value)
    except ValueError:
        return ""
    return " (text: YAML reads an exponent as a number only with a dot and a sign, as in 1.0e+3)"


COORD = 1e9          # m: the largest coordinate a description may name
LENGTH = 1e6         # m: the largest size, radius or width
HEIGHT = 1e4         # m: the largest height or depth of one feature (and the base)
MAX_RANDOM_HILLS = 10_000


def _num(d, key, path, positive=False, limit=COORD):
    """``d[key]`` as a float: a finite number of magnitude at most ``limit`` (and > 0
    when ``positive``), else a GeneratorError naming the key, the range and the value."""
    if key not in d:
        raise GeneratorError(f"{path}.{key}: expected a number, found nothing")
    v = d[key]
    want = f"a number in (0, {limit:g}]" if positive else f"a number in [{-limit:g}, {limit:g}]"
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not -limit <= v <= limit or (positive and v <= 0):
        if isinstance(v, int) and not isinstance(v, bool) and abs(v) > 10 ** 30:
            found = f"an integer of {len(str(abs(v)))} digits"
        else:
            found = f"{v:.6g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else f"{v!r:.60}"
        raise GeneratorError(f"{path}.{key}: expected {want}, found {found}{text_number_hint(v)}")
    return float(v)


def _range(d, key, path, positive=False, limit=HEIGHT):
    """``d[key]``: a number or a range [low, high] (each as :func:`_num`), as (low, high)."""
    v = d.get(key)
    if isinstance(v, (list, tuple)) and len(v) == 2:
        lo, hi = (_num({key: a}, key, path, positive, limit) for a in v)
        if lo <= hi:
            return lo, hi
    elif isinstance(v, (int, float)) and not isinstance(v, bool):
        a = _num(d, key, path, positive, limit)
        return a, a
    raise GeneratorError(f"{path}.{key}: expected a number or a range [low, high] with low <= high, found {v!r:.60}")


def _segment_coords(X, Y, x0, y0, x1, y1):
    """Along-segment fraction (unclipped) and distance from the segment's line."""
    dx, dy = x1 - x0, y1 - y0
    L2 = dx * dx + dy * dy
    s = ((X - x0) * dx + (Y - y0) * dy) / L2
    d = np.abs((X - x0) * dy - (Y - y0) * dx) / np.sqrt(L2)
    return s, d


def generate(desc: dict, path: str = "map.generate") -> ElevationMap:
    """An :class:`ElevationMap` from a generator description (module doc); a
    GeneratorError naming the key for anything else."""
    with np.errstate(all="ignore"):       # (a degenerate feature is refused below, by its NaN or inf)
        return _generate(desc, path)


def _generate(desc: dict, path: str) -> ElevationMap:
    if not isinstance(desc, dict):
        raise GeneratorError(f"{path}: expected a mapping, found {type(desc).__name__}")
    for key in desc:
        if key not in TOP_KEYS:
            raise GeneratorError(unknown_key(path, key, TOP_KEYS))
    size = desc.get("size")
    if not (isinstance(size, (list, tuple)) and len(size) == 2
            and all(isinstance(a, (int, float)) and not isinstance(a, bool) and 0 < a <= LENGTH for a in size)):
        raise GeneratorError(f"{path}.size: expected [width, height], two numbers in (0, {LENGTH:g}] metres, "
                             f"found {size!r:.60}")
    res = _num(desc, "resolution", path, positive=True, limit=LENGTH)
    cells = (size[0] / res + 1) * (size[1] / res + 1)
    if cells > 25_000_000:
        many = f"{cells:.3g}" if cells < 1e300 else "far more"
        raise GeneratorError(f"{path}: expected at most 25 million cells, found {many} ({size[0]:g} m x "
                             f"{size[1]:g} m at {res:g} m)")
    nx, ny = int(round(size[0] / res)) + 1, int(round(size[1] / res)) + 1
    if min(nx, ny) < 2:
        raise GeneratorError(f"{path}.resolution: expected at most half the smaller side of size ({min(size):g} m) "
                             f"for a map of at least 2 x 2 cells, found {res:g}")
    origin = desc.get("origin", [0.0, 0.0])
    if not (isinstance(origin, (list, tuple)) and len(origin) == 2
            and all(isinstance(a, (int, float)) and not isinstance(a, bool) and abs(a) <= COORD for a in origin)):
        raise GeneratorError(f"{path}.origin: expected [x, y], two numbers in metres, found {origin!r:.60}")
    seed = desc.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 63:
        raise GeneratorError(f"{path}.seed: expected an integer in [0, 2^63), found {seed!r:.60}")
    rng = np.random.default_rng(seed)
    x = origin[0] + np.arange(nx) * res
    y = origin[1] + np.arange(ny) * res
    X, Y = np.meshgrid(x, y)
    H = np.full((ny, nx), _num(desc, "base", path, limit=HEIGHT) if "base" in desc else 0.0)
    feats = desc.get("features", [])
    if not isinstance(feats, list):
        raise GeneratorError(f"{path}.features: expected a list, found {type(feats).__name__}")
    for k, f in enumerate(feats):
        fp = f"{path}.features[{k}]"
        if not isinstance(f, dict) or f.get("type") not in FEATURE_KEYS:
            raise GeneratorError(f"{fp}.type: expected one of {', '.join(FEATURE_KEYS)}, found {f.get('type') if isinstance(f, dict) else f!r}")
        kind = f["type"]
        extra = set(f) - FEATURE_KEYS[kind] - {"type"}
        if extra:
            raise GeneratorError(unknown_key(fp, sorted(extra)[0], FEATURE_KEYS[kind] | {"type"}, f" (a {kind})"))
        if kind == "hill":
            r = _num(f, "radius", fp, True, LENGTH)
            H += _num(f, "height", fp, limit=HEIGHT) * np.exp(-((X - _num(f, "x", fp)) ** 2 + (Y - _num(f, "y", fp)) ** 2) / (2 * r * r))
        elif kind == "plateau":
            r, e = _num(f, "radius", fp, True, LENGTH), _num(f, "edge", fp, True, LENGTH)
            d = np.hypot(X - _num(f, "x", fp), Y - _num(f, "y", fp))
            H += _num(f, "height", fp, limit=HEIGHT) * np.clip((r + e - d) / e, 0.0, 1.0)
        elif kind == "random_hills":
            hlo, hhi = _range(f, "height", fp)
            rlo, rhi = _range(f, "radius", fp, positive=True, limit=LENGTH)
            count = f.get("count")
            if isinstance(count, bool) or not isinstance(count, int) or not 0 <= count <= MAX_RANDOM_HILLS:
                raise GeneratorError(f"{fp}.count: expected a whole number in [0, {MAX_RANDOM_HILLS}], found {count!r:.60}")
            for _ in range(count):
                cx, cy = rng.uniform(x[0], x[-1]), rng.uniform(y[0], y[-1])
                h, r = rng.uniform(hlo, hhi), rng.uniform(rlo, rhi)
                H += h * np.exp(-((X - cx) ** 2 + (Y - cy) ** 2) / (2 * r * r))
        else:
            x0, y0, x1, y1 = (_num(f, key, fp) for key in ("x0", "y0", "x1", "y1"))
            if x0 == x1 and y0 == y1:
                raise GeneratorError(f"{fp}: expected two different end points, found ({x0}, {y0}) twice")
            w = _num(f, "width", fp, True, LENGTH)
            s, d = _segment_coords(X, Y, x0, y0, x1, y1)
            if kind == "ramp":      # a strip rising linearly from end 0 to end 1, level beyond
                H += _num(f, "height", fp, limit=HEIGHT) * np.clip(s, 0.0, 1.0) * (s >= 0) * (d <= w / 2)
            else:                   # a Gaussian cross-section (sigma = width / 2) along the segment
                amp = _num(f, "height", fp, limit=HEIGHT) if kind == "ridge" else -_num(f, "depth", fp, limit=HEIGHT)
                H += amp * np.exp(-0.5 * (d / (w / 2)) ** 2) * ((s >= 0) & (s <= 1))
    if not np.all(np.isfinite(H)):      # (a radius so small that its Gaussian underflows)
        raise GeneratorError(f"{path}.features: expected finite heights, found NaN or inf (a radius or width "
                             f"far below the resolution of {res:g} m?)")
    return ElevationMap(H, res, (float(origin[0]), float(origin[1])), name=str(desc.get("name", "")))
