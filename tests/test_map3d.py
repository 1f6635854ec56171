"""The 3D world map in ``occtool map`` (issue 35): its Nav2 projection over the ground per
tile, the choice of its cell size on an inner split, and the files, queries and ``info``
of a 3D log's map, in the frame of the user's poses."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.features import Features, Pose, Position, RangeLog
from occtool.fuse import (
    WorldMap,
    WorldMap3D,
    build_world_map_3d,
    choose_resolution,
    is_3d_log,
    load_map,
    map_log,
    project_band,
)
from occtool.fuse._inner_split import AUC_TOLERANCE, held_out_blocks
from occtool.raster import FREE, OCCUPIED

ROOT = Path(__file__).resolve().parents[1]
OFFICE = ROOT / "fixtures" / "depth-office" / "depth.txt"
ROOM = 6.0  # a 6 m square room with walls, no ceiling


def _cast(origin: np.ndarray, directions: np.ndarray, slope: float = 0.0,
          table: tuple[float, float, float] | None = None, reach: float = 8.0) -> tuple[np.ndarray, np.ndarray]:
    """End points and hits of rays from ``origin`` in a room whose floor is ``z = slope * x``
    (a ramp when ``slope`` > 0), with a table top ``(low, high, height)`` above the floor."""
    t = np.full(len(directions), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, value in ((0, 0.0), (0, ROOM), (1, 0.0), (1, ROOM)):
            s = (value - origin[axis]) / directions[:, axis]
            t = np.minimum(t, np.where(s > 0, s, np.inf))
        s = (slope * origin[0] - origin[2]) / (directions[:, 2] - slope * directions[:, 0])
        t = np.minimum(t, np.where(s > 0, s, np.inf))
        if table is not None:
            low, high, height = table
            s = (height - origin[2]) / directions[:, 2]
            top = origin + s[:, None] * directions
            on = (s > 0) & ((top[:, :2] > low) & (top[:, :2] < high)).all(axis=1)
            t = np.where(on & (s < t), s, t)
    hit = t < reach
    return origin + np.where(hit, t, reach)[:, None] * directions, hit


def _scene(slope: float = 0.0, table: tuple[float, float, float] | None = None, n: int = 4000,
           height: float = 1.0) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """Rays from eight sensors ``height`` above the floor, looking every way."""
    rng = np.random.default_rng(7)
    origins, ends, hits = [], [], []
    for x, y in ((1.0, 1.0), (3.0, 1.0), (5.0, 1.0), (5.0, 3.0), (5.0, 5.0), (3.0, 5.0), (1.0, 5.0), (1.0, 3.0)):
        sensor = np.array([x, y, slope * x + height])
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        end, hit = _cast(sensor, d, slope, table)
        origins.append(sensor)
        ends.append(end)
        hits.append(hit)
    return origins, ends, hits


def _world(origins, ends, hits, resolution: float = 0.2) -> WorldMap3D:
    return build_world_map_3d(np.concatenate([np.broadcast_to(o, e.shape) for o, e in zip(origins, ends)]),
                              np.concatenate(ends), np.concatenate(hits), resolution=resolution)


def _cell(raster, x: float, y: float) -> int:
    row, col, inside = raster.cell_of([[x, y]])
    assert inside[0]
    return int(raster.cells[row[0], col[0]])


def test_the_band_makes_a_table_top_an_obstacle_and_leaves_the_floor_free() -> None:
    origins, ends, hits = _scene(table=(2.5, 3.5, 0.75), n=12000)
    world = _world(origins, ends, hits)
    raster = project_band(world, np.array(origins), sensor_height=1.0, body_height=1.0, radius=0.25)
    under = np.array([_cell(raster, x, y) for x in np.arange(2.6, 3.41, 0.1) for y in np.arange(2.6, 3.41, 0.1)])
    # Under the table top, 0.75 m up: in the band. Its patches are bounded by their cells, so
    # the edge cells' are crossed by rays passing beside the table (trust under the occupied
    # level): unknown there, never free.
    assert (under == OCCUPIED).mean() > 0.6
    assert not (under == FREE).any()
    assert _cell(raster, 0.03, 3.0) == OCCUPIED  # a wall
    assert _cell(raster, 2.0, 3.0) == FREE  # the floor beside the table, seen free up to the body's top
    assert _cell(raster, 4.0, 2.0) == FREE
    # No free cell within FREE_RIM of an occupied one (a return scattered off it lands on unknown).
    from scipy import ndimage

    from occtool.fuse._projection import FREE_RIM

    span = int(round(FREE_RIM / raster.resolution))
    disk = np.hypot(*np.mgrid[-span:span + 1, -span:span + 1]) <= span
    assert not (ndimage.binary_dilation(raster.cells == OCCUPIED, structure=disk) & (raster.cells == FREE)).any()
    # A robot 0.5 m tall passes under the table: its band stops below the top.
    low = project_band(world, np.array(origins), sensor_height=1.0, body_height=0.5, radius=0.25)
    assert not any(_cell(low, x, y) == OCCUPIED for x in np.arange(2.6, 3.41, 0.1) for y in np.arange(2.6, 3.41, 0.1))
    assert _cell(low, 0.03, 3.0) == OCCUPIED


def test_a_ramp_is_ground_not_an_obstacle() -> None:
    # The floor rises 0.1 m a metre (5.7 degrees): 0.5 m across the room, far more than
    # the band's clearance, and the sensors ride 1 m above it.
    origins, ends, hits = _scene(slope=0.1)
    world = _world(origins, ends, hits)
    raster = project_band(world, np.array(origins), sensor_height=1.0, body_height=1.0, radius=0.25)
    inner = [(x, y) for x in np.arange(0.6, 5.5, 0.4) for y in np.arange(0.6, 5.5, 0.4)]
    cells = np.array([_cell(raster, x, y) for x, y in inner])
    assert not (cells == OCCUPIED).any()
    assert (cells == FREE).mean() > 0.8
    assert _cell(raster, 5.97, 3.0) == OCCUPIED  # the wall at the top of the ramp


def test_held_out_blocks_are_blocks_and_the_choice_is_deterministic() -> None:
    picked = held_out_blocks(48, seed=3)
    assert picked.sum() == 8  # 15 % of 48 in blocks of 4
    starts = np.flatnonzero(np.diff(np.r_[0, picked.astype(int)]) == 1)
    assert all(picked[s:s + 4].all() for s in starts)
    origins, ends, hits = _scene(n=800)
    groups = np.repeat(np.arange(len(ends)), [len(e) for e in ends])
    flat = (np.concatenate([np.broadcast_to(o, e.shape) for o, e in zip(origins, ends)]), np.concatenate(ends),
            np.concatenate(hits), groups)
    first = choose_resolution(*flat, seed=0)
    assert first == choose_resolution(*flat, seed=0)
    assert first[0] in (0.1, 0.2, 0.4) and set(first[1]["inner_auc"]) <= {"0.1", "0.2", "0.4"}
    scores = {float(size): auc for size, auc in first[1]["inner_auc"].items()}
    # Refined coarse to fine while a finer cell scores better by more than the tolerance.
    tried = sorted(scores, reverse=True)
    chosen = tried.index(first[0])
    assert all(scores[tried[k + 1]] >= scores[tried[k]] + AUC_TOLERANCE for k in range(chosen))
    assert chosen == len(tried) - 1 or scores[tried[chosen + 1]] < scores[first[0]] + AUC_TOLERANCE
    assert choose_resolution(*(a[groups < 2] for a in flat))[1]["why"].startswith("2 positions")


def _log(origins, ends, hits) -> RangeLog:
    positions = []
    for k, (origin, end, hit) in enumerate(zip(origins, ends, hits)):
        local = end - origin  # the pose's yaw is 0: world axes
        positions.append(Position(k, Features(local, np.where(hit, 0.9, 0.0)), Pose(*origin, 0.0)))
    return RangeLog(positions, source="room")


def test_a_3d_log_is_told_from_a_2d_laser() -> None:
    origins, ends, hits = _scene(n=500)
    assert is_3d_log(_log(origins, ends, hits))
    flat = [np.column_stack([e[:, :2], np.full(len(e), o[2])]) for o, e in zip(origins, ends)]
    assert not is_3d_log(_log(origins, flat, hits))


def test_map_log_of_a_3d_log_writes_a_3d_world_map(tmp_path: Path) -> None:
    origins, ends, hits = _scene(table=(2.5, 3.5, 0.75), n=1000)
    result = map_log(_log(origins, ends, hits), tmp_path / "map", world_resolution=0.2, mcap=False,
                     heights_from_data=True)
    world = load_map(tmp_path / "map" / "world.occmap")
    assert isinstance(world, WorldMap3D) and world.resolution == 0.2
    assert world.predict([[0.0, 3.0, 0.5]])[0] > 0.65  # a wall
    assert world.predict([[2.0, 2.0, 0.5]])[0] < 0.45  # crossed free (by a few hundred rays: not yet the free level)
    summary = json.loads((tmp_path / "map" / "summary.json").read_text())
    assert summary["world_map"]["kind"] == "3d" and summary["world_map"]["file_bytes"] == world.nbytes
    assert result.run.raster.cells.size > 0
    flat = map_log(_log(origins, ends, hits), tmp_path / "flat", world="2d", mcap=False, heights_from_data=True)
    assert isinstance(flat.run.world, WorldMap)
    # The memory estimate counts the 3D map's build, a few hundred bytes a ray.
    from occtool.fuse._memory import estimate_map_memory

    rays = sum(len(e) for e in ends)
    assert estimate_map_memory(_log(origins, ends, hits), world3d=True).parts["world3d"] >= 300 * rays
    with pytest.raises(InputError, match="the 3D map of 8,000 rays"):
        map_log(_log(origins, ends, hits), tmp_path / "refused", mcap=False, memory_limit="103M")


@pytest.mark.slow
def test_a_depth_folder_map_answers_in_the_frame_of_its_poses(tmp_path: Path) -> None:
    out = tmp_path / "office"
    result = CliRunner().invoke(cli, ["-q", "map", str(OFFICE), "-o", str(out), "--depth-features", "1500",
                                      "--world-resolution", "0.2", "--no-mcap"])
    assert result.exit_code == 0, result.output
    world = load_map(out / "world.occmap")
    assert isinstance(world, WorldMap3D) and world.to_map is not None
    # The reader levels the folder's world on its floor; the map takes the folder's own
    # frame and moves queries by the transform it stores.
    from occtool.io.depth_folders import DepthFolderScans

    to_log = DepthFolderScans(OFFICE).to_log_frame
    np.testing.assert_allclose(world.to_map, to_log, atol=1e-9)
    points = np.random.default_rng(0).uniform(world.bounds[0], world.bounds[1], size=(200, 3))
    inverse = np.linalg.inv(to_log)
    in_poses_frame = points @ inverse[:3, :3].T + inverse[:3, 3]
    moved = dataclasses.replace(world, to_map=None)
    np.testing.assert_allclose(world.predict(in_poses_frame), moved.predict(points), atol=1e-9)
    csv = tmp_path / "q.csv"
    csv.write_text("x,y,z\n" + "\n".join(",".join(f"{v:.9f}" for v in p) for p in in_poses_frame[:5]) + "\n")
    answered = CliRunner().invoke(cli, ["-q", "query", str(out / "world.occmap"), str(csv), "-o", "-"])
    assert answered.exit_code == 0, answered.output
    column = [float(line.split(",")[-1]) for line in answered.output.strip().splitlines()[1:]]
    np.testing.assert_allclose(column, moved.predict(points[:5]), atol=1e-4)
    described = CliRunner().invoke(cli, ["info", str(out / "world.occmap")])
    assert described.exit_code == 0 and "occmap version 6" in described.output
    assert "levelled on its floor" in described.output


def test_cells_with_returns_but_no_patch_are_never_free_in_the_band() -> None:
    """A cell whose few returns earned it no patch still holds something: the band under
    the table top is not free even when no cell of it got a patch."""
    origins, ends, hits = _scene(table=(2.5, 3.5, 0.75), n=12000)
    world = build_world_map_3d(np.concatenate([np.broadcast_to(o, e.shape) for o, e in zip(origins, ends)]),
                               np.concatenate(ends), np.concatenate(hits), resolution=0.2, coarse_levels=0,
                               min_returns=10 ** 9)
    assert world.patch_count == 0 and world.bare_points is not None and len(world.bare_points) > 0
    raster = project_band(world, np.array(origins), sensor_height=1.0, body_height=1.0, radius=0.25)
    under = [_cell(raster, x, y) for x in np.arange(2.6, 3.41, 0.1) for y in np.arange(2.6, 3.41, 0.1)]
    assert FREE not in under
    assert _cell(raster, 4.0, 2.0) == FREE  # the floor away from it still is
