"""The OctoMap baseline through pyoctomap: same lattice, parameters and queries as the grid."""

from __future__ import annotations

import builtins
import sys

import numpy as np
import pytest

from occtool.errors import InputError, MissingDependencyError
from occtool.features import Features
from occtool.grid import build_grid, logit
from occtool.robot import Robot

pyoctomap = pytest.importorskip("pyoctomap")

from occtool.grid import (  # noqa: E402
    OctoMapModel,
    build_octomap,
    build_world_octomap,
    octomap_available,
    octomap_updates,
)


def _wall(x: float = 2.03, n: int = 3000, seed: int = 0) -> Features:
    rng = np.random.default_rng(seed)
    return Features.from_xyz(np.full(n, x), rng.uniform(-2, 2, n), rng.uniform(-0.95, 1.0, n), 1.0)


def test_single_ray_matches_octomap_semantics() -> None:
    features = Features.from_xyz([1.03], [0.02], [0.03], 1.0)
    tree = build_octomap(features, resolution=0.1, footprint_prior=False)
    np.testing.assert_allclose(tree.occupancy([[1.03, 0.02, 0.03]]), 0.7, rtol=1e-6)
    np.testing.assert_allclose(tree.occupancy([[0.55, 0.02, 0.03]]), 0.4, rtol=1e-6)
    assert tree.occupancy([[0.5, 0.5, 0.5]])[0] == 0.5
    # The same cells as the dense grid's traversal: 10 misses and one hit.
    assert octomap_updates(features, 0.1) == 11
    assert build_grid(features, resolution=0.1, footprint_prior=False).observed_cells == 11


def test_one_update_per_cell_and_scan() -> None:
    same = Features.from_xyz(np.full(3, 1.03), np.full(3, 0.02), np.full(3, 0.03), 1.0)
    one_scan = build_octomap(same, resolution=0.1, footprint_prior=False)
    three_scans = build_octomap(same, resolution=0.1, footprint_prior=False, scans=3)
    assert one_scan.occupancy([[1.03, 0.02, 0.03]])[0] == pytest.approx(0.7)
    assert three_scans.occupancy([[1.03, 0.02, 0.03]])[0] == pytest.approx(
        float(1 / (1 + np.exp(-3 * logit(0.7)))), rel=1e-5
    )
    assert octomap_updates(same, 0.1, scans=3) == 3 * octomap_updates(same, 0.1)
    # Past the upper clamping threshold the cell stays at it.
    many = Features.from_xyz(np.full(6, 1.03), np.full(6, 0.02), np.full(6, 0.03), 1.0)
    assert build_octomap(many, resolution=0.1, scans=6).occupancy([[1.03, 0.02, 0.03]])[0] == pytest.approx(0.971)


def test_footprint_prior_and_inverse_range_agree_with_the_grid() -> None:
    # Dense enough that every wall cell holds a feature.
    features = _wall(n=20000)
    robot = Robot()
    tree = build_octomap(features, resolution=0.1, robot=robot)
    grid = build_grid(features, resolution=0.1, robot=robot)
    assert tree.occupancy([[0.05, 0.05, -0.5]])[0] == pytest.approx(0.1192, rel=1e-4)
    alphas = np.linspace(-0.6, 0.6, 25)
    heights = np.array([[-0.7], [-0.2], [0.3]])
    r_tree = tree.inverse_range(alphas, heights, 0.6, max_range=3.0)
    r_grid = grid.inverse_range(alphas, heights, 0.6, max_range=3.0)
    assert r_tree.shape == (3, 25)
    horizontal = np.sqrt(r_tree**2 - heights**2) * np.cos(alphas)
    assert np.all(np.abs(horizontal - 2.0) <= 0.1 + 1e-6)
    # One scan of one-hit cells: both models hold the same cells at 0.7 on the wall.
    np.testing.assert_allclose(r_tree, r_grid, atol=0.1 + 1e-6)
    assert np.all(tree.inverse_range(np.pi, heights, 0.6, max_range=3.0) == np.inf)
    # The occupancy threshold is restored after the ray casts.
    assert tree.tree.getOccupancyThres() == pytest.approx(0.5)


def test_memory_and_file_size_are_reported() -> None:
    tree = build_octomap(_wall(), resolution=0.1)
    assert tree.memory_bytes > 10_000
    assert tree.leaf_count > 100
    size = tree.file_bytes()
    assert size > 1000
    # Writing the file leaves the probabilities intact.
    assert tree.occupancy([[2.03, 0.0, 0.0]])[0] in (pytest.approx(0.7), pytest.approx(0.5))


def test_bad_input_is_a_clear_error() -> None:
    with pytest.raises(InputError, match="resolution"):
        build_octomap(_wall(n=5), resolution=-1.0)
    with pytest.raises(InputError, match="scans"):
        build_octomap(_wall(n=5), resolution=0.1, scans=0)


def test_missing_extra_names_the_package(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def no_pyoctomap(name: str, *args, **kwargs):
        if name == "pyoctomap" or name.startswith("pyoctomap."):
            raise ImportError("No module named 'pyoctomap'")
        return real_import(name, *args, **kwargs)

    monkeypatch.delitem(sys.modules, "pyoctomap", raising=False)
    monkeypatch.setattr(builtins, "__import__", no_pyoctomap)
    assert not octomap_available()
    with pytest.raises(MissingDependencyError, match=r"pip install 'occtool\[octomap\]'"):
        build_octomap(_wall(n=5), resolution=0.1)


def test_default_search_range_covers_the_tree() -> None:
    tree = build_octomap(_wall(n=20000), resolution=0.1)
    r = tree.inverse_range(np.array([0.0, np.pi]), 0.0, 0.6)
    assert abs(r[0] - 2.0) <= 0.1 + 1e-6
    assert r[1] == np.inf
    with pytest.raises(InputError, match="max range"):
        tree.inverse_range(0.0, 0.0, 0.6, max_range=np.inf)


# ------------------------------------------------------------------ unobserved space


def _planar_scan_tree() -> OctoMapModel:
    """The layout of tests/test_grid.py's hand-made grid, node by node: the laser's layer
    (z in [0, 0.1)) free from x = -0.2 to 1.8 and y = -0.2 to 0.2, no node at x in
    [0.8, 1.0) (the gap), a hit at x in [1.5, 1.6). One 2x2x2 block at x in [1.2, 1.4),
    y in [0, 0.2), z in [0, 0.2) is all free, so OctoMap prunes it into one 0.2 m leaf."""
    tree = pyoctomap.OcTree(0.1)
    miss, hit = float(logit(0.4)), float(logit(0.7))

    def put(i: int, j: int, k: int, value: float) -> None:
        tree.updateNode(np.array([(i + 0.5) * 0.1, (j + 0.5) * 0.1, (k + 0.5) * 0.1]), value, False)

    for i in range(-2, 18):
        for j in range(-2, 2):
            if i not in (8, 9):
                put(i, j, 0, hit if i == 15 else miss)
    for i in (12, 13):
        for j in (0, 1):
            put(i, j, 1, miss)
    return OctoMapModel(tree=tree, resolution=0.1)


def test_unknown_free_passes_the_gap_and_occupied_stops_at_it() -> None:
    model = _planar_scan_tree()
    sizes = {round(leaf.getSize(), 6) for leaf in model.tree.begin_leafs()}
    assert sizes == {0.1, 0.2}  # the pruned block is one leaf
    heights = np.array([[0.05], [-0.15], [0.25]])
    free = np.sqrt(model.inverse_range(0.0, heights, 0.6, max_range=2.5) ** 2 - heights**2)
    assert free[0, 0] == pytest.approx(1.5)
    assert np.isinf(free[1:]).all()
    occupied = model.inverse_range(0.0, heights, 0.6, max_range=2.5, unknown="occupied")
    np.testing.assert_allclose(np.sqrt(occupied**2 - heights**2), 0.8)
    # The pruned leaf's four columns are observed; the band must reach the laser's layer.
    observed, offset = model.observed_columns(reach=2.0)
    assert observed[12 - offset[0] : 14 - offset[0], 0 - offset[1] : 2 - offset[1]].all()
    assert observed.sum() == 18 * 4
    assert not model.observed_columns((-0.3, -0.05), reach=2.0)[0].any()
    # Behind the laser: the last node is at x = -0.2.
    behind = model.inverse_range(np.pi, 0.05, 0.6, max_range=2.5, unknown="occupied")
    assert np.sqrt(behind**2 - 0.05**2) == pytest.approx(0.2)
    with pytest.raises(InputError, match="'free' or 'occupied'"):
        model.inverse_range(0.0, 0.0, 0.6, unknown="closed")


def test_unknown_occupied_agrees_with_the_grid_on_a_planar_scan() -> None:
    # A planar laser over 120 degrees with no return from 10 to 30 degrees, a wall at x = 1.03.
    robot = Robot(radius=0.1, sensor_height=0.3, body_height=0.4)
    degrees = np.arange(-60.0, 60.5, 0.5)
    alpha = np.radians(degrees[(degrees < 10) | (degrees > 30)])
    r = 1.03 / np.cos(alpha)
    features = Features.from_xyz(r * np.cos(alpha), r * np.sin(alpha), np.zeros_like(alpha), 1.0)
    tree = build_octomap(features, resolution=0.05, robot=robot)
    grid = build_grid(features, resolution=0.05, robot=robot)
    assert tree.footprint == grid.footprint == 0.1
    angles = np.radians(np.arange(-180.0, 180.0, 7.0))[None, :]
    heights = np.array([[-0.2], [0.01], [0.08]])
    for unknown in ("free", "occupied"):
        r_tree = tree.inverse_range(angles, heights, 0.6, max_range=2.0, unknown=unknown, band=robot.body_band)
        r_grid = grid.inverse_range(angles, heights, 0.6, max_range=2.0, unknown=unknown, band=robot.body_band)
        np.testing.assert_allclose(r_tree, r_grid, atol=1e-9)
    # Occupied: behind the laser the rays end past the robot's footprint, in the first
    # column beyond half a cell of its disk; in the gap short of the wall; free: they run on.
    horizontal = np.sqrt(r_tree**2 - heights**2)
    behind = np.abs(angles[0]) > np.radians(100)
    known = 0.1 + 0.05 / 2
    assert (horizontal[:, behind] >= known - 1e-9).all()
    assert (horizontal[:, behind] <= known + 0.05 * np.sqrt(2) + 1e-9).all()
    gap = np.radians(20.0)
    assert np.sqrt(tree.inverse_range(gap, 0.01, 0.6, max_range=2.0, unknown="occupied") ** 2 - 1e-4) < 0.5
    assert np.isinf(tree.inverse_range(gap, 0.01, 0.6, max_range=2.0))


def test_an_evidence_zero_feature_only_clears_its_ray() -> None:
    from occtool.sensor import SensorModel

    beam = Features.from_xyz([3.03], [0.02], [-0.47], 0.0)
    tree = build_octomap(beam, resolution=0.1, footprint_prior=False, sensor=SensorModel())
    assert tree.occupancy([[3.03, 0.02, -0.47]])[0] <= 0.5
    assert tree.occupancy([[1.52, 0.01, -0.235]])[0] == pytest.approx(0.4, rel=1e-5)


def test_world_octomap_inserts_each_scan_from_its_own_origin():
    # Two scans from different origins, in the z = 0.025 plane: a return 1 m ahead of each,
    # and a free ray (evidence 0) 1 m long from the second.
    z = 0.025
    first = (np.array([0.0, 0.0, z]), np.array([[1.0, 0.0, z]]), np.array([1.0]))
    second = (np.array([5.0, 5.0, z]), np.array([[5.0, 6.0, z], [4.0, 5.0, z]]), np.array([1.0, 0.0]))
    model = build_world_octomap([first, second], resolution=0.05)
    p = model.occupancy(np.array([[1.0, 0.0, z], [0.5, 0.0, z], [1.5, 0.0, z],  # first: hit, crossed, behind
                                  [5.0, 6.0, z], [5.0, 5.5, z],  # second: hit, crossed (from its own origin)
                                  [4.5, 5.0, z], [4.01, 5.0, z],  # free ray: crossed, its last cell
                                  [0.5, 5.0, z]]))  # nothing passed here
    assert p[0] > 0.5 and p[3] > 0.5
    assert p[1] < 0.5 and p[4] < 0.5 and p[5] < 0.5
    assert p[2] == 0.5 and p[6] == 0.5 and p[7] == 0.5
    with pytest.raises(InputError):
        build_world_octomap([first], resolution=0.0)
