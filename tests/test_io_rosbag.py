"""ROS bags (rosbags): ROS 1 .bag and ROS 2 .db3 read like their MCAP twins."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.io import detect_format, read_log

pytest.importorskip("rosbags")


def same_features(first, second) -> None:
    assert len(first.positions) == len(second.positions)
    for a, b in zip(first.positions, second.positions):
        np.testing.assert_array_equal(a.features.points, b.features.points)
        np.testing.assert_array_equal(a.features.evidence, b.features.evidence)
        assert a.stamp == b.stamp


def test_the_ccny_ros1_bag_gives_the_features_of_its_mcap_twin(shared_data):
    folder = shared_data / "ccny_hokuyo_bag"
    bag = read_log(folder / "demo.bag", group_by="message")
    twin = read_log(folder / "demo_ros2_converted.mcap", group_by="message")
    assert detect_format(folder / "demo.bag") == "rosbag" and len(bag.positions) == 360
    same_features(bag, twin)
    assert read_log(folder / "demo.bag", topics=["/scan"]).single().features.points.shape[0] == 231_818
    with pytest.raises(InputError, match="no topic '/nope'"):
        read_log(folder / "demo.bag", topics=["/nope"])


def write_ros2_bag(folder: Path, storage: str, scans: int = 5) -> Path:
    """A ROS 2 bag of LaserScans (rosbags' writer), in SQLite or MCAP storage."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    LaserScan = store.types["sensor_msgs/msg/LaserScan"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    rng = np.random.default_rng(3)
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    with Writer(folder, version=8, storage_plugin=plugin) as writer:
        connection = writer.add_connection("/scan", LaserScan.__msgtype__, typestore=store)
        for i in range(scans):
            ranges = rng.uniform(0.5, 4.0, 181).astype(np.float32)
            ranges[::17] = np.inf
            message = LaserScan(Header(Time(100 + i, 0), "base_link"), -np.pi / 2, np.pi / 2, np.pi / 180,
                                0.0, 0.1, 0.05, 5.0, ranges, np.zeros(0, dtype=np.float32))
            writer.write(connection, (100 + i) * 10**9, store.serialize_cdr(message, LaserScan.__msgtype__))
    return folder


def test_a_ros2_db3_bag_reads_like_the_same_bag_in_mcap_storage(tmp_path):
    db3_folder = write_ros2_bag(tmp_path / "sqlite", "sqlite3")
    mcap_folder = write_ros2_bag(tmp_path / "mcap", "mcap")
    db3 = next(db3_folder.glob("*.db3"))
    mcap = next(mcap_folder.glob("*.mcap"))
    assert detect_format(db3) == "rosbag"
    from_db3 = read_log(db3, group_by="message", no_return_range=3.0)
    same_features(from_db3, read_log(mcap, group_by="message", no_return_range=3.0))
    assert len(from_db3.positions) == 5


def test_a_db3_without_its_metadata_is_a_one_line_error(tmp_path):
    folder = write_ros2_bag(tmp_path / "bag", "sqlite3", scans=1)
    lone = tmp_path / "lone.db3"
    lone.write_bytes(next(folder.glob("*.db3")).read_bytes())
    with pytest.raises(InputError, match="metadata.yaml"):
        read_log(lone)


@pytest.mark.slow
@settings(max_examples=25)
@given(st.data())
def test_a_damaged_ros1_bag_is_read_or_refused_with_an_input_error(shared_data_path, data):
    original = (shared_data_path / "ccny_hokuyo_bag" / "demo.bag").read_bytes()
    cut = data.draw(st.integers(20, len(original) - 1))
    flips = data.draw(st.lists(st.integers(0, len(original) - 1), max_size=3))
    damaged = bytearray(original[:cut] if data.draw(st.booleans()) else original)
    for offset in flips:
        if offset < len(damaged):
            damaged[offset] ^= 0x10
    target = shared_data_path.parent / "damaged.bag"
    target.write_bytes(bytes(damaged))
    try:
        log = read_log(target, group_by="message")
    except InputError as exc:
        assert "damaged.bag" in str(exc), str(exc)  # one error class, naming the file
        return
    # What a damaged bag may give: no more scans than the bag holds, each no larger than the
    # largest scan, finite points and evidence in [0, 1]; the bag untouched gives its features.
    assert 1 <= len(log.positions) <= 360
    for position in log.positions:
        assert len(position.features) <= 681  # the Hokuyo's beams a scan (SOURCE.md)
        assert np.isfinite(position.features.points).all()
        assert ((position.features.evidence >= 0) & (position.features.evidence <= 1)).all()
    if bytes(damaged) == original:
        same_features(log, _original_bag(shared_data_path))


_ORIGINAL: dict[Path, object] = {}


def _original_bag(folder: Path):
    if folder not in _ORIGINAL:
        _ORIGINAL[folder] = read_log(folder / "ccny_hokuyo_bag" / "demo.bag", group_by="message")
    return _ORIGINAL[folder]


@pytest.fixture(scope="module")
def shared_data_path(tmp_path_factory):
    from tests.conftest import SHARED_DATA

    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not beside this checkout")
    folder = tmp_path_factory.mktemp("bags") / "data"
    (folder / "ccny_hokuyo_bag").mkdir(parents=True)
    (folder / "ccny_hokuyo_bag" / "demo.bag").symlink_to(SHARED_DATA / "ccny_hokuyo_bag" / "demo.bag")
    return folder
