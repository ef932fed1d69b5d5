import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from maps import ElevationMap, MapError, generate, load_map


def plane(gx=0.2, gy=-0.1, res=0.5, n=41, origin=(-5.0, 3.0)):
    x = origin[0] + np.arange(n) * res
    y = origin[1] + np.arange(n) * res
    X, Y = np.meshgrid(x, y)
    return ElevationMap(1.0 + gx * X + gy * Y, res, origin)


@given(x=st.floats(-4, 14), y=st.floats(4, 22))
def test_bilinear_height_and_gradient_are_exact_on_a_plane(x, y):
    m = plane()
    assert m.height(x, y) == pytest.approx(1.0 + 0.2 * x - 0.1 * y, abs=1e-9)
    gx, gy = m.gradient(x, y)
    assert (gx, gy) == (pytest.approx(0.2, abs=1e-9), pytest.approx(-0.1, abs=1e-9))


@given(yaw=st.floats(-math.pi, math.pi))
def test_pitch_and_roll_on_a_plane(yaw):
    m = plane()
    pitch, roll = m.pitch_roll(5.0, 12.0, yaw, 0.15, 0.2)
    # pitch: slope along the heading; roll: slope to the left (positive when left is higher)
    assert pitch == pytest.approx(math.atan(0.2 * math.cos(yaw) - 0.1 * math.sin(yaw)), abs=1e-9)
    assert roll == pytest.approx(math.atan(-0.2 * math.sin(yaw) - 0.1 * math.cos(yaw)), abs=1e-9)
    back, back_roll = m.pitch_roll(5.0, 12.0, yaw + math.pi, 0.15, 0.2)
    assert back == pytest.approx(-pitch, abs=1e-9) and back_roll == pytest.approx(-roll, abs=1e-9)


def test_row_is_y_and_column_is_x_and_origin_is_cell_centre():
    H = np.zeros((3, 4))
    H[2, 1] = 5.0                    # row 2 (y index), column 1 (x index)
    m = ElevationMap(H, 2.0, (10.0, 20.0))
    assert m.height(12.0, 24.0) == 5.0
    assert m.extent == (10.0, 16.0, 20.0, 24.0)
    assert m.contains(16.0, 24.0) and not m.contains(16.1, 24.0)


def test_npy_and_png_loading(tmp_path):
    H = np.add.outer(np.arange(5.0), np.arange(6.0))       # rises to the north and east
    np.save(tmp_path / "m.npy", H)
    m = load_map({"file": "m.npy", "resolution": 0.5, "origin": [1, 2]}, tmp_path)
    assert m.height(1.0 + 0.5 * 3, 2.0 + 0.5 * 2) == pytest.approx(H[2, 3])
    import matplotlib.image as mpimg
    img = np.flipud(H / H.max())                            # top row of the image = north
    mpimg.imsave(tmp_path / "m.png", img, cmap="gray", vmin=0, vmax=1)
    p = load_map({"file": "m.png", "resolution": 0.5, "height_range": [0, 9.0]}, tmp_path)
    assert p.heights.shape == H.shape
    assert np.allclose(p.heights, H, atol=9.0 / 255 + 1e-9)


@pytest.mark.parametrize("spec, words", [
    ({"file": "none.npy", "resolution": 1}, ["map.file", "no file"]),
    ({"file": "m.npy", "resolution": 0}, ["map.resolution", "positive"]),
    ({"file": "m.npy", "resolution": 1, "origin": [1]}, ["map.origin"]),
    ({"file": "m.npy", "resolution": 1, "size": 3}, ["map.size: expected one of the keys", "found an unknown key"]),
    ({"file": "m.npy", "resolution": 1, "orgin": [0, 0]}, ["map.orgin:", "(did you mean 'origin'?)"]),
    ({"file": "m.png", "resolution": 1}, ["map.height_range"]),
    ({"file": "bad.npy", "resolution": 1}, ["bad.npy", "expected a 2-D array"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "features": [{"type": "volcano"}]}}, ["features[0].type"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "features": [{"type": "hill", "x": 1, "y": 1, "height": 1}]}},
     ["features[0].radius"]),
    # a typo beside the features planned a flat map; degenerate values ended in exit 3
    ({"generate": {"size": [10, 10], "resolution": 1, "featurs": []}}, ["map.generate.featurs", "did you mean 'features'"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "seeds": 3}}, ["map.generate.seeds", "did you mean 'seed'"]),
    ({"generate": {"size": [float("inf"), 10], "resolution": 1}}, ["map.generate.size", "(0, 1e+06]", "inf"]),
    ({"generate": {"size": [1e300, 10], "resolution": 1}}, ["map.generate.size", "1e+300"]),
    ({"generate": {"size": [10, 10], "resolution": 1e-300}}, ["at most 25 million cells, found far more (10 m x 10 m at 1e-300 m)"]),
    ({"generate": {"size": [10, 10], "resolution": 50}}, ["map.generate.resolution", "at least 2 x 2 cells"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "origin": [1]}}, ["map.generate.origin"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "origin": ["a", "b"]}}, ["map.generate.origin"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "base": "x"}}, ["map.generate.base: expected a number"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "seed": -1}}, ["map.generate.seed", "[0, 2^63)"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "features": [
        {"type": "hill", "x": 5, "y": 5, "height": 1, "radius": 1e-300}]}}, ["expected finite heights"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "features": [
        {"type": "hill", "x": 5, "y": 5, "height": 1e300, "radius": 1}]}}, ["height: expected a number in [-10000, 10000]"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "features": [
        {"type": "random_hills", "count": 3, "height": [1, float("nan")], "radius": [1, 2]}]}}, ["features[0].height"]),
    ({"generate": {"size": [10, 10], "resolution": 1, "features": [
        {"type": "random_hills", "count": 3, "height": [1, 2], "radius": [-2, -1]}]}}, ["features[0].radius", "(0, "]),
    ({"generate": {"size": [10, 10], "resolution": 1, "features": [
        {"type": "random_hills", "count": 10 ** 5, "height": [1, 2], "radius": [1, 2]}]}}, ["count", "[0, 10000]"]),
])
def test_bad_map_specs_name_key_expected_found(tmp_path, spec, words):
    np.save(tmp_path / "m.npy", np.zeros((3, 3)))
    np.save(tmp_path / "bad.npy", np.zeros(3))
    (tmp_path / "m.png").write_bytes(b"")
    with pytest.raises(MapError) as err:
        load_map(spec, tmp_path)
    for w in words:
        assert w in str(err.value)


def test_generator_is_deterministic_and_shapes_features():
    desc = {"size": [40, 30], "resolution": 0.5, "seed": 4, "features": [
        {"type": "hill", "x": 10, "y": 10, "height": 2.0, "radius": 3.0},
        {"type": "ramp", "x0": 20, "y0": 5, "x1": 24, "y1": 5, "height": 1.0, "width": 4.0},
        {"type": "ridge", "x0": 2, "y0": 25, "x1": 38, "y1": 25, "height": 1.5, "width": 2.0},
        {"type": "valley", "x0": 2, "y0": 18, "x1": 38, "y1": 18, "depth": 1.0, "width": 3.0},
        {"type": "random_hills", "count": 5, "height": [0.2, 0.5], "radius": [1, 2]}]}
    a, b = generate(desc), generate(desc)
    assert np.array_equal(a.heights, b.heights)
    assert not np.array_equal(a.heights, generate({**desc, "seed": 5}).heights)
    assert a.shape == (61, 81)
    quiet = generate({**desc, "features": desc["features"][:4]})
    assert quiet.height(10, 10) == pytest.approx(2.0, abs=0.01)
    assert quiet.height(22, 5) == pytest.approx(0.5, abs=0.01)          # half way up the ramp
    assert quiet.height(30, 5) == pytest.approx(1.0, abs=0.01)          # level beyond its top
    assert quiet.gradient(22, 5)[0] == pytest.approx(0.25, abs=0.01)    # 1 m over 4 m
    assert quiet.height(20, 25) == pytest.approx(1.5, abs=0.01)
    assert quiet.height(20, 18) == pytest.approx(-1.0, abs=0.01)


def test_terrain_layer_lookup():
    H = np.zeros((4, 4))
    layer = np.zeros((4, 4), int)
    layer[:, 2:] = 1
    m = ElevationMap(H, 1.0, (0, 0), terrain_layer=layer, terrain_names=("asphalt", "grass"))
    assert m.terrain_index(0.2, 1.0) == 0 and m.terrain_index(2.6, 1.0) == 1
    assert m.terrain_index(-3, 0) == -1
    with pytest.raises(ValueError, match="terrain layer"):
        ElevationMap(H, 1.0, terrain_layer=layer, terrain_names=("asphalt",))


def _geotiff(path, H, x0=500000.0, y_top=4000000.0, res=0.5, crs="EPSG:32633", nodata=None):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.transform import from_origin
    with rasterio.open(path, "w", driver="GTiff", height=H.shape[0], width=H.shape[1], count=1, dtype="float32",
                       crs=crs, transform=from_origin(x0, y_top, res, res), nodata=nodata) as ds:
        ds.write(H.astype("float32"), 1)
    return path


def test_a_geotiff_dem_loads_north_up_with_its_own_resolution_and_origin(tmp_path):
    """Rows of a GeoTIFF run north to south; the map's row 0 is the south. The origin is
    the south-west pixel's centre in the file's coordinates, or the one given."""
    H = np.zeros((6, 8))
    H[0, :] = 2.0                                   # the northern row of the file
    _geotiff(tmp_path / "dem.tif", H)
    m = load_map({"file": "dem.tif"}, tmp_path)
    assert m.resolution == 0.5 and m.shape == (6, 8)
    assert m.origin == pytest.approx((500000.25, 4000000.0 - 6 * 0.5 + 0.25))
    assert np.all(m.heights[-1] == 2.0) and np.all(m.heights[0] == 0.0)
    local = load_map({"file": "dem.tif", "origin": [0, 0]}, tmp_path)
    assert local.origin == (0.0, 0.0)
    with pytest.raises(MapError, match="GeoTIFF's own 0.5 m"):
        load_map({"file": "dem.tif", "resolution": 0.25}, tmp_path)


def test_geotiff_nodata_and_degrees_are_handled(tmp_path):
    H = np.ones((5, 5))
    H[2, 2] = -9999.0
    _geotiff(tmp_path / "hole.tif", H, nodata=-9999.0)
    with pytest.raises(MapError, match="1 cells without data"):
        load_map({"file": "hole.tif"}, tmp_path)
    m = load_map({"file": "hole.tif", "nodata": "wall"}, tmp_path)
    assert m.heights[2, 2] == pytest.approx(101.0) and np.isfinite(m.heights).all()
    _geotiff(tmp_path / "geo.tif", np.ones((4, 4)), x0=10.0, y_top=50.0, res=0.001, crs="EPSG:4326")
    with pytest.raises(MapError, match="projected CRS in metres"):
        load_map({"file": "geo.tif"}, tmp_path)


def test_maps_in_feet_cut_short_or_of_the_wrong_kind_are_refused(tmp_path):
    """A DEM in US survey feet was planned as if in metres, a PNG cut after its header
    read as a flat map, an empty .npy and a class raster of text ended in exit 3, and a
    height range beside a GeoTIFF or a .npy was silently ignored."""
    from PIL import Image
    from maps.io import load_class_raster
    _geotiff(tmp_path / "feet.tif", np.ones((4, 4)), x0=6_000_000.0, y_top=2_000_000.0, res=3.0, crs="EPSG:2227")
    with pytest.raises(MapError, match=r"expected a projected CRS in metres, found .* in US survey foot \(0.3048"):
        load_map({"file": "feet.tif"}, tmp_path)
    _geotiff(tmp_path / "m.tif", np.ones((4, 4)))
    with pytest.raises(MapError, match="map.height_range: expected only with a PNG map"):
        load_map({"file": "m.tif", "height_range": [0, 5]}, tmp_path)
    np.save(tmp_path / "h.npy", np.zeros((4, 4)))
    with pytest.raises(MapError, match="map.height_range: expected only with a PNG map"):
        load_map({"file": "h.npy", "resolution": 1, "height_range": [0, 5]}, tmp_path)
    Image.fromarray(np.arange(1600, dtype=np.uint8).reshape(40, 40)).save(tmp_path / "full.png")
    (tmp_path / "cut.png").write_bytes((tmp_path / "full.png").read_bytes()[:60])
    with pytest.raises(MapError, match="expected a PNG image, found a file that cannot be read as one"):
        load_map({"file": "cut.png", "resolution": 1, "height_range": [0, 1]}, tmp_path)
    (tmp_path / "empty.npy").write_bytes(b"")
    with pytest.raises(MapError, match="expected a NumPy .npy array"):
        load_map({"file": "empty.npy", "resolution": 1}, tmp_path)
    np.save(tmp_path / "mask.npy", np.eye(4, dtype=bool))              # a boolean mask is classes 0 and 1
    assert load_class_raster("mask.npy", tmp_path, (4, 4)).tolist() == np.eye(4, dtype=int).tolist()
    np.save(tmp_path / "text.npy", np.full((4, 4), "grass"))
    with pytest.raises(MapError, match="expected integer classes, found an array of <U5"):
        load_class_raster("text.npy", tmp_path, (4, 4))


from hypothesis import given, settings, strategies as st  # noqa: E402

_ANY = st.one_of(st.none(), st.booleans(), st.integers(-10**40, 10**40), st.floats(allow_nan=True, allow_infinity=True),
                 st.text(max_size=6), st.lists(st.floats(-1e3, 1e3), max_size=3))
_FEATURE = st.fixed_dictionaries({"type": st.sampled_from(["hill", "plateau", "ramp", "ridge", "valley", "random_hills"])},
                                 optional={k: _ANY for k in ("x", "y", "x0", "y0", "x1", "y1", "height", "depth",
                                                             "radius", "edge", "width", "count")})


@settings(max_examples=300, deadline=None)
@given(top=st.dictionaries(st.sampled_from(["size", "resolution", "origin", "seed", "base", "name", "seeds"]), _ANY,
                           max_size=4),
       features=st.lists(_FEATURE, max_size=3))
def test_any_generator_description_gives_a_finite_map_or_one_named_error(top, features):
    """Random descriptions around a valid one (10 m x 8 m at 0.5 m): either a map of
    finite heights or a GeneratorError naming a key under map.generate, never another
    exception (an overflow, an IndexError or NaN heights were exit 3 or a flat map)."""
    from maps.generate import GeneratorError
    desc = {"size": [10, 8], "resolution": 0.5, **top, "features": features}
    try:
        m = generate(desc)
    except GeneratorError as exc:
        assert str(exc).startswith("map.generate") and "\n" not in str(exc)
        return
    assert np.isfinite(m.heights).all() and min(m.heights.shape) >= 2


def test_an_elevation_map_from_python_is_checked_and_numpy_numbers_pass():
    """ElevationMap took a NaN origin (every height NaN), boolean or complex heights, a
    resolution of True and fractional terrain indices (truncated); load_map refused
    np.float32 resolutions and array origins as 'expected a positive number'."""
    H = np.zeros((10, 10))
    for kw, says in [(dict(origin=(np.nan, 0.0)), "origin: expected"), (dict(resolution=True), "resolution: expected"),
                     (dict(heights=H.astype(bool)), "found an array of bool"),
                     (dict(heights=H.astype(complex)), "found an array of complex128"),
                     (dict(terrain_layer=np.full((10, 10), 0.7), terrain_names=("a",)), "expected integer indices")]:
        with pytest.raises(ValueError, match=says):
            ElevationMap(**{"heights": H, "resolution": 0.5, **kw})
    m = load_map({"heights": H, "resolution": np.float32(0.5), "origin": np.array([1.0, 2.0])}, None)
    assert m.origin == (1.0, 2.0) and m.resolution == 0.5
    assert load_map({"generate": {"size": [10, 10], "resolution": 0.5, "seed": np.int64(3)}}).shape == (21, 21)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), rough=st.floats(0.005, 0.4), reach=st.floats(0.05, 1.0))
def test_no_footprint_within_reach_is_steeper_than_the_steepest_near_bound(seed, rough, reach):
    """maps.grid.steepest_near bounds every grade a footprint within its reach can
    measure (the edges skip the margin's check aside where the bound is within the
    limit): on random rough maps, at random poses, the pitch and roll (tangents) of a
    footprint whose corners and allowance aside lie within ``reach`` of its centre are
    at most the bound of the centre's cell; and the bound is not loose by orders (on a
    plane it is the plane's slope)."""
    from maps.grid import aside_tilts, slope_grades_at, steepest_at, steepest_near
    rng = np.random.default_rng(seed)
    H = rng.normal(0.0, rough, (24, 31)).cumsum(axis=1)
    res = 0.25
    S = steepest_near(H, res, reach)
    assert S.shape == (23, 30)
    hl, hw = 0.3 * reach, 0.4 * reach
    aside = math.sqrt(reach ** 2 - hl ** 2) - hw
    for _ in range(200):
        x, y = rng.uniform(-0.5, 30 * res + 0.5), rng.uniform(-0.5, 23 * res + 0.5)
        yaw = rng.uniform(-math.pi, math.pi)
        b = steepest_at(S, res, 0.0, 0.0, x, y)
        a, c = slope_grades_at(H, res, 0.0, 0.0, x, y, yaw, hl, hw)
        assert max(abs(a), abs(c)) <= b + 1e-12
        assert aside_tilts(H, res, 0.0, 0.0, x, y, yaw, hl, hw, aside) <= b + 1e-12
    gx, gy = 0.12, -0.05
    plane = gx * np.arange(31)[None, :] * res + gy * np.arange(24)[:, None] * res
    np.testing.assert_allclose(steepest_near(plane, res, reach), math.hypot(gx, gy), rtol=1e-12)
