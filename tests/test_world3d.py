"""The 3D world map (issue 35): a synthetic room of floor, walls and a table seen from a few poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from occtool.errors import InputError
from occtool.features import Features, Pose, Position, RangeLog
from occtool.formats import occmap3d
from occtool.fuse._log3d import map_log_3d
from occtool.fuse._world3d import WorldMap3D, build_world_map_3d, load_map_3d

ROOM = 4.0  # a 4 m square room, floor at z = 0, no ceiling
TABLE = (1.5, 2.5, 0.8)  # x and y from 1.5 to 2.5, top at 0.8 m
RANGE = 6.0
SENSORS = ((1.0, 1.0, 1.2), (3.0, 1.0, 1.2), (1.0, 3.0, 1.2), (3.0, 3.0, 1.2))


def _cast(origin: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """End points and hits of rays from ``origin`` in the room (cut at :data:`RANGE`: free only)."""
    t = np.full(len(directions), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, value in ((0, 0.0), (0, ROOM), (1, 0.0), (1, ROOM), (2, 0.0)):
            s = (value - origin[axis]) / directions[:, axis]
            t = np.minimum(t, np.where(s > 0, s, np.inf))
        s = (TABLE[2] - origin[2]) / directions[:, 2]
    top = origin + s[:, None] * directions
    inside = (top[:, :2] > TABLE[0]) & (top[:, :2] < TABLE[1])
    on_table = (s > 0) & inside.all(axis=1)
    t = np.where(on_table & (s < t), s, t)
    hit = t < RANGE
    return origin + np.where(hit, t, RANGE)[:, None] * directions, hit


def _rays(n: int = 6000, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    origins, ends, hits = [], [], []
    for sensor in SENSORS:
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        end, hit = _cast(np.array(sensor), d)
        origins.append(np.tile(sensor, (n, 1)))
        ends.append(end)
        hits.append(hit)
    return np.concatenate(origins), np.concatenate(ends), np.concatenate(hits)


@pytest.fixture(scope="module")
def room() -> WorldMap3D:
    return build_world_map_3d(*_rays(), resolution=0.2)


def test_surfaces_high_free_low_unseen_unknown(room: WorldMap3D) -> None:
    surfaces = np.array([[2.0, 1.1, 0.0], [0.0, 2.1, 1.0], [3.9, 4.0, 0.5], [2.0, 2.0, 0.8], [1.7, 2.3, 0.8]])
    assert (room.predict(surfaces) > 0.8).all()
    free = np.array([[2.0, 2.0, 1.3], [1.0, 2.0, 0.5], [3.0, 3.0, 2.0], [2.0, 0.6, 0.4]])
    # Crossed cells lie between the free level and unknown, the lower the more rays crossed them.
    p = room.predict(free)
    assert ((p >= room.free_level) & (p < 0.4)).all()
    behind = np.array([[-0.6, 2.0, 1.0], [2.0, 4.7, 0.5], [2.0, 2.0, -0.6], [4.5, -0.5, 1.5]])
    np.testing.assert_array_equal(room.predict(behind), 0.5)


def test_round_trip_answers_bit_identically(room: WorldMap3D, tmp_path) -> None:
    path = tmp_path / "world.occmap"
    size = room.save(path)
    assert size == path.stat().st_size
    back = load_map_3d(path)
    grid = np.stack(np.meshgrid(*[np.linspace(-0.5, 4.5, 21)] * 2, np.linspace(-0.5, 2.5, 13), indexing="ij"),
                    axis=-1).reshape(-1, 3)
    np.testing.assert_array_equal(back.predict(grid), room.predict(grid))
    assert occmap3d.encode(back) == path.read_bytes()


def test_damaged_files_are_one_line(room: WorldMap3D, tmp_path) -> None:
    data = occmap3d.encode(room)
    rng = np.random.default_rng(1)
    broken = [data[:-1], data[: len(data) // 2], b"", b"not a map at all", data[:20] + b"\x00" + data[21:]]
    for at in rng.integers(0, len(data), 20):
        flipped = bytearray(data)
        flipped[at] ^= 0xFF
        broken.append(bytes(flipped))
    for k, bad in enumerate(broken):
        path = tmp_path / f"bad{k}.occmap"
        path.write_bytes(bad)
        with pytest.raises(InputError) as caught:
            load_map_3d(path)
        assert "\n" not in str(caught.value)


def test_map_is_max_over_patches_of_min_over_linear_pieces(room: WorldMap3D) -> None:
    """Evaluate the tree by hand: every patch's MIN over its seven linear pieces (floored at 0,
    itself a linear piece), the MAX over all patches and the cell's constant."""
    points = np.array([[2.0, 2.0, 0.83], [0.05, 1.3, 0.9], [2.6, 2.4, 0.75], [1.0, 1.0, 0.04], [2.0, 2.0, 1.5]])
    n = room.patch_count
    pieces = np.stack([room.linear_pieces(i) for i in range(n)])  # (S, 7, 4)
    values = np.einsum("spk,qk->qsp", pieces[:, :, :3], points) + pieces[:, :, 3]
    by_hand = np.maximum(np.maximum(values.min(axis=2), 0.0).max(axis=1), room.background(points))
    np.testing.assert_allclose(room.predict(points), by_hand, atol=1e-12)


def test_falls_monotonically_away_from_a_surface(room: WorldMap3D) -> None:
    g = room.geometry
    steps = np.linspace(0.0, 0.4, 41)
    for index in np.flatnonzero(g.trust > 0.9)[:50]:
        line = g.centres[index] + steps[:, None] * g.normals[index]
        ridge = room.ridge(line, np.full(len(steps), index))
        assert (np.diff(ridge) <= 1e-12).all() and ridge[0] == g.trust[index] and ridge[-1] == 0.0
    # Up from the table top into the free space above it, the map itself falls to the free level.
    column = np.column_stack([np.full(30, 2.05), np.full(30, 1.95), np.linspace(0.8, 1.4, 30)])
    values = room.predict(column)
    assert values[0] > 0.9 and (np.diff(values) <= 1e-12).all() and values[-1] == room.background(column[-1:])[0] < 0.5


def test_a_range_log_maps_in_the_frame_of_its_poses() -> None:
    origins, ends, hits = _rays(1500)
    positions = []
    for k, sensor in enumerate(SENSORS):
        pose = Pose(sensor[0], sensor[1], sensor[2], yaw=0.3 * k)
        rows = slice(k * 1500, (k + 1) * 1500)
        local = (ends[rows] - pose.translation) @ pose.rotation  # world to the robot frame
        positions.append(Position(k, Features(local, np.where(hits[rows], 0.9, 0.0)), pose))
    world = map_log_3d(RangeLog(positions), resolution=0.2)
    direct = build_world_map_3d(origins, ends, hits, resolution=0.2)
    probe = np.array([[2.0, 2.0, 0.8], [2.0, 2.0, 1.3], [-0.5, 2.0, 1.0]])
    np.testing.assert_allclose(world.predict(probe), direct.predict(probe), atol=0.02)
    assert world.predict(probe)[0] > 0.8 and world.predict(probe)[2] == 0.5


def test_scans_merged_into_one_position_keep_their_own_sensors() -> None:
    # Four scans 0.07-0.2 m apart (within the position tolerance): one position, whose rays
    # still start at each scan's sensor, and whose scans are held out one by one.
    from occtool.fuse._log3d import rays_of_log
    from occtool.io.positions import Scan, build_log

    origins, ends, hits = _rays(1500)
    scans = []
    for k in range(4):
        sensor = np.array([2.0 + 0.06 * k, 2.0 - 0.03 * k, 1.2 + 0.02 * k])
        pose = Pose(*sensor, yaw=0.05 * k)
        rows = slice(k * 1500, (k + 1) * 1500)
        direction = ends[rows] - origins[rows]
        local = (sensor + direction - pose.translation) @ pose.rotation
        scans.append(Scan(local, np.where(hits[rows], 0.9, 0.0), pose))
    merged = build_log(scans, source="scans")
    apart = build_log(scans, source="scans", group_by="message")
    assert len(merged.positions) == 1 and len(apart.positions) == 4
    got, want = rays_of_log(merged), rays_of_log(apart)
    for a, b in zip(got[:2], want[:2]):
        np.testing.assert_allclose(a, b, atol=1e-9)
    np.testing.assert_array_equal(got[3], want[3])
    sensors = np.unique(np.round(got[0], 9), axis=0)
    assert len(sensors) == 4


def test_a_stored_frame_transform_is_applied_to_queries(room: WorldMap3D, tmp_path) -> None:
    """A map built in a levelled frame answers in the poses' frame through ``to_map``."""
    angle = np.radians(4.0)
    to_map = np.eye(4)
    to_map[1:3, 1:3] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    to_map[:3, 3] = [0.1, -0.2, -1.3]
    moved = build_world_map_3d(*_rays(), resolution=0.2)
    moved.to_map = to_map
    in_map = np.array([[2.0, 2.0, 0.8], [0.0, 2.1, 1.0], [2.0, 2.0, 1.3], [-0.6, 2.0, 1.0]])
    in_poses = (in_map - to_map[:3, 3]) @ to_map[:3, :3]  # the inverse transform
    np.testing.assert_allclose(moved.predict(in_poses), room.predict(in_map), atol=1e-9)
    moved.save(tmp_path / "moved.occmap")
    back = load_map_3d(tmp_path / "moved.occmap")
    np.testing.assert_array_equal(back.predict(in_poses), moved.predict(in_poses))
    with pytest.raises(InputError, match="rotation"):
        bad = WorldMap3D(room.resolution, room.lo, room.shape, room.free_keys, room.patches, room.falloff,
                         room.edge_falloff, to_map=np.diag([2.0, 1.0, 1.0, 1.0]))
        occmap3d.decode(occmap3d.encode(bad))


def _with_header(data: bytes, change: dict) -> bytes:
    """``data`` with its JSON header changed and the checksum made right again (so the
    checks behind the checksum are what a damaged file meets)."""
    import json
    import struct
    import zlib

    start = len(occmap3d.MAGIC) + 4
    (length,) = struct.unpack("<I", data[len(occmap3d.MAGIC):start])
    header = json.loads(data[start:start + length])
    header.update(change)
    text = json.dumps(header).encode()
    body = occmap3d.MAGIC + struct.pack("<I", len(text)) + text + data[start + length:-4]
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


@pytest.mark.parametrize("change", [
    {"shape": [100000, 100000, 100000]}, {"shape": [0, 1, 1]}, {"lo": [1, 2]}, {"levels": [1, 2, 3]},
    {"levels": []}, {"levels": [-1, 0, 0]}, {"resolution": -0.2}, {"resolution": "x"}, {"falloff": 0},
    {"free_level": 2.0}, {"version": 4}, {"format": "other"}, {"kind": "world2d"}, {"packed": 7}, {"to_map": [1, 0, 0]},
    {"to_map": [2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0]}, {"levels": None},
])
def test_a_damaged_header_behind_a_good_checksum_is_one_line(room: WorldMap3D, change: dict) -> None:
    with pytest.raises(InputError) as caught:
        occmap3d.decode(_with_header(occmap3d.encode(room), change), "bad.occmap")
    assert "\n" not in str(caught.value) and str(caught.value).startswith("bad.occmap: ")


def test_a_version_5_file_still_loads_and_answers_as_it_was_written() -> None:
    """fixtures/maps/room-v5.occmap: a room written by the version-5 writer (commit 9155404);
    its answers at these points were printed by that commit's map before saving."""
    from occtool.fuse import load_map

    old = load_map(Path(__file__).resolve().parents[1] / "fixtures" / "maps" / "room-v5.occmap")
    assert isinstance(old, WorldMap3D) and old.patch_count == 191 and old.free_cells == 9738
    points = np.array([[0.5, 0.5, 0.5], [2.0, 1.0, 0.2], [2.9, 2.0, 1.0], [1.0, 1.0, 0.02], [9.0, 9.0, 9.0],
                       [2.0, 2.0, 1.0]])
    np.testing.assert_allclose(old.predict(points), [0.1, 0.1, 0.201875, 0.998125, 0.5, 0.1], atol=1e-9)
    # Saved again, it keeps its version-5 coding.
    assert occmap3d.decode(old.to_bytes()).patches[0].__class__ is occmap3d.PatchCodesV5


def test_free_space_is_lower_where_more_rays_crossed(room: WorldMap3D) -> None:
    """The free space is graded: a cell next to the four sensors (crossed by thousands of rays)
    is freer than one near the room's top corner, which few rays reach."""
    assert (np.diff(room.free_table) <= 0).all() and room.free_table[0] < 0.5
    near, corner = room.predict([[2.0, 2.0, 1.3], [0.2, 0.2, 3.0]])
    assert room.free_level <= near < corner < 0.5


def test_a_flat_wall_is_a_few_planes_shared_by_its_cells(room: WorldMap3D) -> None:
    """Coplanar neighbouring cells refer to one plane: the floor's patches of 0.2 m cells name
    far fewer planes than cells, and every patch centre on it lies on the floor's plane."""
    refs = np.concatenate([codes.refs for codes in room.patches])
    assert (refs > 0).mean() > 0.3
    g = room.geometry
    on_floor = (np.abs(g.centres[:, 2]) < 0.05) & (g.normals[:, 2] > 0.99)
    assert on_floor.sum() > 20 and np.abs(g.centres[on_floor, 2]).max() < 0.01


@pytest.mark.parametrize("keys", [[], [0], [5, 6, 7, 300, 20_000, 20_001, 3_000_000]])
def test_surface_keys_round_trip_as_varint_gaps(keys: list[int]) -> None:
    coded = occmap3d.varint_gaps(np.array(keys, dtype=np.int64))
    back = occmap3d.keys_of_varints(coded, len(keys), 4_000_000)
    assert back is not None and back.tolist() == keys
    assert occmap3d.keys_of_varints(coded, len(keys) + 1, 4_000_000) is None
    if keys:
        assert occmap3d.keys_of_varints(coded, len(keys), keys[-1]) is None  # beyond the box


def test_a_large_box_walks_to_the_same_map_as_a_small_one(room: WorldMap3D, monkeypatch) -> None:
    """Boxes over ``DENSE_CELLS`` count the walk by sorting and find patch cells by search
    rather than by dense tables; the map is the same, byte for byte."""
    from occtool.fuse import _patches

    monkeypatch.setattr(_patches, "DENSE_CELLS", 0)
    sparse = build_world_map_3d(*_rays(), resolution=0.2)
    assert sparse.to_bytes() == room.to_bytes()
    assert np.array_equal(sparse.fine_free_keys, room.fine_free_keys)
    monkeypatch.setattr(_patches, "CHUNK_SAMPLES", 5_000)  # many walk chunks: the same sums
    assert build_world_map_3d(*_rays(), resolution=0.2).to_bytes() == room.to_bytes()
    monkeypatch.setattr(_patches, "MERGE_COUNTS", 64)  # the chunks' counts merged as they come, many times
    merged = build_world_map_3d(*_rays(), resolution=0.2)
    assert merged.to_bytes() == room.to_bytes() and np.array_equal(merged.fine_free_keys, room.fine_free_keys)
    monkeypatch.setattr(_patches, "DENSE_CELLS", 1 << 22)  # dense tables, counts by a sort or a bincount
    for chunks in (1, 1 << 10):
        monkeypatch.setattr(_patches, "DENSE_COUNTS", chunks)
        assert build_world_map_3d(*_rays(), resolution=0.2).to_bytes() == room.to_bytes()


def test_one_sensors_origin_is_every_rays_and_rays_that_disagree_are_refused() -> None:
    """``origins`` ``(3,)`` is every ray's (the rays are not copied for it: the same map as
    the origins written out); origins, ends or hits of other counts are an InputError."""
    sensor = np.array(SENSORS[0], dtype=np.float64)
    d = np.random.default_rng(3).normal(size=(3000, 3))
    ends, hits = _cast(sensor, d / np.linalg.norm(d, axis=1, keepdims=True))
    one = build_world_map_3d(sensor, ends, hits, resolution=0.2)
    assert one.to_bytes() == build_world_map_3d(np.tile(sensor, (len(ends), 1)), ends, hits, resolution=0.2).to_bytes()
    for origins, rays_hits in ((np.zeros((5, 3)), hits), (sensor, hits[:-1]), (np.zeros(2), hits)):
        with pytest.raises(InputError, match="same rays"):
            build_world_map_3d(origins, ends, rays_hits, resolution=0.2)
