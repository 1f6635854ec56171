"""Merging saved world maps: `occtool merge` and `occtool.fuse.merge_maps`."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.formats.occmap import encode
from occtool.fuse import WorldMap, build_world_map_3d, decode_map, load_map, merge_maps

INTEL = Path(__file__).resolve().parents[1] / "fixtures" / "maps" / "intel.occmap"


def crop(world: WorldMap, x0: float, x1: float, y0: float, y1: float) -> WorldMap:
    """The part of ``world`` in a box: what a robot that drove only there would have saved."""
    middle = 0.5 * (world.start + world.end)
    keep = (middle[:, 0] >= x0) & (middle[:, 0] < x1) & (middle[:, 1] >= y0) & (middle[:, 1] < y1)
    inside = ((world.positions[:, 0] >= x0) & (world.positions[:, 0] < x1) & (world.positions[:, 1] >= y0)
              & (world.positions[:, 1] < y1))
    params = world.params()
    band = params.pop("band")
    return WorldMap(world.start[keep], world.end[keep], world.thickness[keep], world.trust[keep],
                    shapely.intersection(world.region, shapely.box(x0, y0, x1, y1)), band=tuple(band),
                    positions=world.positions[inside], facing=world.facing[keep], **params).quantised()


@pytest.fixture(scope="module")
def intel() -> WorldMap:
    return load_map(INTEL)


@pytest.fixture(scope="module")
def robots(intel: WorldMap) -> list[WorldMap]:
    """Four overlapping parts of the Intel lab's middle; the fourth as another robot saw it,
    its walls 2 cm off the others' (so that walls are covered, not only repeated)."""
    parts = [crop(intel, -6, 1, -6, 1), crop(intel, -1, 6, -6, 1), crop(intel, -6, 6, -1, 6),
             crop(intel, -3, 3, -3, 3)]
    parts[3] = merge_maps([parts[3]], [(0.02, -0.015, 0.0)])
    return parts


def points_in(world: WorldMap, n: int = 20_000) -> np.ndarray:
    lower, upper = world.bounds
    rng = np.random.default_rng(1)
    return np.column_stack([rng.uniform(lower, upper, (n, 2)), np.zeros(n)])


def test_every_order_of_the_inputs_gives_the_same_bytes(robots: list[WorldMap]) -> None:
    reference = encode(merge_maps(robots))
    for order in itertools.permutations(range(4)):
        assert encode(merge_maps([robots[k] for k in order])) == reference, order
    # With a transform each, the transforms travel with their maps.
    moves = [None, (0.5, -0.25, 0.1), None, (-1.0, 2.0, -0.3)]
    reference = encode(merge_maps(robots, moves))
    for order in itertools.permutations(range(4)):
        assert encode(merge_maps([robots[k] for k in order], [moves[k] for k in order])) == reference, order


def test_walls_two_robots_saw_are_kept_once(intel: WorldMap, robots: list[WorldMap]) -> None:
    middle = crop(intel, -6, 6, -6, 6)
    # The three cut parts tile the middle: merged, they are the middle merged alone (a
    # map's own covered segments go too: on this fixture 1063 -> 727).
    three = merge_maps(robots[:3])
    alone = merge_maps([middle])
    assert len(three) == len(alone) < 0.8 * len(middle)
    xy = points_in(middle)
    xy = xy[middle.observed(xy[:, :2]) | np.isfinite(middle.wall_value(xy[:, :2]))]
    assert np.mean(np.abs(three.predict(xy) - alone.predict(xy)) > 1e-9) < 0.002
    # The fourth robot's walls, 2 cm off, are covered by theirs or cover them: it adds
    # almost no segments, and moves the answers by what 2 cm moves near a wall.
    merged = merge_maps(robots)
    assert len(merged) <= len(three) + 0.05 * len(robots[3])
    difference = np.abs(merged.predict(xy) - three.predict(xy))
    assert np.quantile(difference, 0.99) < 0.2 and difference.mean() < 0.02
    # The region is the union of the parts', the positions every part's.
    union = shapely.union_all([r.region for r in robots])
    assert shapely.symmetric_difference(merged.region, union).area < 5e-4 * union.area
    every = np.unique(np.round(np.concatenate([r.positions for r in robots]) / 0.005), axis=0)
    assert np.array_equal(np.round(merged.positions / 0.005), every)


def test_merging_is_associative_in_positions_and_nearly_in_walls_and_region(robots: list[WorldMap]) -> None:
    a, b, c, d = robots
    flat = merge_maps(robots)
    points = points_in(flat)
    for nested in (merge_maps([merge_maps([a, b]), c, d]), merge_maps([merge_maps([a, b]), merge_maps([c, d])]),
                   merge_maps([a, merge_maps([merge_maps([b, d]), c])])):
        nested = decode_map(encode(nested))
        assert np.array_equal(nested.positions, flat.positions)
        # A segment covered only by one that is itself covered may survive a nested merge
        # (docs/map.md): a few of them, and the region's snap rounding, move few answers.
        ours = {tuple(row) for row in np.round(np.column_stack([flat.start, flat.end]), 6)}
        theirs = {tuple(row) for row in np.round(np.column_stack([nested.start, nested.end]), 6)}
        assert len(ours ^ theirs) <= 0.01 * len(ours)
        assert shapely.symmetric_difference(nested.region, flat.region).area < 1e-3 * flat.region.area
        assert np.mean(np.abs(nested.predict(points) - flat.predict(points)) > 0.01) < 0.002


def test_a_merged_map_merged_again_or_with_itself_is_unchanged(robots: list[WorldMap]) -> None:
    merged = merge_maps(robots[:2])
    data = encode(merged)
    assert encode(merge_maps([decode_map(data)])) == data
    assert encode(merge_maps([merged, merged, decode_map(data)])) == data
    assert encode(decode_map(data)) == data


def test_a_transform_places_a_map(robots: list[WorldMap]) -> None:
    a, b = robots[0], robots[1]
    # b as a robot saw it in its own frame: turned a quarter and moved (both exact on the 5 mm grid).
    seen = merge_maps([b], [(1.0, -2.0, math.pi / 2)])
    assert not np.allclose(seen.bounds[0], b.bounds[0])
    placed = merge_maps([a, seen], [None, (2.0, 1.0, -math.pi / 2)])
    assert encode(placed) == encode(merge_maps([a, b]))


def test_maps_of_different_robots_or_bad_transforms_are_refused(robots: list[WorldMap]) -> None:
    params = robots[0].params()
    band = params.pop("band")
    taller = WorldMap(robots[0].start, robots[0].end, robots[0].thickness, robots[0].trust, robots[0].region,
                      band=(band[0], band[1] + 1.0), positions=robots[0].positions, **params)
    with pytest.raises(InputError, match="band"):
        merge_maps([robots[1], taller])
    with pytest.raises(InputError, match="2 transforms for 1 maps"):
        merge_maps([robots[1]], [None, None])
    with pytest.raises(InputError, match="three numbers"):
        merge_maps([robots[1]], [(1.0, 2.0)])  # type: ignore[list-item]
    with pytest.raises(InputError, match="three numbers"):
        merge_maps([robots[1]], ["123"])  # type: ignore[list-item]
    with pytest.raises(InputError, match="finite"):
        merge_maps([robots[1]], [(1.0, 2.0, math.inf)])
    with pytest.raises(InputError, match="no maps"):
        merge_maps([])
    with pytest.raises(InputError, match="not a WorldMap"):
        merge_maps([robots[1], "robot2/world.occmap"])  # type: ignore[list-item]


def test_the_command_writes_the_librarys_map(robots: list[WorldMap], tmp_path: Path) -> None:
    paths = []
    for k, world in enumerate(robots[:3]):
        paths.append(tmp_path / f"robot{k}.occmap")
        world.save(paths[-1])
    out = tmp_path / "merged.occmap"
    result = CliRunner().invoke(cli, ["merge", str(paths[2]), str(paths[0]), str(paths[1]), "-o", str(out),
                                      "--transform", str(paths[1]), "0.5,-0.25,10deg"])
    assert result.exit_code == 0, result.output
    expected = merge_maps([load_map(p) for p in paths], [None, (0.5, -0.25, math.radians(10)), None])
    assert out.read_bytes() == encode(expected)
    # A folder `occtool map` wrote stands for its world.occmap.
    (tmp_path / "run").mkdir()
    robots[0].save(tmp_path / "run" / "world.occmap")
    result = CliRunner().invoke(cli, ["merge", str(tmp_path / "run"), str(paths[1]), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_bytes() == encode(merge_maps(robots[:2]))


@pytest.mark.parametrize("case", ["not a map", "3d map", "bad transform", "unknown transform", "twice moved"])
def test_bad_input_is_one_line_and_writes_nothing(robots: list[WorldMap], tmp_path: Path, case: str) -> None:
    good = tmp_path / "good.occmap"
    robots[0].save(good)
    other = tmp_path / "other.occmap"
    args = ["merge", str(good), str(other), "-o", str(tmp_path / "out.occmap")]
    if case == "not a map":
        other.write_text("x,y,z\n0,0,0\n")
        wanted = "not a readable occtool map"
    elif case == "3d map":
        # A small real one: rays from a point to a sphere of 2 m.
        directions = np.random.default_rng(0).normal(size=(800, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        build_world_map_3d(np.zeros((800, 3)), 2.0 * directions, resolution=0.25).save(other)
        wanted = "a 3D world map (occmap version 5 or 6); occtool merges 2D world maps"
    else:
        robots[1].save(other)
        args += {"bad transform": ["--transform", str(other), "1,2,east"],
                 "unknown transform": ["--transform", str(tmp_path / "good.occmap.bak"), "1,2,0"],
                 "twice moved": ["--transform", str(other), "1,2,0", "--transform", str(other), "0,0,1"]}[case]
        wanted = {"bad transform": "X,Y,YAW", "unknown transform": "not one of the maps",
                  "twice moved": "two transforms"}[case]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code != 0
    assert wanted in result.output
    # One error line (a usage error adds click's usage lines before it), no traceback.
    assert "Traceback" not in result.output
    assert len([line for line in result.output.splitlines() if "Error" in line]) == 1
    assert not (tmp_path / "out.occmap").exists()
