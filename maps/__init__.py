"""maps: the ground. Elevation grids with a terrain layer, compiled height, gradient and
pitch/roll queries, loading from .npy and PNG files, and seeded generators.

``maps`` never imports ``dynamics`` nor ``sbmpc`` (only ``_jitcache``, which imports neither).
"""
from _jitcache import refresh_once

refresh_once()     # numba's cache, consistent across files (_jitcache), before anything compiled loads

from .generate import GeneratorError, generate
from .grid import ElevationMap, gradient_at, height_at, pitch_roll_at
from .io import MapError, MapWarning, load_map

__all__ = ["ElevationMap", "GeneratorError", "MapError", "MapWarning", "generate", "gradient_at", "height_at",
           "load_map", "pitch_roll_at"]
