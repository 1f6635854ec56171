"""The baselines: the :class:`OccupancyMap` protocol, :class:`Baseline`, :data:`GRID`, :data:`OCTOMAP`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from occtool.features import Features
from occtool.robot import Robot

FloatArray = NDArray[np.float64]


class OccupancyMap(Protocol):
    """What the comparison asks of a built baseline.

    :class:`occtool.grid.OccupancyGrid` and :class:`occtool.grid.OctoMapModel` offer it.
    """

    @property
    def memory_bytes(self) -> int:
        """Memory of the map, bytes."""
        ...

    def file_bytes(self) -> int:
        """Size of the map saved to a file, bytes."""
        ...

    def occupancy(self, points: FloatArray) -> FloatArray:
        """Occupancy probability at ``(N, 3)`` points; 0.5 where the map knows nothing."""
        ...

    def inverse_range(
        self,
        alpha: Any,
        h: Any,
        level: float,
        max_range: float | None = None,
        *,
        unknown: str = "free",
        band: tuple[float, float] | None = None,
    ) -> FloatArray:
        """As :meth:`occtool.grid.OccupancyGrid.inverse_range`."""
        ...


@dataclass(frozen=True)
class BuildInputs:
    """What every baseline is built from: the training features and the shared settings."""

    features: Features
    resolution: float
    robot: Robot
    sensor: Any
    grid_bounds: tuple[Any, Any] | None = None
    octomap_scans: int = 10


def _no_figures(built: Any, inputs: BuildInputs) -> dict[str, Any]:
    return {}


@dataclass(frozen=True)
class Baseline:
    """An occupancy map the parametric model is compared with.

    Attributes
    ----------
    name
        Its key in the report (``models``, ``agreement``, ``ratios``, ``auc``, ...).
    build
        Builds the map from the inputs; timed as the baseline's build time.
    samples
        The samples (cell updates) the built map fused, for the report.
    figures
        Figures of its own for its ``models`` entry, after the common ones.
    """

    name: str
    build: Callable[[BuildInputs], OccupancyMap]
    samples: Callable[[Any, BuildInputs], int]
    figures: Callable[[Any, BuildInputs], dict[str, Any]] = _no_figures


def _build_grid(inputs: BuildInputs) -> OccupancyMap:
    from occtool.grid import build_grid

    return build_grid(
        inputs.features,
        resolution=inputs.resolution,
        robot=inputs.robot,
        sensor=inputs.sensor,
        bounds=inputs.grid_bounds,
    )


def _build_octomap(inputs: BuildInputs) -> OccupancyMap:
    from occtool.grid import build_octomap

    return build_octomap(
        inputs.features,
        resolution=inputs.resolution,
        robot=inputs.robot,
        scans=inputs.octomap_scans,
        sensor=inputs.sensor,
    )


def _octomap_samples(tree: Any, inputs: BuildInputs) -> int:
    from occtool.grid import octomap_updates

    return octomap_updates(
        inputs.features, inputs.resolution, inputs.octomap_scans, robot=inputs.robot, sensor=inputs.sensor
    )


#: The dense 3D log-odds grid of :mod:`occtool.grid`.
GRID = Baseline(
    "grid",
    build=_build_grid,
    samples=lambda grid, inputs: grid.samples,
    figures=lambda grid, inputs: {
        "cells": int(np.prod(grid.shape)),
        "observed_cells": grid.observed_cells,
        "shape": list(grid.shape),
    },
)

#: OctoMap through ``pyoctomap`` (:func:`occtool.grid.build_octomap`); its samples are recounted cell updates.
OCTOMAP = Baseline(
    "octomap",
    build=_build_octomap,
    samples=_octomap_samples,
    figures=lambda tree, inputs: {"leaves": tree.leaf_count, "scans": int(inputs.octomap_scans)},
)


def observation_band(robot: Robot, heights: Any = None) -> tuple[float, float]:
    """Heights whose cells make a grid column observed with ``unknown="occupied"``.

    The robot's body band, widened to any navigation heights asked for outside it: what
    the sensor saw at one height of the band stands for the whole column there
    (docs/comparison.md, "Unobserved space").
    """
    low, high = robot.body_band
    if heights is not None:
        requested = np.asarray(heights, dtype=np.float64).ravel()
        if requested.size and np.isfinite(requested).all():
            low, high = min(low, float(requested.min())), max(high, float(requested.max()))
    return float(low), float(high)
