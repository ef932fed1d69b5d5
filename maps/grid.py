"""The ground: an elevation grid with an optional terrain layer, and compiled queries.

Conventions (docs/formats.md): heights [m] in a 2-D array, row = y index, column = x index;
``origin`` is the world (x, y) of the centre of cell [0, 0]; ``resolution`` is metres per
cell. x is east, y north, z up; yaw is counter-clockwise from +x.

The queries are numba kernels over plain arrays so that the planner's compiled edge
rollouts can call them: :func:`height_at` (bilinear), :func:`gradient_at`, and
:func:`pitch_roll_at`, the pitch and roll of a vehicle from the heights under its front,
rear, left and right wheels (:func:`slope_grades_at`: both as tangents).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def height_at(H, res, ox, oy, x, y):
    """Bilinear height [m] at world (x, y) [m]; clamped to the edge outside the grid."""
    return _bilinear(H, 1.0 / res, ox, oy, x, y)


@njit(cache=True, error_model="numpy")
def _bilinear(H, inv_res, ox, oy, x, y):
    """:func:`height_at` with the cells per metre ``inv_res`` (one division less per
    query where several share it)."""
    ny, nx = H.shape
    u = (x - ox) * inv_res
    v = (y - oy) * inv_res
    if u < 0.0:
        u = 0.0
    elif u > nx - 1:
        u = nx - 1.0
    if v < 0.0:
        v = 0.0
    elif v > ny - 1:
        v = ny - 1.0
    i = min(int(u), nx - 2) if nx > 1 else 0
    j = min(int(v), ny - 2) if ny > 1 else 0
    fu = u - i
    fv = v - j
    i1 = min(i + 1, nx - 1)
    j1 = min(j + 1, ny - 1)
    return ((1 - fu) * (1 - fv) * H[j, i] + fu * (1 - fv) * H[j, i1]
            + (1 - fu) * fv * H[j1, i] + fu * fv * H[j1, i1])


@njit(cache=True, error_model="numpy")
def gradient_at(H, res, ox, oy, x, y):
    """Gradient (dz/dx, dz/dy) [m/m] at (x, y) by central differences of the bilinear
    surface over one cell."""
    h = 0.5 * res
    gx = (height_at(H, res, ox, oy, x + h, y) - height_at(H, res, ox, oy, x - h, y)) / (2 * h)
    gy = (height_at(H, res, ox, oy, x, y + h) - height_at(H, res, ox, oy, x, y - h)) / (2 * h)
    return gx, gy


@njit(cache=True, error_model="numpy")
def slope_grades_at(H, res, ox, oy, x, y, yaw, half_length, half_width):
    """Grades [m/m] under a vehicle centred at (x, y) heading yaw: along its heading,
    tan(pitch), from the mean heights under its front and rear axles (half_length ahead
    and behind), and across it, tan(roll), from those under its left and right wheels
    (half_width aside). Positive nose up and left side up. The planner's edges need no
    angles (limits are compared as tangents, the model takes the pitch's sine and
    cosine); :func:`pitch_roll_at` gives the angles."""
    c = math.cos(yaw)
    s = math.sin(yaw)
    fx, fy = half_length * c, half_length * s      # to the front axle
    lx, ly = -half_width * s, half_width * c       # to the left side
    inv = 1.0 / res
    zfl = _bilinear(H, inv, ox, oy, x + fx + lx, y + fy + ly)
    zfr = _bilinear(H, inv, ox, oy, x + fx - lx, y + fy - ly)
    zrl = _bilinear(H, inv, ox, oy, x - fx + lx, y - fy + ly)
    zrr = _bilinear(H, inv, ox, oy, x - fx - lx, y - fy - ly)
    along = (0.5 * (zfl + zfr) - 0.5 * (zrl + zrr)) / (2.0 * half_length)
    across = (0.5 * (zfl + zrl) - 0.5 * (zfr + zrr)) / (2.0 * half_width)
    return along, across


def steepest_near(H: np.ndarray, res: float, reach: float) -> np.ndarray:
    """Per cell (j, i) of the map H (the square from node (j, i) to (j + 1, i + 1);
    shape (ny - 1, nx - 1)): an upper bound [m/m] of the slope of the bilinear surface
    (:func:`height_at`) at every point within ``reach`` [m] of any point of the cell.

    Within a cell the surface's gradient is affine in the position, and its magnitude
    is largest at a corner: the hypotenuse of the larger of the cell's two differences
    along x and the larger of its two along y, over ``res``. The bound is the largest of
    those over the cells within ``reach`` (a square of cells: more than the disc, never
    less; beyond the map's border :func:`height_at` clamps to it, which steepens
    nothing). A grade measured between two points of that region (a vehicle's pitch or
    roll, :func:`slope_grades_at`: a mean of the slope along segments) is at most the
    bound: where it lies within a limit, no footprint there can pass it."""
    H = np.asarray(H, float)
    dx = np.abs(np.diff(H, axis=1))            # (ny, nx - 1)
    dy = np.abs(np.diff(H, axis=0))            # (ny - 1, nx)
    cell = np.hypot(np.maximum(dx[:-1], dx[1:]), np.maximum(dy[:, :-1], dy[:, 1:])) / res
    k = int(math.ceil(reach / res)) + 1
    # the largest over a (2k + 1)-square of cells, the border's cells repeated beyond it:
    # along x, then along y (numpy alone: this file imports nothing but numba's and numpy)
    for axis in (1, 0):
        n = cell.shape[axis]
        pad = np.pad(cell, [(0, 0), (k, k)] if axis == 1 else [(k, k), (0, 0)], mode="edge")
        out = cell.copy()
        for d in range(2 * k + 1):
            np.maximum(out, pad[:, d:d + n] if axis == 1 else pad[d:d + n], out=out)
        cell = out
    return np.ascontiguousarray(cell)


@njit(cache=True, error_model="numpy")
def steepest_at(S, res, ox, oy, x, y):
    """The bound [m/m] of :func:`steepest_near`'s layer S (shape (ny - 1, nx - 1)) for
    the cell holding (x, y) (the nearest cell off the map)."""
    nyc, nxc = S.shape
    i = min(max(int(math.floor((x - ox) / res)), 0), nxc - 1)
    j = min(max(int(math.floor((y - oy) / res)), 0), nyc - 1)
    return S[j, i]


@njit(cache=True, error_model="numpy")
def aside_tilts(H, res, ox, oy, x, y, yaw, half_length, half_width, aside):
    """The larger grade magnitude [m/m] (pitch's or roll's tangent,
    :func:`maps.grid.slope_grades_at`) of the vehicle at (x, y) heading yaw moved
    ``aside`` [m] to its left and to its right (``planner.margin_aside_m``): beside a
    wall the map's roll rises by degrees a centimetre, and a vehicle a few centimetres
    off its predicted pose meets it."""
    lx = -aside * math.sin(yaw)
    ly = aside * math.cos(yaw)
    a1, c1 = slope_grades_at(H, res, ox, oy, x + lx, y + ly, yaw, half_length, half_width)
    a2, c2 = slope_grades_at(H, res, ox, oy, x - lx, y - ly, yaw, half_length, half_width)
    return max(abs(a1), abs(c1), abs(a2), abs(c2))


@njit(cache=True, error_model="numpy")
def pitch_roll_at(H, res, ox, oy, x, y, yaw, half_length, half_width):
    """Pitch and roll [rad] of a vehicle centred at (x, y) heading yaw
    (:func:`slope_grades_at`). Pitch is positive nose up, roll positive when the left
    side is higher (right-hand rotation about the heading)."""
    along, across = slope_grades_at(H, res, ox, oy, x, y, yaw, half_length, half_width)
    return math.atan(along), math.atan(across)


@njit(cache=True, error_model="numpy")
def cell_value(L, res, ox, oy, x, y):
    """Value of the nearest cell of an integer layer L at (x, y); -1 outside the grid."""
    ny, nx = L.shape
    i = int(math.floor((x - ox) / res + 0.5))
    j = int(math.floor((y - oy) / res + 0.5))
    if i < 0 or j < 0 or i >= nx or j >= ny:
        return -1
    return L[j, i]


@dataclass(frozen=True, eq=False)
class ElevationMap:
    """Heights on a regular grid, with an optional terrain-class layer.

    ``heights`` (ny, nx) [m]; ``resolution`` [m/cell]; ``origin`` world (x, y) of the centre
    of cell [0, 0]; ``terrain_layer`` (ny, nx) integer indices into ``terrain_names`` (or
    None: one terrain everywhere).
    """

    heights: np.ndarray
    resolution: float
    origin: tuple = (0.0, 0.0)
    terrain_layer: np.ndarray | None = None
    terrain_names: tuple = ()
    name: str = ""

    def __post_init__(self):
        raw = np.asarray(self.heights)
        if raw.dtype == bool or np.iscomplexobj(raw) or not np.issubdtype(raw.dtype, np.number):
            raise ValueError(f"heights: expected a 2-D array of real heights in metres, found an array of {raw.dtype}")
        H = np.ascontiguousarray(raw, dtype=float)
        if H.ndim != 2 or min(H.shape) < 2:
            raise ValueError(f"heights: expected a 2-D array of at least 2 x 2 cells, found shape {H.shape}")
        if not np.all(np.isfinite(H)):
            raise ValueError("heights: expected finite numbers, found NaN or inf")
        r = self.resolution
        if isinstance(r, bool) or not isinstance(r, (int, float, np.number)) or not (r > 0 and math.isfinite(r)):
            raise ValueError(f"resolution: expected a positive number of metres per cell, found {r!r:.40}")
        o = self.origin
        if not (len(o) == 2 if hasattr(o, "__len__") else False) or not all(
                not isinstance(a, bool) and isinstance(a, (int, float, np.number)) and math.isfinite(a) for a in o):
            raise ValueError(f"origin: expected (x, y), two finite numbers in metres, found {o!r:.60}")
        H.setflags(write=False)
        object.__setattr__(self, "heights", H)
        object.__setattr__(self, "resolution", float(r))
        object.__setattr__(self, "origin", (float(o[0]), float(o[1])))
        if self.terrain_layer is not None:
            raw_layer = np.asarray(self.terrain_layer)
            if not np.issubdtype(raw_layer.dtype, np.integer):
                raise ValueError(f"terrain layer: expected integer indices, found an array of {raw_layer.dtype}")
            Lr = np.ascontiguousarray(raw_layer, dtype=np.int64)
            if Lr.shape != H.shape:
                raise ValueError(f"terrain layer: expected shape {H.shape} like the heights, found {Lr.shape}")
            if Lr.min() < 0 or Lr.max() >= len(self.terrain_names):
                raise ValueError(f"terrain layer: expected indices 0..{len(self.terrain_names) - 1}, found {Lr.min()}..{Lr.max()}")
            Lr.setflags(write=False)
            object.__setattr__(self, "terrain_layer", Lr)

    # geometry ----------------------------------------------------------------------
    @property
    def shape(self):
        return self.heights.shape

    @property
    def extent(self):
        """(x_min, x_max, y_min, y_max) [m] of the cell centres."""
        ny, nx = self.heights.shape
        ox, oy = self.origin
        return ox, ox + (nx - 1) * self.resolution, oy, oy + (ny - 1) * self.resolution

    def contains(self, x, y, margin: float = 0.0) -> bool:
        x0, x1, y0, y1 = self.extent
        return x0 + margin <= x <= x1 - margin and y0 + margin <= y <= y1 - margin

    # queries (Python-facing wrappers of the kernels) -------------------------------
    def height(self, x, y) -> float:
        return height_at(self.heights, self.resolution, self.origin[0], self.origin[1], float(x), float(y))

    def gradient(self, x, y):
        return gradient_at(self.heights, self.resolution, self.origin[0], self.origin[1], float(x), float(y))

    def pitch_roll(self, x, y, yaw, half_length: float, half_width: float):
        return pitch_roll_at(self.heights, self.resolution, self.origin[0], self.origin[1], float(x), float(y),
                             float(yaw), float(half_length), float(half_width))

    def terrain_index(self, x, y) -> int:
        if self.terrain_layer is None:
            return 0 if self.contains(x, y) else -1
        return int(cell_value(self.terrain_layer, self.resolution, self.origin[0], self.origin[1], float(x), float(y)))

    def max_slope_deg(self) -> np.ndarray:
        """Steepest slope [deg] of every cell (from the gradient of the grid)."""
        gy, gx = np.gradient(self.heights, self.resolution)
        return np.degrees(np.arctan(np.hypot(gx, gy)))


def wall_nodata(H: np.ndarray, mode, what: str, why: str, where: str, error) -> np.ndarray:
    """Heights ``H`` with their cells without data (NaN) refused or walled: ``mode``
    'wall' (a map's ``nodata: wall``) raises them to a wall 100 m above the highest cell,
    which no plan crosses; anything else makes ``error`` (the exception class to raise)
    name ``what`` (the file, the layer), how many cells, ``why`` they have none, and the
    remedy ``where.nodata: wall``. All cells without data is an error either way."""
    bad = ~np.isfinite(H)
    if bad.any():
        if mode != "wall":
            raise error(f"{what}: {int(bad.sum())} cells without data ({why}); expected none, or "
                        f"'{where}.nodata: wall' to make them impassable")
        if bad.all():
            raise error(f"{what}: expected some cells with data, found none")
        H[bad] = float(np.nanmax(H)) + 100.0
    return H
