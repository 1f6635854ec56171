"""The map of a run as an MCAP that Foxglove draws with its standard schemas, no plugins.

* ``/map`` — ``foxglove.Grid``: the rasterised fused map in frame ``map``, one int8 field
  ``occupancy`` valued as ``nav_msgs/OccupancyGrid`` (0 free, 100 occupied, -1 unknown),
  row 0 at the grid's pose (its lower-left corner), columns along +x. A raster of more than
  :data:`MAX_GRID_CELLS` cells is drawn in blocks of k x k cells (:func:`grid_values`).
* ``/positions`` — ``foxglove.SceneUpdate``: one message per position on its timestamp,
  an entity with the position's navigation polygon (line loops), its obstacle points
  (red spheres) and exploration points (green spheres), in frame ``map``.
* ``/tf`` — ``foxglove.FrameTransform``, only when the poses were registered
  (:mod:`occtool.register`): ``map`` -> ``base_link`` of every scan on its timestamp.

Written with ``mcap-protobuf-support`` and ``foxglove-schemas-protobuf`` (the
``protobuf`` extra).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np

from occtool.errors import MissingDependencyError
from occtool.raster import FREE, OCCUPIED

GRID_TOPIC = "/map"
SCENE_TOPIC = "/positions"
FRAME = "map"
TF_TOPIC = "/tf"
BASE_FRAME = "base_link"
POINT_DIAMETER = 0.1
#: Most cells of the ``/map`` grid: a raster of more is drawn coarser, in whole blocks of
#: cells (a Foxglove panel draws no more, and the grid's bytes are held three times over
#: while the MCAP is made: the campus at 0.02 m, 129 M cells, would take 0.4 GB).
MAX_GRID_CELLS = 1 << 25


def grid_values(raster: Any, max_cells: int = MAX_GRID_CELLS) -> tuple[Any, int]:
    """The ``/map`` grid's int8 values of ``raster`` (0 free, 100 occupied, -1 unknown) and
    its block side k: 1 when the raster has at most ``max_cells`` cells, else the least k
    that brings it under, each k x k block (cut at the raster's edges) occupied when a cell
    of it is, else free when a cell is, else unknown. Computed a strip of rows at a time."""
    rows, cols = raster.shape
    k = 1
    while -(-rows // k) * -(-cols // k) > max_cells:
        k += 1
    out_rows, out_cols = -(-rows // k), -(-cols // k)
    values = np.full((out_rows, out_cols), -1, dtype=np.int8)
    step = k * max(1, (1 << 22) // max(1, cols * k))  # whole blocks of rows, about 4 M cells
    for low in range(0, rows, step):
        cells = raster.cells[low:low + step]
        if k == 1:
            strip = values[low:low + step]
            strip[cells == FREE] = 0
            strip[cells == OCCUPIED] = 100
            continue
        blocks = _block_ranks(cells, k, out_cols)
        values[low // k:low // k + blocks.shape[0]] = _RANK_VALUES[blocks]
    return values, k


#: Each rank of a block's cells (0 neither free nor occupied, 1 free, 2 occupied: the highest
#: counts) as its grid value.
_RANK_VALUES = np.array([-1, 0, 100], dtype=np.int8)


def _block_ranks(cells: Any, k: int, out_cols: int) -> Any:
    """The highest rank (:data:`_RANK_VALUES`) of each k x k block of ``cells`` (blocks cut at
    the edges: what lies past them ranks 0), by a maximum over each of the k columns of a
    block and then each of its k rows: an eighth of the time of comparing whole blocks
    (the campus x2's 63 M cells, 0.8 s)."""
    rows, cols = cells.shape
    ranks = np.zeros((-(-rows // k) * k, out_cols * k), dtype=np.uint8)
    # By comparisons, not a table lookup: np.take's indices become an 8-byte array a cell.
    inner = ranks[:rows, :cols]
    inner[...] = cells == FREE
    inner[cells == OCCUPIED] = 2
    del inner
    across = ranks[:, 0::k].copy()
    for j in range(1, k):
        np.maximum(across, ranks[:, j::k], out=across)
    del ranks
    blocks = across[0::k].copy()
    for j in range(1, k):
        np.maximum(blocks, across[j::k], out=blocks)
    return blocks


def _imports() -> Any:
    try:
        from foxglove_schemas_protobuf import (
            Color_pb2,
            Grid_pb2,
            LinePrimitive_pb2,
            PackedElementField_pb2,
            Point3_pb2,
            Pose_pb2,
            Quaternion_pb2,
            SceneEntity_pb2,
            SceneUpdate_pb2,
            SpherePrimitive_pb2,
            Vector2_pb2,
            Vector3_pb2,
        )
        from mcap_protobuf.writer import Writer
    except ImportError as exc:
        raise MissingDependencyError("foxglove-schemas-protobuf", "protobuf", "writing the map's MCAP") from exc
    return (Color_pb2, Grid_pb2, LinePrimitive_pb2, PackedElementField_pb2, Point3_pb2, Pose_pb2, Quaternion_pb2,
            SceneEntity_pb2, SceneUpdate_pb2, SpherePrimitive_pb2, Vector2_pb2, Vector3_pb2, Writer)


#: Latest stamp written as a time (seconds): signed 64-bit nanoseconds end in the year 2262.
_LAST_STAMP = float(2**63 - 1) / 1e9


def _nanoseconds(stamp: float | None, fallback: int) -> int:
    # A stamp that is no time (negative, NaN, past int64 nanoseconds) keeps the message's order instead.
    return round(stamp * 1e9) if stamp is not None and 0 <= stamp < _LAST_STAMP else fallback


def _point3_records(field: Any, point3: Any) -> Any:
    """A function of ``xy`` ``(N, 2)`` giving the protobuf wire bytes of ``N`` values of the
    repeated ``foxglove.Point3`` field ``field`` (a field descriptor), z = 0: each a
    length-delimited record of its x and y as 64-bit doubles, little-endian as the wire
    format has them. A message parses them in one call (``MergeFromString``, the same message
    as one built point by point): a Python object a point took three of the four seconds of
    the campus's MCAP (1.1 M outline points)."""

    def tag(number: int, wire_type: int) -> int:
        value = number << 3 | wire_type
        assert value < 0x80, "one-byte tags: the field numbers of foxglove.Point3 and its parents are small"
        return value

    x, y = point3.DESCRIPTOR.fields_by_name["x"].number, point3.DESCRIPTOR.fields_by_name["y"].number
    record = np.dtype([("tag", "u1"), ("length", "u1"), ("x_tag", "u1"), ("x", "<f8"), ("y_tag", "u1"),
                       ("y", "<f8")])
    length, fixed64 = 2, 1  # the wire types of a length-delimited field and of a double
    head = (tag(field.number, length), record.itemsize - 2, tag(x, fixed64), tag(y, fixed64))

    def records(xy: Any) -> bytes:
        out = np.empty(len(xy), dtype=record)
        out["tag"], out["length"], out["x_tag"], out["y_tag"] = head
        out["x"], out["y"] = xy[:, 0], xy[:, 1]
        return out.tobytes()

    return records


def run_map_mcap_bytes(run: Any) -> bytes:
    """The MCAP file of a :class:`occtool.fuse.RunMap`, as bytes (:func:`write_run_map_mcap`)."""
    buffer = io.BytesIO()
    write_run_map_mcap(run, buffer)
    return buffer.getvalue()


def write_run_map_mcap(run: Any, buffer: Any) -> None:
    """Write the MCAP file of a :class:`occtool.fuse.RunMap` to the binary stream ``buffer``
    (a file the caller writes atomically: the file is written as it is made, never held whole)."""
    (Color_pb2, Grid_pb2, LinePrimitive_pb2, PackedElementField_pb2, Point3_pb2, Pose_pb2, Quaternion_pb2,
     SceneEntity_pb2, SceneUpdate_pb2, SpherePrimitive_pb2, Vector2_pb2, Vector3_pb2, Writer) = _imports()
    from google.protobuf.timestamp_pb2 import Timestamp

    def stamp_of(ns: int) -> Any:
        t = Timestamp()
        t.FromNanoseconds(ns)
        return t

    identity = Quaternion_pb2.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    red = Color_pb2.Color(r=0.85, g=0.1, b=0.1, a=1.0)
    green = Color_pb2.Color(r=0.1, g=0.7, b=0.2, a=1.0)
    blue = Color_pb2.Color(r=0.1, g=0.4, b=0.9, a=1.0)
    size = Vector3_pb2.Vector3(x=POINT_DIAMETER, y=POINT_DIAMETER, z=POINT_DIAMETER)
    point_records = _point3_records(LinePrimitive_pb2.LinePrimitive.DESCRIPTOR.fields_by_name["points"],
                                    Point3_pb2.Point3)
    writer = Writer(buffer)
    last = 0
    for k, item in enumerate(run.placed):
        ns = _nanoseconds(item.stamp, k * 100_000_000)
        last = max(last, ns)
        entity = SceneEntity_pb2.SceneEntity(timestamp=stamp_of(ns), frame_id=FRAME, id=f"position-{item.position}")
        geometry = item.nav.polygon
        polygons = [geometry] if geometry.geom_type == "Polygon" else list(getattr(geometry, "geoms", []))
        for polygon in polygons:
            if polygon.is_empty:
                continue
            for ring in [polygon.exterior, *polygon.interiors]:
                line = LinePrimitive_pb2.LinePrimitive(
                    type=LinePrimitive_pb2.LinePrimitive.LINE_LOOP,
                    pose=Pose_pb2.Pose(position=Vector3_pb2.Vector3(x=0.0, y=0.0, z=0.0), orientation=identity),
                    thickness=0.03, scale_invariant=False, color=blue)
                line.MergeFromString(point_records(np.asarray(ring.coords)[:-1]))
                entity.lines.append(line)
        for points, color in ((item.nav.obstacle_points, red), (item.nav.exploration_points, green)):
            for x, y in np.asarray(points, dtype=np.float64).reshape(-1, 2):
                entity.spheres.append(SpherePrimitive_pb2.SpherePrimitive(
                    pose=Pose_pb2.Pose(position=Vector3_pb2.Vector3(x=float(x), y=float(y), z=0.0),
                                       orientation=identity), size=size, color=color))
        writer.write_message(SCENE_TOPIC, SceneUpdate_pb2.SceneUpdate(entities=[entity]), log_time=ns,
                             publish_time=ns)
    raster = run.raster
    values, k = grid_values(raster)
    cols = values.shape[1]
    grid = Grid_pb2.Grid(
        timestamp=stamp_of(last), frame_id=FRAME,
        pose=Pose_pb2.Pose(position=Vector3_pb2.Vector3(x=raster.origin[0], y=raster.origin[1], z=0.0),
                           orientation=identity),
        column_count=cols, cell_size=Vector2_pb2.Vector2(x=raster.resolution * k, y=raster.resolution * k),
        row_stride=cols, cell_stride=1,
        fields=[PackedElementField_pb2.PackedElementField(name="occupancy", offset=0,
                                                          type=PackedElementField_pb2.PackedElementField.INT8)],
        data=values.tobytes(),
    )
    del values
    writer.write_message(GRID_TOPIC, grid, log_time=last, publish_time=last)
    _write_trajectory(writer, getattr(run, "trajectory", None) or [], stamp_of)
    writer.finish()


def _write_trajectory(writer: Any, trajectory: list[Any], stamp_of: Any) -> None:
    """The registered poses as ``foxglove.FrameTransform`` on ``/tf``: ``map`` -> ``base_link``,
    one a scan on its timestamp (what ``occtool map --register`` estimated)."""
    if not trajectory:
        return
    from foxglove_schemas_protobuf import FrameTransform_pb2, Quaternion_pb2, Vector3_pb2

    for k, (stamp, pose) in enumerate(trajectory):
        ns = _nanoseconds(stamp, k * 100_000_000)
        half = pose.yaw / 2.0
        message = FrameTransform_pb2.FrameTransform(
            timestamp=stamp_of(ns), parent_frame_id=FRAME, child_frame_id=BASE_FRAME,
            translation=Vector3_pb2.Vector3(x=pose.x, y=pose.y, z=pose.z),
            rotation=Quaternion_pb2.Quaternion(x=0.0, y=0.0, z=float(np.sin(half)), w=float(np.cos(half))))
        writer.write_message(TF_TOPIC, message, log_time=ns, publish_time=ns)


__all__ = ["BASE_FRAME", "FRAME", "GRID_TOPIC", "MAX_GRID_CELLS", "SCENE_TOPIC", "TF_TOPIC", "grid_values",
           "run_map_mcap_bytes", "write_run_map_mcap"]
