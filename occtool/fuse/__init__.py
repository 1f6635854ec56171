"""One world-frame occupancy map from the local models of a whole log.

occtool fits one small model per robot position, in that position's sensor-centred
frame. A local model only *speaks* where its position observed: at pan angles its rays
covered, in front of the first obstacle at that angle (plus the obstacle's own depth
window; a function increasing in range says nothing true behind it) and no farther than
its rays reached or the fit's focus range. :func:`observed_reach` records that, per pan
bin, as a few hundred bytes next to the model.

:class:`FusedMap` is the list of local trees, their poses and reaches (nothing else: no
grid), and answers occupancy queries at world points by combining every position that
observed the point:

* ``"log_odds"``: the models' occupancies, clamped as OctoMap clamps, added as log-odds;
* ``"dempster_shafer"``: each model gives masses ``occupied = c F``, ``free = c (1 - F)``,
  ``unknown = 1 - c``; Dempster's conjunctive rule combines them (as products of
  commonalities), the conflict mass flags positions that contradict each other, and the
  probability reported is the pignistic one;
* ``"mean"``: the plain mean of the speaking models.

Where no model speaks the place is *unknown* (never free). Each position also keeps its
nearest return per pan degree (:func:`nearest_returns`: 720 bytes of distances and 360 of
angles within the bin; a model read from a file, the :class:`Observation` a model set's
file keeps, or in older files and single fits its return guard's distances at the bins'
centres): :meth:`FusedMap.predict` joins them to the
models' occupancy, and the world map refitted from them (:func:`build_world_map`)
draws the free / occupied / unknown grid over the robot's body band
(:meth:`WorldMap.rasterise`) with its walls where the returns fall.
:func:`fuse_log` fits only the log's keyframes (:func:`select_keyframes`).

The parts, one concept a module (private; everything public is imported from here):

==============  =======================================================================
``_combine``    the combination rules (log-odds, Dempster-Shafer, mean) and :class:`Evidence`
``_map``        :class:`FusedMap`: storage, where each model speaks, queries
``_build``      :func:`fuse_log`, :func:`fuse_models`, :func:`fuse_model_set` and :class:`FuseReport`
``_walls``      walls as linear pieces: the returns summarised into segments, and who saw through them
``_sightings``  :class:`RunReturns`: what every position of the run saw, per pan bin
``_world``      :class:`WorldMap`: the run in the world frame, a few kilobytes; its raster; its file
``_refit``      :func:`build_world_map`: a fused map (and its sightings) refitted as a :class:`WorldMap`
``_keyframes``  the positions of a log worth fitting (:func:`select_keyframes`)
``_run``        :func:`map_of_run`: the map of a run (world map, raster, navigation region, frontiers)
``_outputs``    :func:`write_run_map`: its files (world map, Nav2, MCAP, GeoJSON, summary)
``_mapping``    :func:`map_log`, :func:`map_model_set`: the library ``occtool map``
``_patches``    planar patches and crossed free space: the numbers of a 3D map
``_world3d``    :class:`WorldMap3D`: the run in x, y, z (a 3D log's ``world.occmap``)
``_log3d``      :func:`map_log_3d`: a log's rays, whether it is 3D, its 3D map built
``_inner_split``  :func:`choose_resolution`: the 3D map's cell size, on the run's own positions
``_projection`` :func:`project_band`: a 3D map's body band over the ground per tile, for Nav2
``_load``       :func:`load_map`: a saved map of either kind
==============  =======================================================================

Below it, and below :mod:`occtool.formats` which writes its files: :mod:`occtool.observation`
(what a position observed: reach and first obstacle per pan bin, returns; the
:class:`Observation` a model file keeps) and :mod:`occtool.raster` (:class:`Raster` and the
Nav2 pixel values). :mod:`occtool.formats.occmap` reads and writes the ``.occmap`` file's
numbers; :func:`load_map` makes a :class:`WorldMap` of them (a :class:`WorldMap3D` of a version-5 or -6 file).

A :class:`FusedMap` is the run as its local models saw it (a megabyte and more for a
building); :func:`build_world_map` refits it into a :class:`WorldMap` (walls as MIN nodes
over linear pieces in world x, y under one MAX, over the region some position observed),
the map ``occtool map`` writes as ``world.occmap`` and draws for Nav2 (docs/map.md).
:func:`map_log` and :func:`map_model_set` are ``occtool map`` as library calls.
"""

from typing import TYPE_CHECKING

from occtool._lazy import lazy_attributes
from occtool.fuse._build import FuseReport, fuse_log, fuse_model_set, fuse_models
from occtool.fuse._combine import (
    CLAMP,
    COMBINATIONS,
    CONFLICT_FLAG,
    DEFAULT_COMBINATION,
    DS_CONFIDENCE,
    RETURN_KERNEL,
    Evidence,
)
from occtool.fuse._inner_split import choose_resolution
from occtool.fuse._keyframes import KEYFRAME_CELL, KEYFRAME_NEW_SHARE, select_keyframes
from occtool.fuse._load import load_map
from occtool.fuse._log3d import is_3d_log, map_log_3d
from occtool.fuse._map import FRONT_MARGIN, FusedMap
from occtool.fuse._merge import merge_files, merge_maps
from occtool.fuse._projection import project_band
from occtool.fuse._refit import build_world_map
from occtool.fuse._sightings import RunReturns, returns_of_positions
from occtool.fuse._world import WorldMap, decode_map
from occtool.fuse._world3d import WorldMap3D, build_world_map_3d
from occtool.observation import (
    LASER_RETURNS_PER_DEGREE,
    NO_OBSTACLE,
    OFFSET_STEPS,
    REACH_BINS,
    REACH_UNIT,
    Observation,
    is_scanning_laser,
    nearest_returns,
    observe,
    observed_reach,
    reach_from_guard,
    returns_from_guard,
    returns_per_degree,
)
from occtool.raster import FREE, OCCUPIED, UNKNOWN, Raster

# The map of a run and its writers, imported on first use (PEP 562): they import shapely
# at their top, and `import occtool.fuse` stays as light as it was without them.
_LAZY: dict[str, str] = {
    "FRONTIER_MIN_LENGTH": "occtool.fuse._run",
    "frontiers_of": "occtool.fuse._run",
    "PlacedMap": "occtool.fuse._run",
    "RunMap": "occtool.fuse._run",
    "map_of_run": "occtool.fuse._run",
    "NAV2_MODES": "occtool.fuse._outputs",
    "check_outputs": "occtool.fuse._outputs",
    "output_paths": "occtool.fuse._outputs",
    "write_run_map": "occtool.fuse._outputs",
    "MapResult": "occtool.fuse._mapping",
    "map_log": "occtool.fuse._mapping",
    "map_model_set": "occtool.fuse._mapping",
}

if TYPE_CHECKING:  # pragma: no cover - what the lazy names are, for type checkers and IDEs
    from occtool.fuse._mapping import MapResult, map_log, map_model_set
    from occtool.fuse._outputs import (
        NAV2_MODES,
        check_outputs,
        output_paths,
        write_run_map,
    )
    from occtool.fuse._run import FRONTIER_MIN_LENGTH, PlacedMap, RunMap, frontiers_of, map_of_run

__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())

__all__ = [
    "FRONTIER_MIN_LENGTH",
    "KEYFRAME_CELL",
    "KEYFRAME_NEW_SHARE",
    "NAV2_MODES",
    "MapResult",
    "PlacedMap",
    "RunMap",
    "check_outputs",
    "frontiers_of",
    "map_log",
    "map_model_set",
    "map_of_run",
    "output_paths",
    "write_run_map",
    "CLAMP",
    "COMBINATIONS",
    "CONFLICT_FLAG",
    "DEFAULT_COMBINATION",
    "DS_CONFIDENCE",
    "FREE",
    "LASER_RETURNS_PER_DEGREE",
    "FRONT_MARGIN",
    "NO_OBSTACLE",
    "OCCUPIED",
    "OFFSET_STEPS",
    "REACH_BINS",
    "REACH_UNIT",
    "RETURN_KERNEL",
    "UNKNOWN",
    "Evidence",
    "FuseReport",
    "FusedMap",
    "Observation",
    "Raster",
    "RunReturns",
    "WorldMap",
    "WorldMap3D",
    "build_world_map",
    "build_world_map_3d",
    "choose_resolution",
    "decode_map",
    "fuse_log",
    "fuse_model_set",
    "fuse_models",
    "is_3d_log",
    "is_scanning_laser",
    "load_map",
    "map_log_3d",
    "merge_files",
    "merge_maps",
    "nearest_returns",
    "observe",
    "observed_reach",
    "project_band",
    "reach_from_guard",
    "returns_from_guard",
    "returns_of_positions",
    "returns_per_degree",
    "select_keyframes",
]
