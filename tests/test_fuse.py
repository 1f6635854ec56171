"""The fused world map: where local models speak, how they combine, the raster, log scoring."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _room_log import ROOM, write_room_log

from occtool.errors import InputError
from occtool.fit import OccupancyRegressor
from occtool.fuse import (
    FREE,
    OCCUPIED,
    FusedMap,
    build_world_map,
    fuse_log,
    fuse_models,
    nearest_returns,
    observed_reach,
    returns_from_guard,
    select_keyframes,
)
from occtool.io import read_log
from occtool.robot import Robot
from occtool.scoring import evaluate_log, holdout_blocks

LASER_ROBOT = Robot(radius=0.25, sensor_height=0.3, body_height=0.5)


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    path = tmp_path_factory.mktemp("room") / "room.log"
    write_room_log(path, scans=60)
    log = read_log(path)
    # Every position (no keyframe selection): these tests are about how positions combine.
    fused, models, report = fuse_log(log, OccupancyRegressor(robot=LASER_ROBOT), keyframe_share=0.0)
    return path, log, fused, models, report


def test_free_inside_occupied_at_walls_unknown_behind(room):
    _, _, fused, _, report = room
    assert report.skipped == []
    _x0, y0, x1, y1 = ROOM
    inside = np.array([[1.0, 0.25, 0.0], [0.0, 0.0, 0.0], [2.0, 1.0, 0.0]])
    walls = np.array([[x1 + 0.02, 0.3, 0.0], [1.0, y1 + 0.02, 0.0], [1.0, y0 - 0.02, 0.0]])
    behind = np.array([[x1 + 1.5, 0.3, 0.0], [1.0, y1 + 1.5, 0.0]])
    ev = fused.evidence(np.vstack([inside, walls, behind]))
    assert ev.observed[:6].all()
    assert (ev.probability[:3] < fused.threshold).all()
    assert (ev.probability[3:6] >= fused.threshold).all()
    # Behind a wall nobody observed: unknown, not free.
    assert not ev.observed[6:].any()
    assert np.allclose(ev.probability[6:], 0.5)


def test_dempster_shafer_masses_are_normalised(room):
    _, _, fused, _, _ = room
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-4, 6, 2000), rng.uniform(-3, 3.5, 2000), np.zeros(2000)])
    for combination in ("log_odds", "dempster_shafer", "mean"):
        ev = fused.evidence(points, combination=combination)
        seen = ev.observed
        total = ev.belief_occupied + ev.belief_free + ev.unknown_mass
        assert np.allclose(total[seen], 1.0)
        assert ((ev.conflict >= 0) & (ev.conflict <= 1)).all()
        assert ((ev.probability >= 0) & (ev.probability <= 1)).all()
        # Unobserved: 0.5, or more near a return (the returns' kernel).
        assert (ev.probability[~seen] >= 0.5).all()
        bare = FusedMap(fused.trees, fused.poses, fused.reaches, fused.robot, combination=combination)
        assert np.allclose(bare.evidence(points).probability[~seen], 0.5)


def test_returns_raise_occupancy_at_walls_only(room):
    _, _, fused, _, _ = room
    bare = FusedMap(fused.trees, fused.poses, fused.reaches, fused.robot)
    _x0, _y0, x1, y1 = ROOM
    wall = np.array([[1.0, y1, 0.0], [x1, 0.3, 0.0]])
    inside = np.array([[1.0, 0.25, 0.0], [2.0, 1.0, 0.0]])
    with_returns, without = fused.predict(np.vstack([wall, inside])), bare.predict(np.vstack([wall, inside]))
    assert (with_returns[:2] >= 0.8).all() and (with_returns[:2] >= without[:2]).all()
    assert np.allclose(with_returns[2:], without[2:])
    # Above the robot's body band a return lends nothing.
    assert np.allclose(fused.predict([[1.0, y1, 2.0]]), bare.predict([[1.0, y1, 2.0]]))


def test_memory_is_the_float32_trees_poses_reaches_and_returns(room):
    from occtool.compare import tree_bytes

    _, _log, fused, models, _ = room
    # float32 coefficients: half of tree_bytes' float64 ones, the same 8 bytes a node.
    trees = sum(tree_bytes(m.tree_) - m.tree_.coefficients.nbytes // 2 for m in models)
    assert fused.returns is not None and fused.returns.shape == (len(models), 360)
    # Returns: 360 uint16 distances and 360 uint8 angles within their bins a position.
    assert fused.return_offsets is not None and fused.return_offsets.shape == (len(models), 360)
    assert fused.nbytes == trees + 32 * len(models) + fused.reaches.nbytes + 1080 * len(models)
    assert fused.reaches.shape == (len(models), 2, 120)


def test_float32_trees_read_as_the_models_within_1e6(room):
    _, _log, fused, models, _ = room
    rng = np.random.default_rng(1)
    alpha, x = rng.uniform(-np.pi, np.pi, 500), rng.uniform(0.1, 8.0, 500)
    for k in (0, len(models) // 2, len(models) - 1):
        exact = models[k].tree_.predict(alpha, np.zeros(500), x)
        assert np.abs(fused.tree(k).predict(alpha, np.zeros(500), x) - exact).max() < 1e-6


def test_raster_rows_grow_with_y_and_walls_are_occupied(room):
    _, _, fused, _, _ = room
    raster = build_world_map(fused).rasterise(0.05)
    _x0, _y0, x1, y1 = ROOM
    row, col, inside = raster.cell_of(np.array([[1.0, y1 + 0.02], [1.0, 0.25], [x1 + 1.5, 0.3]]))
    # Behind the wall nothing was observed: off the raster, which Nav2 reads as unknown.
    assert inside.tolist() == [True, True, False]
    assert raster.cells[row[0], col[0]] == OCCUPIED
    assert raster.cells[row[1], col[1]] == FREE
    # Rows go up in y: the top wall lies in a higher row than the robot's path.
    assert row[0] > row[1]


def test_models_from_files_fuse_like_fresh_ones(room, tmp_path):
    from occtool.formats.model import load_model, save_model

    _, log, _fused, models, report = room
    loaded = []
    for k, model in enumerate(models):
        save_model(model, tmp_path / f"m{k}.json")
        loaded.append(load_model(tmp_path / f"m{k}.json"))
    poses = [log.positions[index].pose for index in report.fitted]
    again = fuse_models(loaded, poses)
    points = np.array([[1.0, 0.25, 0.0], [ROOM[2] + 0.02, 0.3, 0.0]])
    p = again.predict(points)
    assert p[0] < 0.6 <= p[1]


def test_reach_is_zero_where_nothing_was_seen():
    from occtool.features import Features

    # Returns straight ahead only: every other pan bin is unobserved.
    features = Features.from_xyz(np.full(50, 2.0), np.linspace(-0.05, 0.05, 50), np.zeros(50), 0.9)
    reach = observed_reach(features, LASER_ROBOT)
    assert reach[0].max() >= 199 and (reach[0] > 0).sum() <= 3
    assert (reach[1][reach[0] == 0] == np.iinfo(np.uint16).max).all()


def test_fused_map_refuses_positions_without_poses(room):
    _, _, fused, _, _ = room
    with pytest.raises(InputError, match="pose"):
        FusedMap(fused.trees[:1], [None], fused.reaches[:1], LASER_ROBOT)
    with pytest.raises(InputError, match="combination"):
        fused.predict(np.zeros((1, 3)), combination="max")


def test_holdout_blocks_are_whole_consecutive_blocks():
    held = holdout_blocks(910, 0.1, 40, seed=3)
    assert held.sum() == 80
    starts = np.flatnonzero(np.diff(np.concatenate([[0], held.astype(int)])) == 1)
    assert all(s % 40 == 0 for s in starts)
    assert (holdout_blocks(910, 0.1, 40, seed=3) == held).all()
    with pytest.raises(InputError):
        holdout_blocks(30, 0.1, 40)


def test_evaluate_log_scores_the_fused_map(room):
    path = room[0]
    score = evaluate_log(str(path), OccupancyRegressor(robot=LASER_ROBOT), holdout=0.2, block=10, seed=0,
                         no_return_range=None)
    assert score.held_out_scans == 10
    assert score.auc["fused_log_odds"] > 0.9
    assert score.auc["grid"] > 0.5
    assert 0 < score.coverage <= 1
    assert score.nav2["returns_on_occupied"] > 0.5
    assert score.fused_positions <= score.training_positions


def test_occupied_cells_are_where_the_returns_are(room):
    _, _, fused, _, _ = room
    raster = build_world_map(fused).rasterise(0.05)
    occupied = np.argwhere(raster.cells == OCCUPIED)
    centres = np.array(raster.origin) + (occupied[:, ::-1] + 0.5) * raster.resolution
    x0, y0, x1, y1 = ROOM
    to_wall = np.min(np.abs(np.column_stack([centres[:, 0] - x0, centres[:, 0] - x1,
                                             centres[:, 1] - y0, centres[:, 1] - y1])), axis=1)
    # Every occupied cell lies on a wall's band (its centre within WorldMap.wall_half_width of it
    # past its thickness, on the 5 cm grid: 7.5 cm at most here).
    assert len(occupied) > 100 and to_wall.max() <= 0.075 + 1e-9


def test_the_raster_needs_returns(room):
    _, _, fused, _, _ = room
    bare = FusedMap(fused.trees, fused.poses, fused.reaches, fused.robot)
    assert bare.returns is None
    with pytest.raises(InputError, match="no returns"):
        build_world_map(bare)


def test_returns_are_the_guard_in_whole_millimetres():
    from occtool.guard import ReturnGuard

    distance = np.full(360, np.inf)
    distance[[0, 90, 359]] = [1.2345, 0.5, 70.0]
    returns = returns_from_guard(ReturnGuard(distance, 0.6))
    assert returns.dtype == np.uint16 and returns.shape == (360,)
    assert returns[0] == 1234 and returns[90] == 500
    # None, and beyond what uint16 millimetres hold: no return.
    assert returns[359] == np.iinfo(np.uint16).max and returns[1] == np.iinfo(np.uint16).max
    assert (returns_from_guard(None) == np.iinfo(np.uint16).max).all()


def test_nearest_returns_keep_each_bins_own_return_on_its_beam():
    from occtool.features import Features, Pose

    # Returns 3 m and 5 m away at angles off their bins' centres, a farther one in the 3 m
    # return's bin, one inside the robot, one above the body band and a free ray.
    angles = np.radians([10.2, 10.9, 47.77, 120.0, -30.0, 80.0])
    ranges = np.array([3.0, 4.0, 5.0, 0.1, 2.0, 2.5])
    z = np.array([0.0, 0.0, 0.0, 0.0, 0.4, 0.0])
    points = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles), z])
    features = Features(points, np.array([1.0, 1.0, 1.0, 1.0, 1.0, 0.0]))
    millimetres, offsets = nearest_returns(features, LASER_ROBOT)
    held = np.flatnonzero(millimetres != np.iinfo(np.uint16).max)
    assert list(millimetres[held]) == [3000, 5000]  # the nearest whole millimetre
    assert len(held) == 2
    # Placed in a fused map at a turned pose, each lies on its own beam, not the bin's centre.
    pose = Pose(1.0, -2.0, 0.0, 0.7)
    fused = FusedMap([OccupancyRegressor(robot=LASER_ROBOT).fit(features).tree_], [pose],
                     np.zeros((1, 2, 120), np.uint16), LASER_ROBOT, returns=millimetres[None],
                     return_offsets=offsets[None])
    expected = pose.to_world(points[[0, 2], :2])
    assert np.abs(fused.return_points(0) - expected).max() < 2e-3
    centres = FusedMap(fused.trees, [pose], fused.reaches, LASER_ROBOT, returns=millimetres[None])
    assert np.abs(centres.return_points(0) - expected).max() > 0.01  # half a degree off at 5 m: 4 cm
    # The guard's reach: nothing past it; a map's return_reach keeps far returns for walls only.
    assert (nearest_returns(features, LASER_ROBOT, reach=4.0)[0] != np.iinfo(np.uint16).max).sum() == 1
    assert np.abs(fused.return_points(0, within=4.0) - expected[:1]).max() < 2e-3
    with pytest.raises(InputError, match="return_reach"):
        FusedMap(fused.trees, [pose], fused.reaches, LASER_ROBOT, returns=millimetres[None], return_reach=0.0)
    with pytest.raises(InputError, match="same shape"):
        FusedMap(fused.trees, [pose], fused.reaches, LASER_ROBOT, returns=millimetres[None],
                 return_offsets=offsets[None, :10])


def test_keyframes_skip_positions_that_see_nothing_new(room):
    from dataclasses import replace

    _, log, _, _, _ = room
    positions = list(log.positions)
    twice = positions[:5] + [replace(p, index=100 + p.index) for p in positions[:5]]
    kept = select_keyframes(twice, LASER_ROBOT)
    # The repeats saw exactly what the first five saw.
    assert kept and all(k < 5 for k in kept) and kept[0] == 0
    assert select_keyframes(twice, LASER_ROBOT, new_share=0.0) == list(range(10))
    assert len(select_keyframes(positions, LASER_ROBOT, new_share=1.0)) < len(positions)
    with pytest.raises(InputError, match="share"):
        select_keyframes(positions, LASER_ROBOT, new_share=1.5)
    with pytest.raises(InputError, match="cell"):
        select_keyframes(positions, LASER_ROBOT, cell=0.0)


def test_keyframes_of_a_known_small_case():
    from occtool.features import Features, Pose, Position

    def wall(x, y, z=0.0, evidence=0.9):
        """Returns along a wall at x (local frame), at heights z."""
        return Features.from_xyz(np.full(y.size, x), y, np.full(y.size, z), evidence)

    y = np.round(np.arange(-1.0, 1.0001, 0.05), 2)
    longer = np.round(np.arange(-1.0, 1.4001, 0.05), 2)
    positions = [
        Position(0, wall(2.1, y), Pose(0.0, 0.0, 0.0, 0.0)),         # the first: kept
        Position(1, wall(2.1, y), Pose(0.0, 0.0, 0.0, 0.0)),         # the same cells again: not kept
        Position(2, wall(2.1, y), Pose(0.0, 0.0, 0.0, np.pi / 2)),   # turned: another wall, all new
        Position(3, wall(1.1, y), Pose(1.0, 0.0, 0.0, 0.0)),         # closer, the first wall again: not kept
        Position(4, wall(2.1, longer), Pose(0.0, 0.0, 0.0, 0.0)),    # 1-2 of 13 cells new: over 5 %, under 20 %
        Position(5, wall(2.1, y), None),                            # no pose: kept, the fit decides
        Position(6, wall(2.1, y, z=1.0), Pose(0.0, 0.0, 0.0, 0.0)),  # returns above the body band only: kept
        Position(7, wall(2.1, y, evidence=0.0), Pose()),             # free rays only, no returns: kept
    ]
    assert select_keyframes(positions, LASER_ROBOT) == [0, 2, 4, 5, 6, 7]
    assert select_keyframes(positions, LASER_ROBOT, new_share=0.2) == [0, 2, 5, 6, 7]
    # Share 0 keeps every position; share 1 only those whose every cell is new.
    assert select_keyframes(positions, LASER_ROBOT, new_share=0.0) == list(range(8))
    assert select_keyframes(positions, LASER_ROBOT, new_share=1.0) == [0, 2, 5, 6, 7]
    # Cells wide enough to hold the whole first wall in one: the longer one adds none.
    assert 4 not in select_keyframes(positions, LASER_ROBOT, cell=5.0)


@pytest.mark.slow
def test_a_model_set_keeps_what_each_position_observed_and_maps_as_its_log(room, tmp_path):
    from occtool.fuse import fuse_model_set, reach_from_guard
    from occtool.modelset import fit_model_set

    path, log, *_ = room
    summary = fit_model_set(path, tmp_path / "models", estimator=OccupancyRegressor(robot=LASER_ROBOT), jobs=1)
    assert not summary.failures
    fused, models, positions = fuse_model_set(tmp_path / "models")
    features = {p.index: p.features for p in log.positions}
    # The reach and returns come from the position's own features, read back from its file.
    for k, (index, _, _) in enumerate(positions):
        model = models[k]
        reach = observed_reach(features[index], model.robot_, model.focus_range)
        nearest, offsets = nearest_returns(features[index], model.robot_, level=model.level)
        assert np.array_equal(fused.reaches[k], reach)
        assert np.array_equal(fused.returns[k], nearest) and np.array_equal(fused.return_offsets[k], offsets)
    assert fused.return_reach == pytest.approx(models[0].focus_range + models[0].robot_.radius)
    # A free ray (no return in its bin) reaches into the room; the guard alone leaves it unseen.
    guard_only = np.stack([reach_from_guard(m.guard_, m.focus_range) for m in models])
    assert (fused.reaches[:, 0] > guard_only[:, 0]).any()

    # Fitted as `occtool map LOG` fits every position (a focus range the planar defaults keep),
    # the set's fused map and world map answer as the log's own, to the bit.
    estimator = OccupancyRegressor(robot=LASER_ROBOT, focus_range=4.5)
    assert not fit_model_set(path, tmp_path / "same", estimator=estimator, jobs=1).failures
    from_set, _, _ = fuse_model_set(tmp_path / "same")
    from_log, _, _ = fuse_log(log, estimator, keyframe_share=0.0)
    points = np.random.default_rng(0).uniform([-4.0, -3.0, 0.0], [6.0, 3.5, 0.0], (2000, 3))
    assert np.array_equal(from_set.predict(points), from_log.predict(points))
    assert np.array_equal(build_world_map(from_set).predict(points), build_world_map(from_log).predict(points))

    # Files without it (sets written before; single fits) fall back to the return guard.
    for entry in (tmp_path / "models").glob("model_*.json"):
        data = json.loads(entry.read_text())
        del data["observed"]
        entry.write_text(json.dumps(data))
    old, _, _ = fuse_model_set(tmp_path / "models")
    assert np.array_equal(old.reaches[:, 0], guard_only[:, 0]) and old.return_offsets is None


def test_fuse_log_fits_only_keyframes(room):
    path, log, every, _, _ = room
    fused, models, report = fuse_log(log, OccupancyRegressor(robot=LASER_ROBOT), keyframe_share=0.5)
    assert len(fused) == len(models) == len(report.fitted) < len(every)
    assert sorted(report.fitted + report.not_keyframes) == [p.index for p in log.positions]


def test_a_model_set_fuses_from_its_folder_as_from_its_models(room, tmp_path):
    from occtool.formats.model import load_model
    from occtool.fuse import fuse_model_set
    from occtool.modelset import fit_model_set, read_model_set

    path, *_ = room
    summary = fit_model_set(path, tmp_path / "models", estimator=OccupancyRegressor(robot=LASER_ROBOT), jobs=1)
    assert not summary.failures
    fused, models, positions = fuse_model_set(tmp_path / "models")
    folder, entries = read_model_set(tmp_path / "models")
    assert [p[0] for p in positions] == [e["position"] for e in entries] and len(models) == len(entries)
    again = fuse_models([load_model(folder / e["file"]) for e in entries], [p[1] for p in positions])
    points = np.array([[1.0, 0.25, 0.0], [ROOM[2] + 0.02, 0.3, 0.0], [2.0, 1.0, 0.0]])
    assert np.array_equal(fused.predict(points), again.predict(points))

    # The index tells the map a scanning laser's set from its returns per degree, as a log does.
    assert all(0 < e["returns_per_degree"] <= 10 for e in entries)
    assert fused.scanning_laser and not again.scanning_laser and room[4].sightings.scanning_laser
    world = build_world_map(fused)
    assert (world.facing != 0).any()
    # A set written before the index held them: walls facing both sides, as before.
    index = folder / "index.json"
    data = json.loads(index.read_text())
    for entry in data["models"]:
        del entry["returns_per_degree"]
    index.write_text(json.dumps(data))
    old, _, _ = fuse_model_set(folder)
    assert not old.scanning_laser and (build_world_map(old).facing == 0).all()
