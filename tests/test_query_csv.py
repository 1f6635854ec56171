"""`occtool.formats.query_csv`: x, y, z rows in, the same rows out with an occupancy column."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from occtool.errors import InputError
from occtool.formats import query_csv as module
from occtool.formats.query_csv import COLUMN, query_csv


class Ramp:
    """A map whose occupancy is a known function of the point, recording what it was asked."""

    def __init__(self):
        self.asked = []

    def predict(self, xyz):
        xyz = np.asarray(xyz, dtype=np.float64)
        assert xyz.ndim == 2 and xyz.shape[1] == 3
        self.asked.append(xyz.copy())
        return np.clip(0.1 * xyz[:, 0] + 0.01 * xyz[:, 1] + 0.001 * xyz[:, 2], 0.0, 1.0)


def write(tmp_path, text, name="points.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_every_row_comes_back_as_it_was_read_with_its_occupancy(tmp_path):
    source = write(tmp_path, "# a comment first\nX, Y ,z,label\n1,2,3,door\n\n  # and one inside\n"
                             "4.5,-1,0.25,\"a, b\"\n12,0,0,far\n")
    world = Ramp()
    rows = query_csv(world, source, tmp_path / "out.csv")
    assert rows == 3
    # The header and the other columns are written as they were; comments and blanks dropped;
    # 0.1 x + 0.01 y + 0.001 z, clipped to [0, 1], at four decimals.
    assert (tmp_path / "out.csv").read_text(encoding="utf-8") == (
        "X, Y ,z,label,occupancy\n"
        "1,2,3,door,0.1230\n"
        "4.5,-1,0.25,\"a, b\",0.4402\n"
        "12,0,0,far,1.0000\n"
    )
    np.testing.assert_array_equal(np.concatenate(world.asked), [[1, 2, 3], [4.5, -1, 0.25], [12, 0, 0]])


def test_the_columns_may_come_in_any_order(tmp_path):
    source = write(tmp_path, "id,z,y,x\na,3,2,1\n")
    query_csv(Ramp(), source, tmp_path / "out.csv", precision=3)
    assert (tmp_path / "out.csv").read_text(encoding="utf-8") == "id,z,y,x,occupancy\na,3,2,1,0.123\n"


@pytest.mark.parametrize(("precision", "value"), [(0, "0"), (2, "0.12"), (6, "0.123000")])
def test_precision_is_the_occupancys_decimals(tmp_path, precision, value):
    source = write(tmp_path, "x,y,z\n1,2,3\n")
    query_csv(Ramp(), source, tmp_path / "out.csv", precision=precision)
    assert (tmp_path / "out.csv").read_text(encoding="utf-8").splitlines() == ["x,y,z,occupancy", f"1,2,3,{value}"]


def test_a_long_file_is_asked_in_chunks_and_written_whole(tmp_path, monkeypatch):
    points = np.random.default_rng(3).uniform(-5, 5, size=(7, 3)).round(3)
    source = write(tmp_path, "x,y,z\n" + "".join(f"{x},{y},{z}\n" for x, y, z in points))
    whole = Ramp()
    assert query_csv(whole, source, tmp_path / "whole.csv") == 7
    monkeypatch.setattr(module, "CHUNK_ROWS", 3)
    chunked = Ramp()
    assert query_csv(chunked, source, tmp_path / "chunked.csv") == 7
    assert [len(a) for a in chunked.asked] == [3, 3, 1]
    assert (tmp_path / "chunked.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    with open(tmp_path / "chunked.csv", newline="", encoding="utf-8") as handle:
        back = list(csv.reader(handle))
    assert back[0] == ["x", "y", "z", COLUMN] and len(back) == 8
    np.testing.assert_array_equal(np.array([row[:3] for row in back[1:]], dtype=float), points)
    expected = np.clip(points @ [0.1, 0.01, 0.001], 0.0, 1.0)
    np.testing.assert_allclose([float(row[3]) for row in back[1:]], expected, atol=5e-5)


def test_a_header_without_rows_gives_the_header_back(tmp_path):
    source = write(tmp_path, "x,y,z\n")
    world = Ramp()
    assert query_csv(world, source, tmp_path / "out.csv") == 0
    assert (tmp_path / "out.csv").read_text(encoding="utf-8") == "x,y,z,occupancy\n" and world.asked == []


def test_standard_output(tmp_path, capsys):
    source = write(tmp_path, "x,y,z\n0,0,10\n")
    assert query_csv(Ramp(), source, "-") == 1
    assert capsys.readouterr().out == "x,y,z,occupancy\n0,0,10,0.0100\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty file (expected a header with x, y, z)"),
        ("# only a comment\n\n", "empty file (expected a header with x, y, z)"),
        ("x,y,height\n1,2,3\n", "the header needs columns x, y and z (missing z)"),
        ("a,b\n1,2\n", "the header needs columns x, y and z (missing x, y, z)"),
        ("x,y,z,Occupancy\n1,2,3,0\n", "already has an 'occupancy' column"),
        ("x,y,z\n1,2,3\n4,five,6\n", "row 3 has no number in x, y or z: '4,five,6'"),
        ("x,y,z\n1,2\n", "row 2 has no number in x, y or z: '1,2'"),
        ("x,y,z\n1,2,3\n1,nan,3\n", "row 3 has a coordinate that is not finite"),
        ("x,y,z\n-inf,2,3\n", "row 2 has a coordinate that is not finite"),
    ],
)
def test_bad_points_are_refused_in_one_line_and_nothing_is_written(tmp_path, text, message):
    source = write(tmp_path, text)
    output = tmp_path / "out.csv"
    with pytest.raises(InputError) as raised:
        query_csv(Ramp(), source, output)
    assert str(raised.value) == f"{source}: {message}"
    assert not output.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["points.csv"]


def test_text_that_is_not_utf8_is_refused_in_one_line(tmp_path):
    source = tmp_path / "points.csv"
    source.write_bytes(b"x,y,z\n1,2,3\n\xff\xfe,0,0\n")
    # (A small file is decoded in one read, before its first row: no row to name then.)
    with pytest.raises(InputError, match=r"points\.csv: not CSV text (near row \d+ )?\('utf-8' codec") as raised:
        query_csv(Ramp(), source, tmp_path / "out.csv")
    assert "\n" not in str(raised.value)
    assert not (tmp_path / "out.csv").exists()


def test_a_missing_file_is_refused_in_one_line(tmp_path):
    with pytest.raises(InputError, match=r"nowhere\.csv: cannot read the points: No such file or directory$"):
        query_csv(Ramp(), tmp_path / "nowhere.csv", tmp_path / "out.csv")


def test_an_existing_output_is_kept_without_overwrite(tmp_path):
    source = write(tmp_path, "x,y,z\n1,2,3\n")
    output = write(tmp_path, "keep me\n", name="out.csv")
    with pytest.raises(FileExistsError):
        query_csv(Ramp(), source, output, overwrite=False)
    assert output.read_text(encoding="utf-8") == "keep me\n"
    query_csv(Ramp(), source, output)
    assert output.read_text(encoding="utf-8") == "x,y,z,occupancy\n1,2,3,0.1230\n"
