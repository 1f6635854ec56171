"""The grid baselines: the dense 3D occupancy grid, the textbook 2D grids and OctoMap.

The grid is built the way grid methods sample the sensor model (the paper's Figure 3a):
every cell that a feature's ray crosses between the sensor and the feature gets one
sample. The rays are traversed with a 3D DDA written in numpy (all rays of a chunk at
once, no loop per cell), and the samples are fused per cell in log-odds with OctoMap's
parameters and defaults (:class:`LogOddsParams`).

Each sample is the sensor model's value ``v`` at the sample's distance along the ray,
turned into an observation probability between OctoMap's miss and hit probabilities,
``p = prob_miss + (prob_hit - prob_miss) * v``. With no sensor model (``sensor=None``)
``v`` is 1 in the cell holding the feature and 0 before it, which is OctoMap's own
hit/miss model; with a sensor model and evidence 1 the endpoint cell still gets
``prob_hit``. Log-odds are summed per cell and then clamped to OctoMap's clamping
thresholds (OctoMap clamps after every update, which for one batch of rays only differs
in the order the updates are applied).

The columns under the robot are never seen by its own sensor, so the cells of the
robot's footprint cylinder (its radius, over the body's height band) get the same prior
as the parametric model: free, at the lower clamping threshold.

:meth:`OccupancyGrid.inverse_range` inverts the grid the way the parametric model is
inverted: along a horizontal ray at height ``h``, the distance from the sensor to the
first cell whose occupancy reaches the level. The same navigation extraction then
applies to both.

Unobserved space (cells no sample reached, log-odds 0, probability 0.5) is read one of
two ways (:data:`UNKNOWN_SPACE`, ``inverse_range(..., unknown=...)``):

* ``"free"`` (the default): at its prior probability 0.5, so it is free for every level
  above 0.5 and blocking at or below;
* ``"occupied"``: as a careful planner reads it, the ray also ends where it enters a
  cell whose *column* is unobserved, a column counting as observed when any of its cells
  between the heights of a band (the robot's body band, in the comparison) received a
  sample (:meth:`OccupancyGrid.observed_columns`). Per column rather than per cell,
  because a planar laser observes only its own plane: per cell every other height of the
  body would be unknown and the navigation polygon would collapse (docs/comparison.md).

The parts, one concept a module (private; everything public is imported from here):

==============  =========================================================================
``_logodds``    :func:`logit`, :func:`probability`, :class:`LogOddsParams` (OctoMap's)
``_traverse``   :func:`traverse`: the cells straight rays cross, a vectorised 3D DDA
``_grid``       :class:`OccupancyGrid`: occupancy at points, ``inverse_range`` along rays
``_unknown``    unobserved space: :data:`UNKNOWN_SPACE`, observed bands and columns
``_build``      :func:`build_grid`: samples per crossed cell, the footprint prior
``_textbook``   :func:`textbook_grid`: the textbook 2D log-odds grid of world-frame beams
``_counting``   :func:`counting_grid`: the counting-model (reflection) grid of the same beams
``_octomap``    :func:`build_octomap`, :func:`build_world_octomap`: OctoMap through ``pyoctomap``
==============  =========================================================================

The grids are built here and scored elsewhere: nothing in ``grid`` imports
:mod:`occtool.scoring` or :mod:`occtool.compare` (both import it). The textbook grids'
settings are tuned by their held-out score, so the tuners live in :mod:`occtool.scoring`
(:func:`occtool.scoring.tune_grids`).
"""

from occtool.grid._build import (
    MAX_GRID_BYTES,
    build_grid,
    floor_reach,
    footprint_cells,
    observation_log_odds,
    ray_plan,
)
from occtool.grid._counting import COUNTING_PRIOR, CountingGrid, counting_grid
from occtool.grid._grid import OccupancyGrid
from occtool.grid._logodds import OCTOMAP_DEFAULTS, LogOddsParams, logit, probability
from occtool.grid._octomap import (
    OctoMapModel,
    build_octomap,
    build_world_octomap,
    octomap_available,
    octomap_updates,
    require_pyoctomap,
)
from occtool.grid._textbook import (
    TEXTBOOK_DEFAULTS,
    ScanUpdates,
    TextbookGrid,
    TextbookParams,
    WorldBeams,
    textbook_grid,
)
from occtool.grid._traverse import RaySegments, traverse
from occtool.grid._unknown import (
    UNKNOWN_SPACE,
    band_layers,
    check_unknown,
    first_unobserved,
    footprint_columns_reached,
)

__all__ = [
    "COUNTING_PRIOR",
    "MAX_GRID_BYTES",
    "OCTOMAP_DEFAULTS",
    "TEXTBOOK_DEFAULTS",
    "UNKNOWN_SPACE",
    "CountingGrid",
    "LogOddsParams",
    "OccupancyGrid",
    "OctoMapModel",
    "RaySegments",
    "ScanUpdates",
    "TextbookGrid",
    "TextbookParams",
    "WorldBeams",
    "band_layers",
    "build_grid",
    "build_octomap",
    "build_world_octomap",
    "check_unknown",
    "counting_grid",
    "first_unobserved",
    "floor_reach",
    "footprint_cells",
    "footprint_columns_reached",
    "logit",
    "observation_log_odds",
    "octomap_available",
    "octomap_updates",
    "probability",
    "ray_plan",
    "require_pyoctomap",
    "textbook_grid",
    "traverse",
]
