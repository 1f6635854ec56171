"""Synthetic scenes with their ground truth, seen by a simulated stereo camera.

A :class:`Scene` is a set of vertical prisms (a 2D footprint polygon extruded from
``z_min`` to ``z_max`` above the floor): walls, boxes, a table top on thin legs, a low
pallet. The robot stands at the origin facing +x (REP-103); the scene's x, y are
sensor-centred, its z is measured up from the floor. :func:`simulate_scene` casts the
rays of a stereo camera on a pan-tilt unit at the sensor against the prisms and the
floor and returns the registered :class:`~occtool.features.Features` (sensor frame,
z relative to the sensor) together with the scene, which is the truth that
:mod:`occtool.scoring` scores navigation polygons against.

The camera model, the scenes and the truth file format are described in
``docs/scenes.md``.

The parts, one concept a module (private; everything public is imported from here):

==============  =========================================================================
``_scene``      :class:`Obstacle` prisms, :func:`box`, the :class:`Scene`, truth files
``_catalogue``  the built-in scenes: :data:`SCENES`, :func:`build_scene`
``_rays``       :func:`cast_rays`: rays against the prisms and the floor
``_camera``     the pan-tilt stereo camera: :func:`simulate_scene`, its CSV output
``_depth``      a pinhole depth camera: :func:`render_depth_frames`, TUM / 3DMatch folders
==============  =========================================================================
"""

from occtool.simulate._camera import (
    DEFAULT_RANGE_NOISE,
    DEFAULT_SENSOR_RANGE,
    MIN_SENSOR_RANGE,
    TILT_RANGE,
    camera_directions,
    match_evidence,
    save_features_csv,
    simulate_scene,
)
from occtool.simulate._catalogue import SCENES, WALL_HEIGHT, WALL_THICKNESS, build_scene
from occtool.simulate._depth import DepthFrame, render_depth_frames, write_depth_folder
from occtool.simulate._rays import FLOOR, NOTHING, cast_rays
from occtool.simulate._scene import TRUTH_FORMAT, TRUTH_VERSION, Obstacle, Scene, box, load_truth

__all__ = [
    "DEFAULT_RANGE_NOISE",
    "DEFAULT_SENSOR_RANGE",
    "FLOOR",
    "MIN_SENSOR_RANGE",
    "NOTHING",
    "DepthFrame",
    "SCENES",
    "TILT_RANGE",
    "TRUTH_FORMAT",
    "TRUTH_VERSION",
    "WALL_HEIGHT",
    "WALL_THICKNESS",
    "Obstacle",
    "Scene",
    "box",
    "build_scene",
    "camera_directions",
    "cast_rays",
    "load_truth",
    "match_evidence",
    "render_depth_frames",
    "save_features_csv",
    "simulate_scene",
    "write_depth_folder",
]
