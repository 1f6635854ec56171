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

from typing import TYPE_CHECKING

from occtool._lazy import lazy_attributes

# Public name -> the module it lives in, imported on first use (PEP 562): the scene names
# (``SCENES``) load without numpy, for ``occtool simulate --help``.
_LAZY: dict[str, str] = {
    "DEFAULT_RANGE_NOISE": "occtool.simulate._camera",
    "DEFAULT_SENSOR_RANGE": "occtool.simulate._camera",
    "DepthFrame": "occtool.simulate._depth",
    "FLOOR": "occtool.simulate._rays",
    "MIN_SENSOR_RANGE": "occtool.simulate._camera",
    "NOTHING": "occtool.simulate._rays",
    "Obstacle": "occtool.simulate._scene",
    "SCENES": "occtool.simulate._names",
    "Scene": "occtool.simulate._scene",
    "TILT_RANGE": "occtool.simulate._camera",
    "TRUTH_FORMAT": "occtool.simulate._scene",
    "TRUTH_VERSION": "occtool.simulate._scene",
    "WALL_HEIGHT": "occtool.simulate._catalogue",
    "WALL_THICKNESS": "occtool.simulate._catalogue",
    "box": "occtool.simulate._scene",
    "build_scene": "occtool.simulate._catalogue",
    "camera_directions": "occtool.simulate._camera",
    "cast_rays": "occtool.simulate._rays",
    "load_truth": "occtool.simulate._scene",
    "match_evidence": "occtool.simulate._camera",
    "render_depth_frames": "occtool.simulate._depth",
    "save_features_csv": "occtool.simulate._camera",
    "simulate_scene": "occtool.simulate._camera",
    "write_depth_folder": "occtool.simulate._depth",
}

if TYPE_CHECKING:  # pragma: no cover - what the lazy names are, for type checkers and IDEs
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
    from occtool.simulate._catalogue import WALL_HEIGHT, WALL_THICKNESS, build_scene
    from occtool.simulate._depth import DepthFrame, render_depth_frames, write_depth_folder
    from occtool.simulate._names import SCENES
    from occtool.simulate._rays import FLOOR, NOTHING, cast_rays
    from occtool.simulate._scene import TRUTH_FORMAT, TRUTH_VERSION, Obstacle, Scene, box, load_truth

__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())

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
