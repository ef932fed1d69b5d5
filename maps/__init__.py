"""maps: the ground. Elevation grids with a terrain layer, compiled height, gradient and
pitch/roll queries, loading from .npy and PNG files, and seeded generators.

``maps`` never imports ``dynamics`` nor ``sbmpc``. Its compiled queries are one file
(``grid.py``), which numba's own cache index keeps right (``dynamics._jitcache``).
"""
from .generate import GeneratorError, generate
from .grid import ElevationMap, gradient_at, height_at, pitch_roll_at
from .io import MapError, MapWarning, load_map

__all__ = ["ElevationMap", "GeneratorError", "MapError", "MapWarning", "generate", "gradient_at", "height_at",
           "load_map", "pitch_roll_at"]
