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
    np.testing.assert_allclose(
        position.features.points, np.column_stack([r * np.cos(angles), r * np.sin(angles), 0 * r])
    )
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


# --- no-return readings kept as free rays (--no-return-range) --------------------------------


def _beams(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.arctan2(points[:, 1], points[:, 0]), np.hypot(points[:, 0], points[:, 1])


@pytest.mark.parametrize("reach, expected", [(5.0, 5.0), (100.0, 50.0)])
def test_no_return_readings_become_free_rays_at_the_range_or_the_max_range(fixtures_dir, reach, expected):
    path = fixtures_dir / "logs" / "tiny.carmen.log"
    plain = read_log(path, group_by="message")
    log = read_log(path, group_by="message", no_return_range=reach)
    assert [len(p.features) for p in plain.positions] == [3, 1, 4]
    assert [len(p.features) for p in log.positions] == [4, 4, 4]
    # The 50.0 readings (the file's no-return sentinel) of each scan, by beam: -90, -45, 0, 45 degrees.
    beam_angles = np.radians([-90.0, -45.0, 0.0, 45.0])
    no_return = [np.array([2]), np.array([1, 2, 3]), np.array([], dtype=int)]
    for before, after, missing in zip(plain.positions, log.positions, no_return):
        free = after.features.evidence == 0.0
        assert free.sum() == missing.size
        # The returns are unchanged, evidence and all.
        np.testing.assert_array_equal(after.features.points[~free], before.features.points)
        np.testing.assert_array_equal(after.features.evidence[~free], before.features.evidence)
        # Free rays lie on the no-return beams (one position per scan: each in its own frame).
        alpha, r = _beams(after.features.points[free])
        np.testing.assert_allclose(alpha, beam_angles[missing], atol=1e-12)
        np.testing.assert_allclose(r, expected, rtol=1e-12)
        assert (after.features.points[free, 2] == 0.0).all()
    assert any(f"kept 4 of 12 readings with no return (readings >= 50 m) as free rays at {expected:g} m "
               "with evidence 0" in note for note in log.notes)
    assert not any("dropped" in note for note in log.notes)


def test_without_the_option_no_return_readings_are_dropped_as_before(fixtures_dir):
    path = fixtures_dir / "logs" / "tiny.carmen.log"
    default, explicit = read_log(path), read_log(path, no_return_range=None)
    assert default.notes == explicit.notes
    assert any("dropped 4 of 12 readings as no return" in note for note in default.notes)
    for a, b in zip(default.positions, explicit.positions):
        np.testing.assert_array_equal(a.features.points, b.features.points)
        assert (a.features.evidence == 0.9).all()


def test_robotlaser1_free_rays_stop_at_the_lines_max_range(tmp_path):
    # 7 beams from -0.75 rad in 0.25 rad steps; the line's max range is 8 m, the file's
    # no-return sentinel 80 m (repeated); +inf is no return too; 0, -1 and NaN are no readings.
    readings = "1.0 80.0 inf 0.0 -1.0 nan 80.0"
    line = (f"ROBOTLASER1 0 -0.75 1.5 0.25 8.0 0.01 0 7 {readings} 0 0.0 0.0 0.0 0.0 0.0 0.0 "
            "0 0 0 0 0 7.0 host 7.0")
    path = tmp_path / "robot.log"
    path.write_text(line + "\n")
    angles = -0.75 + 0.25 * np.arange(7)
    plain = read_log(path)
    np.testing.assert_allclose(plain.single().features.points, [[np.cos(angles[0]), np.sin(angles[0]), 0.0]])
    assert any("dropped 6 of 7 readings as no return (readings >= 80 m)" in note for note in plain.notes)
    for reach, expected in ((20.0, 8.0), (3.0, 3.0)):
        log = read_log(path, no_return_range=reach)
        features = log.single().features
        np.testing.assert_array_equal(features.evidence, [0.9, 0.0, 0.0, 0.0])
        alpha, r = _beams(features.points)
        np.testing.assert_allclose(alpha, angles[[0, 1, 2, 6]], atol=1e-12)
        np.testing.assert_allclose(r, [1.0, expected, expected, expected], rtol=1e-12)
        assert any(f"kept 3 of 7 readings with no return (readings >= 80 m) as free rays at {expected:g} m" in note
                   for note in log.notes)
        assert any("dropped 3 of 7 readings <= 0 or NaN" in note for note in log.notes)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf"), "far"])
def test_a_bad_no_return_range_is_an_error(fixtures_dir, bad):
    with pytest.raises(InputError, match="no-return range must be a finite number of metres > 0"):
        read_log(fixtures_dir / "logs" / "tiny.carmen.log", no_return_range=bad)


def test_point_formats_ignore_the_no_return_range(fixtures_dir):
    path = fixtures_dir / "office" / "features.csv"
    plain, with_option = read_log(path).single(), read_log(path, no_return_range=5.0).single()
    np.testing.assert_array_equal(plain.features.points, with_option.features.points)
    np.testing.assert_array_equal(plain.features.evidence, with_option.features.evidence)


def test_real_intel_first_scan_gains_its_no_return_beams(shared_data):
    path = shared_data / "intel_lab" / "intel-corrected.log.gz"
    with gzip.open(path, "rt") as handle:
        first = next(line for line in handle if line.startswith("FLASER")).split()
    ranges = np.array(first[2:182], dtype=float)
    sentinel = ranges == 81.83
    assert sentinel.sum() == 15  # the first scan has 15 no-return beams
    plain = read_log(path, group_by="message").positions[0].features
    log = read_log(path, group_by="message", no_return_range=4.0)
    features = log.positions[0].features
    free = features.evidence == 0.0
    assert len(plain) == 165 and len(features) == 180 and free.sum() == 15
    np.testing.assert_array_equal(features.points[~free], plain.points)
    alpha, r = _beams(features.points[free])
    np.testing.assert_allclose(alpha, (-np.pi / 2 + np.pi / 180 * np.arange(180))[sentinel], atol=1e-9)
    np.testing.assert_allclose(r, 4.0)
    assert any("kept 4172 of 163800 readings with no return (readings >= 81.83 m) as free rays at 4 m" in note
               for note in log.notes)


def test_info_counts_no_return_beams_as_free_rays(fixtures_dir) -> None:
    from click.testing import CliRunner

    from occtool.cli.main import cli

    path = str(fixtures_dir / "logs" / "tiny.carmen.log")
    runner = CliRunner()
    plain = runner.invoke(cli, ["info", path])
    kept = runner.invoke(cli, ["info", path, "--no-return-range", "5"])
    assert plain.exit_code == 0 and kept.exit_code == 0, kept.output
    words = " ".join(kept.output.split())  # rich wraps the notes at the terminal width
    assert "free rays at 5 m" in words and "free rays" not in plain.output
    bad = runner.invoke(cli, ["info", path, "--no-return-range", "-1"])
    assert bad.exit_code == 2 and "must be a finite number of metres > 0" in bad.output


def _flaser(ranges, x=0.0):
    return f"FLASER {len(ranges)} {' '.join(f'{r:.2f}' for r in ranges)} {x} 0 0 {x} 0 0 1.0 host 1.0\n"


def test_a_cluster_of_no_return_codes_is_told_with_its_stray_readings(tmp_path):
    """A laser that logs no return as codes a few centimetres apart (the MIT infinite corridor's
    51.05-51.12 m): every reading from the lowest code less the codes' spread is no return, a
    real return just below is kept, and the note names the codes."""
    rng = np.random.default_rng(0)
    lines = []
    for scan in range(40):
        ranges = rng.uniform(1.0, 50.8, 180)
        ranges[:12] = rng.choice([51.05, 51.06, 51.11], 12)  # the codes
        lines.append(_flaser(ranges, x=0.01 * scan))
    strays = np.full(180, 3.0)
    strays[:3] = [51.01, 51.16, 50.9]  # two strays of the cluster and a real far return
    lines.append(_flaser(strays))
    path = tmp_path / "codes.log"
    path.write_text("".join(lines))
    log = read_log(path, group_by="message")
    assert "dropped 482 of 7380 readings as no return (readings >= 50.99 m: the laser's codes 51.05 to 51.11 m)" \
        in log.notes
    far = np.concatenate([p.features.range for p in log.positions])
    assert far.max() == pytest.approx(50.9)
    # Told by the user instead: only readings at or above it.
    told = read_log(path, group_by="message", no_return_code=51.1)
    assert any("readings >= 51.1 m, no_return_code" in note for note in told.notes)


def test_each_laser_of_a_log_has_its_own_codes(tmp_path):
    front = [_flaser([2.0] * 170 + [81.91] * 10, x=0.01 * i) for i in range(3)]
    rear = [line.replace("FLASER", "RLASER") for line in
            (_flaser([3.0] * 175 + [50.0] * 5, x=0.01 * i) for i in range(3))]
    path = tmp_path / "two.log"
    path.write_text("".join(front + rear))
    from occtool.io.carmen import CarmenScans

    limits = CarmenScans(path).limits()
    assert limits["FLASER"] == (81.91, [81.91]) and limits["RLASER"] == (50.0, [50.0])
    assert limits["ROBOTLASER1"] == (None, [])
    log = read_log(path, group_by="message")
    assert "dropped 45 of 1080 readings as no return (FLASER readings >= 81.91 m; RLASER readings >= 50 m)" \
        in log.notes


@pytest.mark.parametrize("log, found, codes", [
    ("mit_infinite_corridor/infinite-corridor-corrected.log.gz", 4660,
     "readings >= 50.98 m: the laser's codes 51.05 to 51.12 m"),
    ("fr_campus/freiburg-campus-corrected.log.gz", 187049, "readings >= 81.75 m: the laser's codes 81.83 to 81.91 m"),
])
def test_the_corridors_and_the_campuss_no_return_codes_are_found_without_options(shared_data, log, found, codes):
    from occtool.io.carmen import CarmenScans

    scans = CarmenScans(shared_data / log)
    for _ in scans:
        pass
    readings = {"mit_infinite_corridor": 349380, "fr_campus": 722880}[log.split("/")[0]]
    assert f"dropped {found} of {readings} readings as no return ({codes})" in scans.notes


def test_a_bad_no_return_code_is_an_error(fixtures_dir):
    for bad in (0, -1, float("nan"), True, "far"):
        with pytest.raises(InputError, match="no-return code must be"):
            read_log(fixtures_dir / "logs" / "tiny.carmen.log", no_return_code=bad)


@pytest.mark.parametrize("kept", [1 << 22, 500])
def test_the_lines_kept_from_the_first_reading_give_the_scans_of_a_second(tmp_path, fixtures_dir, monkeypatch, kept):
    """read_carmen keeps the lines its no-return codes' reading parsed (up to KEPT_READINGS
    readings, else none) and makes its scans of them: the scans, notes and skipped lines
    of a reader that parses the file again."""
    import occtool.io.carmen as carmen

    monkeypatch.setattr(carmen, "KEPT_READINGS", kept)
    lines = (fixtures_dir / "logs" / "tiny.carmen.log").read_text().splitlines(keepends=True)
    path = tmp_path / "log.log"
    path.write_text("".join(lines + ["FLASER 2 oops\n", "WHATEVER 1 2\n"]
                            + [_flaser([2.0] * 170 + [81.91] * 10, x=0.01 * i) for i in range(3)]))
    keeping = carmen.CarmenScans(path, keep=True, skip_invalid=True, no_return_range=3.0)
    again = carmen.CarmenScans(path, skip_invalid=True, no_return_range=3.0)
    readings, parse = [], keeping._lines
    keeping._lines = lambda: (readings.append(1), parse())[1]  # type: ignore[method-assign]
    both = list(keeping), list(again)
    assert len(readings) == (1 if kept > 1000 else 2)  # the file read once when its lines were kept
    assert (keeping._kept is None) and len(both[0]) == len(both[1]) > 3
    for a, b in zip(*both, strict=True):
        assert a.points.tobytes() == b.points.tobytes() and a.evidence.tobytes() == b.evidence.tobytes()
        assert (a.pose, a.stamp, a.source) == (b.pose, b.stamp, b.source)
    assert keeping.notes == again.notes and keeping.skipped_lines == again.skipped_lines == 1
    assert keeping.unknown == again.unknown == {"WHATEVER"}
