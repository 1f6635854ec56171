"""CARMEN laser logs: beams, poses, no-return readings, positions and errors."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from occtool.errors import InputError
from occtool.features import Pose
from occtool.io import detect_format, read_log


def test_tiny_log_beams_poses_and_no_return(fixtures_dir):
    path = fixtures_dir / "logs" / "tiny.carmen.log"
    assert detect_format(path) == "carmen"
    log = read_log(path)
    assert len(log.positions) == 2
    first, second = log.positions
    assert first.pose == Pose(0.0, 0.0, 0.0, 0.0)
    s = np.sqrt(0.5)
    # 4 beams at -90, -45, 0, 45 degrees; 50.0 is the file's repeated maximum: no return.
    # The second scan, 0.1 m further ahead, is moved into the first scan's frame.
    np.testing.assert_allclose(
        first.features.points, [[0, -1, 0], [2 * s, -2 * s, 0], [0.5 * s, 0.5 * s, 0], [0.1, -1, 0]], atol=1e-12
    )
    np.testing.assert_array_equal(first.features.evidence, 0.9)
    assert second.pose == Pose(3.0, 0.0, 0.0, np.pi / 2)
    assert len(second.features) == 4
    assert first.stamp == pytest.approx(1.5)
    assert any("dropped 4 of 12 readings as no return" in note for note in log.notes)
    assert len(read_log(path, group_by="message").positions) == 3
    np.testing.assert_array_equal(read_log(path, evidence=0.3).positions[0].features.evidence, 0.3)


def test_a_laser_line_that_does_not_parse_names_its_line(tmp_path, fixtures_dir):
    text = (fixtures_dir / "logs" / "tiny.carmen.log").read_text().splitlines()
    text.insert(4, "FLASER 4 1.0 2.0 oops 0.5 0.0 0.0 0.0 0.0 0.0 0.0 1.5 nohost 1.5")
    text.insert(5, "FLASER 180 1.0 2.0")
    path = tmp_path / "bad.log"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(InputError, match="bad.log, line 5: FLASER record has a field that is not a number"):
        read_log(path)
    log = read_log(path, skip_invalid=True)
    assert len(log.positions) == 2
    assert any("skipped 2 laser line(s)" in note for note in log.notes)


def test_a_log_without_scans_is_an_error(tmp_path):
    path = tmp_path / "odom.log"
    path.write_text("PARAM a 1 nohost 0\nODOM 0 0 0 0 0 0 1 nohost 1\n")
    with pytest.raises(InputError, match="no laser scans"):
        read_log(path)


def test_robotlaser1_records(tmp_path):
    # 3 beams from -0.5 rad in 0.5 rad steps, 2 remissions, laser pose (1, 2, 0).
    line = "ROBOTLASER1 0 -0.5 1.0 0.5 80.0 0.01 0 3 1.0 2.0 3.0 2 0 0 1.0 2.0 0.0 1.0 2.0 0.0 0 0 0 0 0 7.0 host 7.0"
    path = tmp_path / "robot.log.gz"
    with gzip.open(path, "wt") as handle:
        handle.write(line + "\n")
    position = read_log(path).single()
    angles = np.array([-0.5, 0.0, 0.5])
    r = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(position.features.points, np.column_stack([r * np.cos(angles), r * np.sin(angles), 0 * r]))
    assert position.pose == Pose(1.0, 2.0, 0.0, 0.0)
    assert position.stamp == 7.0


def test_real_intel_lab_log(shared_data):
    path = shared_data / "intel_lab" / "intel-corrected.log.gz"
    log = read_log(path, group_by="message")
    # 910 scans of 180 beams; the 81.83 m readings (2.5%) are no return.
    assert len(log.positions) == 910
    assert any("readings >= 81.83 m" in note for note in log.notes)
    total = sum(len(p.features) for p in log.positions)
    assert 0.97 * 910 * 180 < total < 0.98 * 910 * 180
    ranges = np.concatenate([p.features.range for p in log.positions])
    assert ranges.max() < 81.83 and ranges.min() > 0.2
    xs = [p.pose.x for p in log.positions]
    ys = [p.pose.y for p in log.positions]
    assert -9.3 < min(xs) and max(xs) < 16.6 and -22.2 < min(ys) and max(ys) < 4.0
    grouped = read_log(path)
    assert 1 < len(grouped.positions) <= 910
    assert sum(len(p.features) for p in grouped.positions) == total
