"""Loading maps: ``.npy`` arrays, PNG heightmaps with a height range, and generators.

A map specification is the ``map:`` section of a scenario (paths relative to ``base``)::

    map: {file: maps/two_hills.npy, resolution: 0.25, origin: [0, 0]}
    map: {file: maps/valley.png, resolution: 0.5, origin: [0, 0], height_range: [0.0, 6.0]}
    map: {generate: {size: [60, 60], resolution: 0.25, seed: 3, features: [...]}}
    map: {heights: <2-D array>, resolution: 0.25, origin: [0, 0]}     # from Python
    map: {file: dem.tif}                       # GeoTIFF / DEM (pip install 'sbmpc[geotiff]')
    map: {file: dem.tif, origin: [0, 0], nodata: wall}
    map: {file: walk.bag, topic: /elevation_mapping/elevation_map, layer: elevation}   # maps.gridmap

A GeoTIFF (read with rasterio) brings its own resolution and position: its first band
is the heights [m], its pixels must be square and north-up, its CRS projected (metres;
a geographic CRS in degrees is refused), and ``origin`` defaults to the centre of its
south-west pixel in the file's coordinates (give ``origin: [0, 0]`` to work in a local
frame). Cells without data (the file's nodata value or NaN) are refused unless
``nodata: wall`` turns them into a wall 100 m above the highest cell, which no plan
crosses.

Heights are rows of y and columns of x: ``H[j, i]`` is the height [m] at
``(origin[0] + i * resolution, origin[1] + j * resolution)``; ``origin`` is the world
position of cell [0, 0], the map's south-west corner (as ROS's map origin is the
lower-left pixel's pose).

An 8-bit PNG has 256 grey levels: over a height range of a few metres each level is
a centimetre step, which turns smooth slopes into stairs that the model climbs as
steps. :class:`MapWarning` says so with the step size and the remedy (a 16-bit PNG or
a ``.npy`` array).

PNG heightmaps follow ROS map_server's idea of an image plus metadata: the grey level
(0..max) maps linearly onto ``height_range`` [m]; the image's top row is the map's
northern edge (largest y), as an image is seen from above.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .generate import GeneratorError, generate, unknown_key
from .grid import ElevationMap, wall_nodata
from .gridmap import is_bag, read_gridmap


class MapError(ValueError):
    """A map specification or file is wrong; the message names file or key, expected, found."""


class MapWarning(UserWarning):
    """A map loads but may mislead the planner (an 8-bit PNG's height steps)."""


def _png_header(path: Path) -> bytes | None:
    """The first 26 bytes of a PNG (signature and IHDR up to the bit depth), None if the
    file is not a PNG."""
    with open(path, "rb") as f:
        head = f.read(26)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return head


def png_size(path: Path) -> tuple | None:
    """(width, height) of a PNG from its IHDR chunk, read from the header alone (None if
    the file is not a PNG)."""
    head = _png_header(path)
    return None if head is None else (int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big"))


def refuse_large_png(path: Path) -> None:
    """A MapError naming the file and the limit when a PNG's header claims more than
    MAX_CELLS pixels: judged before the image is decoded (a decompression bomb's 65 535 x
    65 535 header, or a 12 000 x 12 000 image that would take gigabytes to read)."""
    size = png_size(path)
    if size is not None and size[0] * size[1] > MAX_CELLS:
        raise MapError(f"{path}: expected at most {MAX_CELLS // 1_000_000} million cells, found a PNG whose header "
                       f"claims {size[1]} x {size[0]} (crop or coarsen the map)")


def load_npy(path: Path) -> np.ndarray:
    """A .npy array, its shape judged from the header before the data is read (at most
    MAX_CELLS cells); a MapError naming the file otherwise."""
    try:
        with open(path, "rb") as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, _, _ = np.lib.format.read_array_header_1_0(f)
            else:
                shape, _, _ = np.lib.format.read_array_header_2_0(f)
    except (ValueError, OSError, EOFError) as exc:
        raise MapError(f"{path}: expected a NumPy .npy array, found a file that cannot be read as one ({exc})") from None
    cells = 1
    for n in shape:
        cells *= int(n)
    if cells > MAX_CELLS:
        raise MapError(f"{path}: expected at most {MAX_CELLS // 1_000_000} million cells, found a .npy whose header "
                       f"claims shape {tuple(shape)} (crop or coarsen the map)")
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise MapError(f"{path}: expected a NumPy .npy array, found a file that cannot be read as one ({exc})") from None


def png_bit_depth(path: Path) -> int | None:
    """The bit depth of a PNG from its IHDR chunk (None if the file is not a PNG)."""
    head = _png_header(path)
    return None if head is None else head[24]


def _number(spec, key, where, positive=False):
    v = spec.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not -1e300 < v < 1e300 or (positive and v <= 0):
        want = "a positive number" if positive else "a number"
        raise MapError(f"{where}.{key}: expected {want}, found {v!r:.60}")
    return float(v)


def _origin(spec, where):
    o = spec.get("origin", [0.0, 0.0])
    if not (isinstance(o, (list, tuple)) and len(o) == 2
            and all(isinstance(a, (int, float)) and not isinstance(a, bool) and -1e300 < a < 1e300 for a in o)):
        raise MapError(f"{where}.origin: expected [x, y], two finite numbers in metres, found {o!r:.60}")
    return float(o[0]), float(o[1])


def read_png_heights(path: Path, zmin: float, zmax: float) -> np.ndarray:
    """Heights [m] from a greyscale (or colour: mean of RGB) PNG, row 0 = largest y."""
    import matplotlib.image as mpimg
    from PIL import Image
    try:
        with Image.open(path) as im:      # a file cut short (no image data) read as zeros: a flat map
            im.verify()
        img = mpimg.imread(str(path))
    except (OSError, SyntaxError, ValueError) as exc:
        raise MapError(f"{path}: expected a PNG image, found a file that cannot be read as one ({exc})") from None
    img = np.asarray(img, dtype=float)
    if img.ndim == 3:
        img = img[..., :3].mean(axis=2)
    if img.max() > 1.0:       # 16-bit PNGs come as integers in some readers
        img = img / img.max()
    return np.flipud(zmin + (zmax - zmin) * img)


def plain_data(x, key=None):
    """Data from Python as a YAML file would hold it (a map spec, a scenario): NumPy
    scalars as Python numbers, arrays and tuples as lists (a map's ``heights`` kept as it
    is: checked as an array), so that a value computed with NumPy passes the same checks
    as a typed one."""
    if key == "heights":
        return x
    if isinstance(x, dict):
        return {k: plain_data(v, k) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain_data(v) for v in x]
    if isinstance(x, np.ndarray):
        return [plain_data(v) for v in x.tolist()]
    if isinstance(x, np.generic):
        return x.item()
    return x


def load_map(spec, base: Path | str | None = ".", where: str = "map") -> ElevationMap:
    """An :class:`ElevationMap` from a map specification (module doc); ``base`` (None: the
    current folder) is the folder its file paths are relative to."""
    base = Path("." if base is None else base)
    spec = plain_data(spec)
    if not isinstance(spec, dict):
        raise MapError(f"{where}: expected a mapping with 'file' or 'generate', found {spec!r}")
    if "generate" in spec:
        extra = set(spec) - {"generate"}
        if extra:
            k = sorted(extra)[0]
            raise MapError(f"{where}.{k}: expected no key beside 'generate' (a map is generated, or read from 'file' "
                           f"or 'heights'), found '{k}'")
        try:
            return generate(spec["generate"], f"{where}.generate")
        except GeneratorError as exc:
            raise MapError(str(exc)) from None
    if "heights" in spec:
        extra = set(spec) - {"heights", "resolution", "origin"}
        if extra:
            raise MapError(unknown_key(where, sorted(extra)[0], {"heights", "resolution", "origin"}))
        try:
            raw = np.asarray(spec["heights"])
            if raw.dtype == bool or np.iscomplexobj(raw):     # (a cast to float takes them as 0/1, drops j)
                raise TypeError
            H = raw.astype(float)
        except (TypeError, ValueError):
            found = f"an array of {raw.dtype}" if isinstance(spec["heights"], np.ndarray) else type(spec["heights"]).__name__
            raise MapError(f"{where}.heights: expected a 2-D array of real heights in metres, found {found}") from None
        return _checked(H, _number(spec, "resolution", where, positive=True), _origin(spec, where),
                        f"{where}.heights", "heights")
    if isinstance(spec.get("file"), str) and is_bag(base / spec["file"]):
        path = base / spec["file"]
        H, res, own = read_gridmap(path, spec, where, MapError)
        return _checked(H, res, _origin(spec, where) if "origin" in spec else own, str(path), path.stem)
    known = {"file", "resolution", "origin", "height_range", "nodata"}
    extra = set(spec) - known
    if extra:
        raise MapError(unknown_key(where, sorted(extra)[0], known | {"generate"}))
    if not isinstance(spec.get("file"), str):
        raise MapError(f"{where}.file: expected a path to a .npy or .png file, found {spec.get('file')!r}")
    path = base / spec["file"]
    if not path.is_file():
        raise MapError(f"{where}.file: expected an existing file, found no file at '{path}'")
    if path.suffix.lower() in (".tif", ".tiff"):
        H, res, origin = read_geotiff(path, spec, where)
        return _checked(H, res, origin, str(path), path.stem)
    if "nodata" in spec:
        raise MapError(f"{where}.nodata: expected only with a GeoTIFF map, found it with '{path.suffix}'")
    res = _number(spec, "resolution", where, positive=True)
    origin = _origin(spec, where)
    if path.suffix.lower() == ".npy":
        if "height_range" in spec:
            raise MapError(f"{where}.height_range: expected only with a PNG map (a .npy holds heights in metres), "
                           "found it with '.npy'")
        H = load_npy(path)
    elif path.suffix.lower() == ".png":
        hr = spec.get("height_range")
        if not (isinstance(hr, (list, tuple)) and len(hr) == 2
                and all(isinstance(a, (int, float)) and not isinstance(a, bool) and -1e300 < a < 1e300 for a in hr)
                and hr[0] <= hr[1]):
            raise MapError(f"{where}.height_range: expected [z_min, z_max], two finite numbers in metres with "
                           f"z_min <= z_max, for a PNG map, found {_shown(hr)}")
        refuse_large_png(path)
        H = read_png_heights(path, float(hr[0]), float(hr[1]))
        emap = _checked(H, res, origin, str(path), path.stem)
        if png_bit_depth(path) == 8 and hr[1] > hr[0]:
            # warned once the map is known to load: a refusal after it made two lines
            import warnings
            step = (float(hr[1]) - float(hr[0])) / 255.0
            warnings.warn(MapWarning(
                f"{path}: an 8-bit PNG: heights come in steps of {100 * step:.2g} cm over the height range "
                f"[{hr[0]:g}, {hr[1]:g}] m, a {math.degrees(math.atan(step / res)):.1f} deg step between "
                f"neighbouring cells; smooth slopes become stairs. Save the heights as a 16-bit PNG or a .npy "
                f"array"), stacklevel=2)
        return emap
    else:
        raise MapError(f"{where}.file: expected a .npy, .png or .tif file, found '{path.suffix or path.name}'")
    return _checked(H, res, origin, str(path), path.stem)


def _shown(v, limit: int = 60) -> str:
    """A value for a message: a huge integer by its number of digits, else its repr, cut."""
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_shown(a, 20) for a in v[:4]) + (", ..." if len(v) > 4 else "") + "]"
    if isinstance(v, int) and not isinstance(v, bool) and abs(v) >= 10 ** 30:
        if v.bit_length() < 14_000:       # (str() of an int refuses beyond 4 300 digits)
            return f"an integer of {len(str(abs(v)))} digits"
        return f"an integer of about {int(v.bit_length() * 0.30103) + 1} digits"
    return f"{v!r:.{limit}}"


def _read_tif(path: Path) -> tuple:
    """(band 1 as a masked array, affine transform, CRS) of a GeoTIFF, read with rasterio."""
    try:
        import rasterio
    except ImportError:
        raise MapError(f"{path}: reading GeoTIFF files needs rasterio (pip install 'sbmpc[geotiff]')") from None
    try:
        with rasterio.open(path) as ds:
            return ds.read(1, masked=True), ds.transform, ds.crs
    except rasterio.errors.RasterioError as exc:
        raise MapError(f"{path}: expected a GeoTIFF, found a file that cannot be read as one ({exc})") from None


def _linear_units(crs):
    """(unit name, metres per unit) of a projected CRS, or None where it says none."""
    if crs is None:
        return None
    try:
        name, factor = crs.linear_units_factor
        return str(name), float(factor)
    except Exception:               # (rasterio's CRSError: no linear units to read)
        return None


def read_geotiff(path: Path, spec: dict, where: str) -> tuple:
    """(heights with row 0 = south, resolution [m], origin) of a GeoTIFF (module doc)."""
    band, tr, crs = _read_tif(path)
    if "height_range" in spec:
        raise MapError(f"{where}.height_range: expected only with a PNG map (a GeoTIFF holds heights in metres), "
                       f"found it with '{path.suffix}'")
    if crs is not None and crs.is_geographic:
        raise MapError(f"{path}: expected a projected CRS in metres, found {crs.to_string()} (degrees): "
                       "reproject the DEM first (e.g. gdalwarp -t_srs to a UTM zone)")
    units = _linear_units(crs)
    if units is not None and not math.isclose(units[1], 1.0, rel_tol=1e-9):
        raise MapError(f"{path}: expected a projected CRS in metres, found {crs.to_string()} in {units[0]} "
                       f"({units[1]:g} m): reproject the DEM to metres first (e.g. gdalwarp -t_srs to a UTM zone)")
    if np.iscomplexobj(band) or band.dtype == bool or not np.issubdtype(band.dtype, np.number):
        raise MapError(f"{path}: expected real heights, found a band of {band.dtype}")
    if tr.b != 0.0 or tr.d != 0.0 or not math.isclose(tr.a, -tr.e, rel_tol=1e-6) or tr.a <= 0:
        raise MapError(f"{path}: expected square, north-up pixels, found the transform {tuple(tr)[:6]}")
    res = float(tr.a)
    if "resolution" in spec and not math.isclose(_number(spec, "resolution", where, positive=True), res, rel_tol=1e-6):
        raise MapError(f"{where}.resolution: expected the GeoTIFF's own {res:g} m (or nothing), found {spec['resolution']}")
    H = np.ma.filled(band.astype(float), np.nan)
    H = np.flipud(H)                                  # row 0 = the southern edge
    ny = H.shape[0]
    origin = _origin(spec, where) if "origin" in spec else (float(tr.c + 0.5 * tr.a), float(tr.f + (ny - 0.5) * tr.e))
    return wall_nodata(H, spec.get("nodata", "error"), str(path), "nodata", where, MapError), res, origin


def load_class_raster(file: str, base: Path | str, shape: tuple, where: str = "terrain.raster") -> np.ndarray:
    """Integer terrain classes on the map's grid, from a ``.npy`` array (row 0 = south,
    as heights), a PNG (grey levels as integers; top row = north) or a GeoTIFF (band 1,
    top row = north). It must have the map's ``shape`` (rows, columns)."""
    path = Path(base) / file
    if not path.is_file():
        raise MapError(f"{where}.file: expected an existing file, found no file at '{path}'")
    suf = path.suffix.lower()
    if suf == ".npy":
        C = load_npy(path)
    elif suf == ".png":
        refuse_large_png(path)
        from PIL import Image
        try:
            with Image.open(path) as im:
                C = np.flipud(np.asarray(im))
        except OSError as exc:
            raise MapError(f"{path}: expected a PNG image, found a file that cannot be read as one ({exc})") from None
        if C.ndim == 3:
            raise MapError(f"{path}: expected a single-channel (grey) class image, found {C.shape[2]} channels")
    elif suf in (".tif", ".tiff"):
        C = np.flipud(np.ma.getdata(_read_tif(path)[0]))
    else:
        raise MapError(f"{where}.file: expected a .npy, .png or .tif file, found '{path.suffix or path.name}'")
    if C.ndim != 2 or tuple(C.shape) != tuple(shape):
        raise MapError(f"{path}: expected classes on the map's grid, {shape[0]} x {shape[1]} cells, found shape {C.shape}")
    if C.dtype == bool:                   # a 1-bit PNG or a mask: classes 0 and 1
        C = C.astype(np.int64)
    if not np.issubdtype(C.dtype, np.number) or np.iscomplexobj(C):
        raise MapError(f"{path}: expected integer classes, found an array of {C.dtype}")
    if not np.issubdtype(C.dtype, np.integer):
        if not (np.all(np.isfinite(C)) and np.all(C == np.round(C))):
            raise MapError(f"{path}: expected integer classes, found {C.dtype} values with fractions or NaN")
        C = np.round(C)
    return C.astype(np.int64)


MAX_CELLS = 25_000_000     # maps larger than this are refused (about 200 MB of heights)


def _checked(H, res, origin, src: str, name: str) -> ElevationMap:
    if H.ndim != 2 or min(H.shape) < 2 or not np.issubdtype(H.dtype, np.number) or np.iscomplexobj(H):
        raise MapError(f"{src}: expected a 2-D array of real heights of at least 2 x 2, found shape {H.shape} of {H.dtype}")
    if H.size > MAX_CELLS:
        raise MapError(f"{src}: expected at most {MAX_CELLS // 1_000_000} million cells, found {H.shape[0]} x {H.shape[1]} "
                       "(crop or coarsen the map)")
    if not np.all(np.isfinite(H)):
        raise MapError(f"{src}: expected finite heights, found NaN or inf")
    return ElevationMap(np.array(H, dtype=float), res, origin, name=name)
