"""The simulated pan-tilt stereo camera: :func:`simulate_scene` and its parts."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Features
from occtool.limits import MAX_DISTANCE, MAX_FEATURES, MAX_RANGE_NOISE
from occtool.robot import Robot
from occtool.simulate._catalogue import build_scene
from occtool.simulate._rays import FLOOR, NOTHING, cast_rays
from occtool.simulate._scene import Scene

FloatArray = NDArray[np.float64]

#: Pan-tilt limits of the simulated camera, radians (tilt 0 is horizontal, negative looks down).
TILT_RANGE: tuple[float, float] = (math.radians(-50.0), math.radians(30.0))
#: Default stereo depth noise coefficient: sigma(r) = range_noise * r**2 metres.
DEFAULT_RANGE_NOISE = 0.01
#: Farthest range at which the stereo matcher still registers a feature, metres.
DEFAULT_SENSOR_RANGE = 6.0
#: Nearest range of the stereo matcher (the cameras' overlap starts here), metres.
MIN_SENSOR_RANGE = 0.2


def camera_directions(n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` view directions of the pan-tilt camera: pan uniform over 360 degrees, tilt in :data:`TILT_RANGE`."""
    pan = rng.uniform(-math.pi, math.pi, n)
    tilt = rng.uniform(TILT_RANGE[0], TILT_RANGE[1], n)
    c = np.cos(tilt)
    return np.column_stack([c * np.cos(pan), c * np.sin(pan), np.sin(tilt)])


def match_evidence(ranges: FloatArray, rng: np.random.Generator) -> FloatArray:
    """Evidence from a simulated stereo match error: mostly 0.7..1.0, a little lower far away."""
    error = 0.15 * np.abs(rng.standard_normal(ranges.shape[0])) + 0.02 * ranges
    return np.clip(1.0 - error, 0.05, 1.0)


def simulate_scene(
    name: str | Scene,
    *,
    n_features: int = 10000,
    seed: int = 0,
    range_noise: float = DEFAULT_RANGE_NOISE,
    outlier_rate: float = 0.05,
    robot: Robot | None = None,
    yaw: float = 0.0,
    sensor_range: float = DEFAULT_SENSOR_RANGE,
) -> tuple[Features, Scene]:
    """Register features in a scene with a simulated pan-tilt stereo camera.

    The camera at the sensor looks in directions drawn uniformly in pan (360 degrees) and
    tilt (:data:`TILT_RANGE`); a view direction whose ray meets a textured surface (the
    floor included) within ``sensor_range`` yields one feature. Its range carries
    Gaussian stereo noise with standard deviation ``range_noise * r**2``; a share
    ``outlier_rate`` of the features are mismatches placed at a range uniform in
    [0.2 m, ``sensor_range``] along the same ray. Evidence comes from a simulated match
    error (see :func:`match_evidence`), outliers included.

    Parameters
    ----------
    name
        A scene name from :data:`SCENES`, or a :class:`Scene`.
    n_features
        Number of features to register.
    seed
        Random seed; the result is a function of all arguments.
    range_noise
        Stereo noise coefficient, metres per square metre of range.
    outlier_rate
        Share of features at a wrong range, in [0, 1].
    robot
        The robot (sensor height, body); default ``Robot()`` or the given scene's robot.
    yaw
        Turn the whole scene, features and truth alike, by this many radians.
    sensor_range
        Farthest range at which features are registered, metres.

    Returns
    -------
    features
        The registered features, sensor-centred robot frame.
    scene
        The truth: the scene as simulated, turned by ``yaw``.

    Examples
    --------
    >>> features, scene = simulate_scene("office", n_features=500, seed=1)
    >>> len(features), scene.name
    (500, 'office')
    """
    if isinstance(name, Scene):
        scene = name if robot is None else name.with_robot(robot)
    else:
        scene = build_scene(name, robot=robot)
    if not isinstance(n_features, (int, np.integer)) or n_features < 0:
        raise InputError(f"the number of features must be a whole number >= 0, got {n_features!r}")
    if n_features > MAX_FEATURES:
        raise InputError(f"n_features must be at most {MAX_FEATURES:,}, got {n_features:,}")
    if not (np.isfinite(range_noise) and range_noise >= 0):
        raise InputError(f"range noise must be a finite number >= 0, got {range_noise}")
    if range_noise > MAX_RANGE_NOISE:
        raise InputError(f"range_noise must be at most {MAX_RANGE_NOISE:g} (per metre squared), got {range_noise:g}")
    if not 0.0 <= outlier_rate <= 1.0:
        raise InputError(f"outlier rate must lie in [0, 1], got {outlier_rate}")
    if not (np.isfinite(sensor_range) and sensor_range > MIN_SENSOR_RANGE):
        raise InputError(f"sensor range must be a finite number > {MIN_SENSOR_RANGE} m, got {sensor_range}")
    if sensor_range > MAX_DISTANCE:
        raise InputError(f"sensor_range must be at most {MAX_DISTANCE:g} m, got {sensor_range:g}")
    if not np.isfinite(yaw):
        raise InputError(f"yaw must be finite, got {yaw}")

    rng = np.random.default_rng(seed)
    textured = np.array([o.textured for o in scene.obstacles] + [True], dtype=bool)  # last: floor
    found_dirs: list[FloatArray] = []
    found_ranges: list[FloatArray] = []
    have = 0
    batch = max(64, int(n_features * 1.5))
    for _ in range(200):
        if have >= n_features:
            break
        dirs = camera_directions(batch, rng)
        ranges, surface = cast_rays(scene, dirs, max_range=sensor_range)
        seen = (surface != NOTHING) & (ranges >= MIN_SENSOR_RANGE)
        seen &= textured[np.where(surface == FLOOR, -1, surface)]
        found_dirs.append(dirs[seen])
        found_ranges.append(ranges[seen])
        have += int(seen.sum())
        rate = max(seen.mean(), 0.01)
        batch = max(64, int((n_features - have) / rate * 1.2))
    if have < n_features:
        raise InputError(f"scene {scene.name!r} shows too few textured surfaces to register {n_features} features")
    dirs = np.concatenate([np.empty((0, 3)), *found_dirs])[:n_features]
    true_range = np.concatenate([np.empty(0), *found_ranges])[:n_features]

    measured = true_range + rng.standard_normal(n_features) * range_noise * true_range**2
    outlier = rng.random(n_features) < outlier_rate
    measured[outlier] = rng.uniform(MIN_SENSOR_RANGE, sensor_range, int(outlier.sum()))
    measured = np.maximum(measured, 0.5 * MIN_SENSOR_RANGE)
    evidence = match_evidence(true_range, rng)
    features = Features(dirs * measured[:, None], evidence)
    if yaw:
        return features.rotated(yaw), scene.rotated(yaw)
    return features, scene


def save_features_csv(features: Features, path: str | os.PathLike[str], comments: Sequence[str] = ()) -> None:
    """Write features as CSV with header ``x,y,z,m`` after ``#`` comment lines (atomically).

    Coordinates to 0.1 mm and evidence to 3 decimals: :func:`occtool.io.csv.write_csv`
    with ``decimals=(4, 3)``.
    """
    from occtool.io.csv import write_csv

    write_csv(features, path, comments=comments, decimals=(4, 3))
