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

from occtool.octomap import build_octomap, octomap_available, octomap_updates  # noqa: E402


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
    assert three_scans.occupancy([[1.03, 0.02, 0.03]])[0] == pytest.approx(float(1 / (1 + np.exp(-3 * logit(0.7)))), rel=1e-5)
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
