"""``occtool info`` on every file occtool writes: world maps, map folders, Nav2 maps, model sets, models."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from occtool.cli.main import cli

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"


def info(*args: object) -> str:
    result = CliRunner().invoke(cli, ["info", *map(str, args)], terminal_width=200)
    assert result.exit_code == 0, result.output
    return result.output


def test_a_world_map_is_described_by_its_file():
    text = info(FIXTURES / "maps" / "intel.occmap")
    assert "occmap version 4" in text and "44,328 bytes" in text
    assert "5,202 segments" in text and "3,565 trusted" in text
    assert "x -16.96 to 19.57 m, y -24.79 to 12.77 m" in text
    assert "435 kept" in text and "137,616 bytes" in text


def test_a_damaged_world_map_is_one_line(tmp_path):
    damaged = tmp_path / "world.occmap"
    data = bytearray((FIXTURES / "maps" / "intel.occmap").read_bytes())
    data[100] ^= 0xFF
    damaged.write_bytes(bytes(data))
    result = CliRunner().invoke(cli, ["info", str(damaged)])
    assert result.exit_code == 1
    assert len(result.output.strip().splitlines()) == 1 and "world.occmap" in result.output


def test_a_nav2_map_and_its_folder(tmp_path):
    from occtool.formats.nav2 import write_nav2

    pixels = np.full((4, 6), 205, dtype=np.uint8)
    pixels[0, :] = 0
    pixels[1:3, 1:5] = 254
    write_nav2(pixels, 0.05, (-1.0, 2.0), tmp_path / "map.yaml")
    text = info(tmp_path / "map.yaml")
    assert "6 x 4 cells at 0.05 m" in text and "x -1 m, y 2 m" in text
    assert "8 free, 6 occupied, 10 unknown" in text
    assert info(tmp_path) == text  # the folder: its map.yaml (no world.occmap here)


def test_a_model_set_and_a_model_short_by_default(tmp_path):
    result = CliRunner().invoke(cli, ["-q", "fit", str(FIXTURES / "logs" / "tiny.carmen.log"),
                                      "-o", str(tmp_path / "set") + "/"])
    assert result.exit_code == 0, result.output
    text = info(tmp_path / "set")
    assert "2 positions" in text and "2 of 2 in the world frame" in text
    assert info(tmp_path / "set" / "index.json") == text
    model = sorted((tmp_path / "set").glob("model_*.json"))[0]
    short, long = info(model), info(model, "--pieces")
    assert "RMSE" in short
    assert "pieces" in long and len(long.splitlines()) > len(short.splitlines()) + 60


@pytest.mark.parametrize("name", ["not-a-map.yaml"])
def test_a_yaml_that_is_no_nav2_map_is_one_line(tmp_path, name):
    path = tmp_path / name
    path.write_text("resolution: nan\n")
    result = CliRunner().invoke(cli, ["info", str(path)])
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1
