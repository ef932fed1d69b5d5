"""Elevation maps from a ROS bag's ``grid_map_msgs/GridMap`` (ANYbotics' grid_map, the
format of elevation_mapping), read with the optional ``rosbags`` package.

A scenario names the bag as its map file::

    map: {file: walk.bag, topic: /elevation_mapping/elevation_map, layer: elevation}
    map: {file: walk_ros2/, layer: elevation, message: 0, origin: [0, 0], nodata: wall}

``topic`` (default: the bag's only GridMap topic), ``layer`` (default ``elevation``),
``message`` (which message of the topic, 0 the first, -1 the last; default -1), ``origin``
(default: the map's own position in its frame) and ``nodata``. A grid map stores its
layers as column-major ``Float32MultiArray`` s (``column_index``, ``row_index``) of a
circular buffer starting at (``outer_start_index``, ``inner_start_index``); cell (0, 0)
is its corner of largest x and y, index i running down x and j down y, cell centres
``resolution`` apart about ``info.pose`` (which must not rotate the map). Cell centres
become the elevation map's nodes. NaN cells (unobserved) are refused with their count
unless ``nodata: wall`` makes them a wall 100 m above the highest cell.

``rosbags`` knows no grid_map types: the message definitions below (ROS 2 and ROS 1)
are registered from their text.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .grid import wall_nodata

GRID_MAP_MSG_ROS2 = {
    "grid_map_msgs/msg/GridMapInfo": """float64 resolution
float64 length_x
float64 length_y
geometry_msgs/Pose pose
""",
    "grid_map_msgs/msg/GridMap": """std_msgs/Header header
grid_map_msgs/GridMapInfo info
string[] layers
string[] basic_layers
std_msgs/Float32MultiArray[] data
uint16 outer_start_index
uint16 inner_start_index
""",
}
GRID_MAP_MSG_ROS1 = {
    "grid_map_msgs/msg/GridMapInfo": """std_msgs/Header header
float64 resolution
float64 length_x
float64 length_y
geometry_msgs/Pose pose
""",
    "grid_map_msgs/msg/GridMap": """grid_map_msgs/GridMapInfo info
string[] layers
string[] basic_layers
std_msgs/Float32MultiArray[] data
uint16 outer_start_index
uint16 inner_start_index
""",
}
GRID_MAP = "grid_map_msgs/msg/GridMap"
KEYS = {"file", "topic", "layer", "message", "origin", "nodata"}


def typestore(ros1: bool = False):
    """A rosbags type store that knows grid_map_msgs (ROS 2 Humble's, or ROS 1 Noetic's)."""
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types = {}
    for name, text in (GRID_MAP_MSG_ROS1 if ros1 else GRID_MAP_MSG_ROS2).items():
        types.update(get_types_from_msg(text, name))
    ts.register(types)
    return ts


def is_bag(path: Path) -> bool:
    """A ROS 1 .bag file or a ROS 2 bag folder (its metadata.yaml)."""
    return (path.is_file() and path.suffix.lower() == ".bag") or (path.is_dir() and (path / "metadata.yaml").is_file())


def any_reader(path: Path, default_typestore):
    """A ``rosbags`` AnyReader (not yet opened) of the bag at ``path``: a folder is a ROS 2
    bag whatever its name, a file a ROS 1 bag. ``ros2 bag record -o drive.bag`` makes a
    folder named ``drive.bag``, which AnyReader takes for ROS 1 by its suffix and refuses
    ("Is a directory"): such a folder is read through a link of another name to it,
    removed with the reader."""
    import shutil
    import tempfile
    import weakref
    from rosbags.highlevel import AnyReader
    path = Path(path)
    link = None
    if path.is_dir() and path.suffix == ".bag":
        link = Path(tempfile.mkdtemp(prefix="sbmpc-bag-")) / "ros2-bag"
        link.symlink_to(path.resolve(), target_is_directory=True)
    reader = AnyReader([link or path], default_typestore=default_typestore)
    if link is not None:
        weakref.finalize(reader, shutil.rmtree, str(link.parent), True)
    return reader


def read_gridmap(path: Path, spec: dict, where: str, error) -> tuple:
    """(heights H[j, i] [m], resolution [m], origin (x, y) [m]) of the grid map layer the
    map ``spec`` names in the bag at ``path``; ``error(message)`` makes the exception to raise."""
    try:
        import rosbags  # noqa: F401
    except ImportError:
        raise error(f"{where}.file: a ROS bag map needs the rosbags package: pip install 'sbmpc[ros]'") from None
    extra = set(spec) - KEYS
    if extra:
        raise error(f"{where}.{sorted(extra)[0]}: expected one of {', '.join(sorted(KEYS))} for a ROS bag map, "
                    f"found an unknown key")
    layer = spec.get("layer", "elevation")
    index = spec.get("message", -1)
    if not isinstance(index, int) or isinstance(index, bool):
        raise error(f"{where}.message: expected an integer (0 the first message, -1 the last), found {index!r:.40}")
    ros1 = path.is_file()
    try:
        with any_reader(path, typestore(ros1)) as reader:
            grids = sorted({c.topic for c in reader.connections if c.msgtype == GRID_MAP})
            topic = spec.get("topic")
            if topic is None:
                if len(grids) != 1:
                    raise error(f"{where}.topic: expected the {GRID_MAP} topic to read (the bag has "
                                f"{len(grids) or 'no'} such topics{': ' + ', '.join(grids) if grids else ''}), "
                                "found nothing")
                topic = grids[0]
            if topic not in grids:
                have = ", ".join(f"{c.topic} ({c.msgtype})" for c in reader.connections) or "none"
                raise error(f"{path}: expected the topic {topic} ({GRID_MAP}), found the topics {have}")
            conns = [c for c in reader.connections if c.topic == topic]
            raws = [(conn, raw) for conn, _, raw in reader.messages(connections=conns)]
            if not raws:
                raise error(f"{path}: topic {topic}: expected a message, found none")
            if not -len(raws) <= index < len(raws):
                raise error(f"{where}.message: expected an index in [{-len(raws)}, {len(raws) - 1}] (the topic has "
                            f"{len(raws)} messages), found {index}")
            conn, raw = raws[index]
            msg = reader.deserialize(raw, conn.msgtype)
    except error:
        raise
    except Exception as exc:
        raise error(f"{path}: expected a ROS bag with a {GRID_MAP} message, found one that cannot be read "
                    f"({' '.join(str(exc).split())[:200]})") from None
    return gridmap_heights(msg, layer, spec.get("nodata", "error"), where, str(path), error)


def gridmap_heights(msg, layer: str = "elevation", nodata: str = "error", where: str = "map",
                    source: str = "grid map", error=ValueError) -> tuple:
    """(heights H[j, i] [m], resolution [m], origin (x, y) [m] of cell [0, 0]) of one layer
    of a ``grid_map_msgs/GridMap`` message (a deserialized one from a bag, or rclpy's: the
    fields are the same); ``nodata``: 'error' refuses NaN cells, 'wall' makes them
    impassable. ``error``: the exception raised, with one line naming ``source``."""
    path = source
    if layer not in msg.layers:
        raise error(f"{where}.layer: expected one of the grid map's layers {', '.join(msg.layers)}, found {layer!r}")
    arr = msg.data[list(msg.layers).index(layer)]
    info = msg.info
    res = float(info.resolution)
    rows, cols = int(round(info.length_x / res)), int(round(info.length_y / res))
    dims = {d.label: d.size for d in arr.layout.dim}
    data = np.asarray(arr.data, float)
    if res <= 0 or data.size != rows * cols or dims.get("column_index", cols) != cols:
        raise error(f"{path}: layer {layer}: expected {rows} x {cols} cells (length {info.length_x:g} x "
                    f"{info.length_y:g} m at {res:g} m) in column_index/row_index order, found {data.size} values "
                    f"(dims {dims})")
    q = info.pose.orientation
    if abs(2.0 * math.atan2(q.z, q.w)) > 1e-6 or abs(q.x) > 1e-9 or abs(q.y) > 1e-9:
        raise error(f"{path}: expected a grid map aligned with its frame (identity orientation), found the "
                    f"quaternion ({q.x:g}, {q.y:g}, {q.z:g}, {q.w:g})")
    M = data.reshape(cols, rows).T                          # M[i, j]: column-major, i down x, j down y
    M = np.roll(M, (-int(msg.outer_start_index), -int(msg.inner_start_index)), axis=(0, 1))
    H = M[::-1, ::-1].T.copy()                              # H[j, i] up y and up x
    px, py = info.pose.position.x, info.pose.position.y
    own = (px - 0.5 * info.length_x + 0.5 * res, py - 0.5 * info.length_y + 0.5 * res)
    return wall_nodata(H, nodata, f"{path}: layer {layer}", "NaN: not observed", where, error), res, own


__all__ = ["GRID_MAP_MSG_ROS1", "GRID_MAP_MSG_ROS2", "any_reader", "gridmap_heights", "is_bag", "read_gridmap", "typestore"]
