"""The parametric model against occupancy grids, on the same features and the same output.

:func:`compare_grid` fits the parametric model and builds the baselines from the same
features (less a held-out share), extracts the navigation polygon from each with the
same settings, and reports what each costs (samples, time, memory) and how each does
(agreement with the parametric polygon, IoU and safety against a scene's truth, ROC AUC
of occupancy on held-out features). The report is a plain dict, the layout of
``occtool compare-grid --json`` (see docs/comparison.md).

Baselines, each a :class:`Baseline` (a name, a build function, its samples and figures)
whose built map offers the :class:`OccupancyMap` protocol (``inverse_range``,
``occupancy``, ``memory_bytes``, ``file_bytes``); every baseline goes through the same
build, extraction and scoring:

* ``grid`` (:data:`GRID`): the dense 3D grid of :mod:`occtool.grid`, fed with the same
  sensor model;
* ``octomap`` (:data:`OCTOMAP`): OctoMap through ``pyoctomap`` (:func:`occtool.grid.build_octomap`),
  optional.

Both get the parametric model's prior on the robot's footprint (it is free), since the
robot's own sensor never sees the columns under it. Their navigation polygons read
unobserved space as free (the default) or, with ``unknown="occupied"``, as a careful
planner does: closed where no cell of the column was observed in the robot's body band.

The parts, one concept a module (private; everything public is imported from here):

===============  ========================================================================
``_compare``     :func:`compare_grid`: build, extract and score every model; the report
``_baselines``   :class:`OccupancyMap`, :class:`Baseline`, :data:`GRID`, :data:`OCTOMAP`
``_results``     :class:`ModelResult`: what a model cost (time, memory, file size)
===============  ========================================================================
"""

from occtool.compare._baselines import (
    GRID,
    OCTOMAP,
    Baseline,
    BuildInputs,
    OccupancyMap,
    observation_band,
)
from occtool.compare._compare import REPORT_VERSION, UNKNOWN_SPACE_NOTES, compare_grid, report_json
from occtool.compare._results import ModelResult, tree_bytes

__all__ = [
    "GRID",
    "OCTOMAP",
    "REPORT_VERSION",
    "UNKNOWN_SPACE_NOTES",
    "Baseline",
    "BuildInputs",
    "ModelResult",
    "OccupancyMap",
    "compare_grid",
    "observation_band",
    "report_json",
    "tree_bytes",
]
