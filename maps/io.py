"""Loading maps: ``.npy`` arrays, PNG heightmaps with a height range, and generators.

A map specification is the ``map:`` section of a scenario (paths relative to ``base``)::

    map: {file: maps/two_hills.npy, resolution: 0.25, origin: [0, 0]}
    map: {file: maps/valley.png, resolution: 0.5, origin: [0, 0], height_range: [0.0, 6.0]}
    map: {generate: {size: [60, 60], resolution: 0.25, seed: 3, features: [...]}}

PNG heightmaps follow ROS map_server's idea of an image plus metadata: the grey level
(0..max) maps linearly onto ``height_range`` [m]; the image's top row is the map's
northern edge (largest y), as an image is seen from above.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .generate import GeneratorError, generate
from .grid import ElevationMap


class MapError(ValueError):
    """A map specification or file is wrong; the message names file or key, expected, found."""


def _number(spec, key, where, positive=False):
    v = spec.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not -1e300 < v < 1e300 or (positive and v <= 0):
        want = "a positive number" if positive else "a number"
        raise MapError(f"{where}.{key}: expected {want}, found {v!r:.60}")
    return float(v)


def _origin(spec, where):
    o = spec.get("origin", [0.0, 0.0])
    if not (isinstance(o, (list, tuple)) and len(o) == 2 and all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in o)):
        raise MapError(f"{where}.origin: expected [x, y] in metres, found {o!r}")
    return float(o[0]), float(o[1])


def read_png_heights(path: Path, zmin: float, zmax: float) -> np.ndarray:
    """Heights [m] from a greyscale (or colour: mean of RGB) PNG, row 0 = largest y."""
    import matplotlib.image as mpimg
    try:
        img = mpimg.imread(str(path))
    except (OSError, SyntaxError, ValueError) as exc:
        raise MapError(f"{path}: expected a PNG image, found a file that cannot be read as one ({exc})") from None
    img = np.asarray(img, dtype=float)
    if img.ndim == 3:
        img = img[..., :3].mean(axis=2)
    if img.max() > 1.0:       # 16-bit PNGs come as integers in some readers
        img = img / img.max()
    return np.flipud(zmin + (zmax - zmin) * img)


def load_map(spec, base: Path | str = ".", where: str = "map") -> ElevationMap:
    """An :class:`ElevationMap` from a map specification (module doc)."""
    base = Path(base)
    if not isinstance(spec, dict):
        raise MapError(f"{where}: expected a mapping with 'file' or 'generate', found {spec!r}")
    if "generate" in spec:
        extra = set(spec) - {"generate"}
        if extra:
            raise MapError(f"{where}: unknown key '{sorted(extra)[0]}' beside 'generate'")
        try:
            return generate(spec["generate"], f"{where}.generate")
        except GeneratorError as exc:
            raise MapError(str(exc)) from None
    known = {"file", "resolution", "origin", "height_range"}
    extra = set(spec) - known
    if extra:
        raise MapError(f"{where}: unknown key '{sorted(extra)[0]}': expected {', '.join(sorted(known | {'generate'}))}")
    if not isinstance(spec.get("file"), str):
        raise MapError(f"{where}.file: expected a path to a .npy or .png file, found {spec.get('file')!r}")
    path = base / spec["file"]
    res = _number(spec, "resolution", where, positive=True)
    origin = _origin(spec, where)
    if not path.is_file():
        raise MapError(f"{where}.file: expected an existing file, found no file at '{path}'")
    if path.suffix.lower() == ".npy":
        try:
            H = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as exc:
            raise MapError(f"{path}: expected a NumPy .npy array, found a file that cannot be read as one ({exc})") from None
    elif path.suffix.lower() == ".png":
        hr = spec.get("height_range")
        if not (isinstance(hr, (list, tuple)) and len(hr) == 2 and all(isinstance(a, (int, float)) for a in hr) and hr[0] <= hr[1]):
            raise MapError(f"{where}.height_range: expected [z_min, z_max] in metres for a PNG map, found {hr!r}")
        H = read_png_heights(path, float(hr[0]), float(hr[1]))
    else:
        raise MapError(f"{where}.file: expected a .npy or .png file, found '{path.suffix or path.name}'")
    if H.ndim != 2 or min(H.shape) < 2 or not np.issubdtype(H.dtype, np.number):
        raise MapError(f"{path}: expected a 2-D array of heights of at least 2 x 2, found shape {H.shape} of {H.dtype}")
    if not np.all(np.isfinite(H)):
        raise MapError(f"{path}: expected finite heights, found NaN or inf")
    return ElevationMap(np.array(H, dtype=float), res, origin, name=path.stem)
