"""What an extraction returns: :class:`NavigationMap`, its :class:`Slice` s, and the warning."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

from occtool.errors import InputError
from occtool.features import Pose

FloatArray = NDArray[np.float64]


class NavigationWarning(UserWarning):
    """The navigation map was extracted but is degenerate (robot in collision, ...)."""


@dataclass(frozen=True, eq=False)
class Slice:
    """The free area at one sensor-frame height, before the shrink by the robot radius.

    Parameters
    ----------
    height
        Sensor-frame height of the cut, metres (negative below the sensor).
    polygon
        The star-shaped polygon of horizontal free distances swept over the pan angle,
        robot-frame x, y metres, out to the read range (max range plus robot radius).
    """

    height: float
    polygon: Polygon


@dataclass(frozen=True, eq=False)
class NavigationMap:
    """A local navigation map and the parameters it was extracted with.

    Parameters
    ----------
    polygon
        Where the robot can drive in a straight line with its whole body clear: a
        shapely Polygon, x/y metres in ``frame_id``, outer ring counter-clockwise
        (RFC 7946). Empty when the robot is in collision where it stands.
    slices
        The free area at each requested height (:class:`Slice`), unshrunk.
    obstacle_points
        ``(K, 2)`` points on the polygon's boundary strictly inside the max-range circle,
        at evenly spaced angles in each obstacle sector (negative reinforcement).
    exploration_points
        ``(K, 2)`` points on the max-range circle where the polygon reaches it, at evenly
        spaced angles in each such sector (positive reinforcement).
    threshold
        The occupancy level asked for.
    effective_threshold
        The level the model was actually cut at: ``threshold`` minus the margin that
        makes the map hold between slices and rays (equal to ``threshold`` without
        slope bounds).
    heights
        The requested sensor-frame heights, metres, ascending.
    robot_radius, max_range
        Metres.
    n_angles
        Pan angles swept (evenly spaced, the first straight ahead).
    point_spacing
        Arc length on the max-range circle between neighbouring points, metres.
    sensor_height, body_height, ground_clearance
        The robot's geometry above the floor, metres.
    slice_heights
        Every height the model was cut at: the requested ones and any added to hold the
        map between them.
    margin
        ``threshold - effective_threshold``.
    straight_line
        Whether the polygon was cut to what the robot reaches in a straight line.
    return_snap
        How far (m) in front of the guarded returns a ray's crossing was carried on to
        them (0: not; :func:`~occtool.navigation.navigation_map`'s ``return_snap``).
    frame_id
        ``"base_link"`` for the robot frame, else the world frame the map was moved to.
    pose
        The robot's world pose when the map is in a world frame.
    extra
        Further properties a GeoJSON file carried, kept for writing it back.
    """

    polygon: Polygon
    slices: list[Slice]
    obstacle_points: FloatArray
    exploration_points: FloatArray
    threshold: float
    effective_threshold: float
    heights: tuple[float, ...]
    robot_radius: float
    max_range: float
    n_angles: int
    point_spacing: float
    sensor_height: float = 1.0
    body_height: float = 1.0
    ground_clearance: float = 0.05
    slice_heights: tuple[float, ...] = ()
    margin: float = 0.0
    straight_line: bool = True
    return_snap: float = 0.0
    frame_id: str = "base_link"
    pose: Pose | None = None
    extra: Mapping[str, object] = field(default_factory=dict)

    @property
    def is_empty(self) -> bool:
        """True when there is nowhere to go (the robot is in collision)."""
        return bool(self.polygon.is_empty)

    def in_world(self, pose: Pose, frame_id: str = "map") -> NavigationMap:
        """The same map moved from the robot frame into a world frame by the robot's pose.

        Parameters
        ----------
        pose
            The robot's pose in the world frame (x, y, yaw are used).
        frame_id
            Name of the world frame (REP-105: ``map`` or ``odom``).

        Returns
        -------
        NavigationMap
            Polygon, slices and points rotated by ``pose.yaw`` and moved by ``(x, y)``.
        """
        if self.frame_id != "base_link":
            raise InputError(f"the navigation map is already in the {self.frame_id!r} frame")

        def move(geometry: BaseGeometry) -> BaseGeometry:
            return shapely.transform(geometry, pose.to_world)

        return replace(
            self,
            polygon=move(self.polygon),
            slices=[Slice(s.height, move(s.polygon)) for s in self.slices],
            obstacle_points=pose.to_world(self.obstacle_points),
            exploration_points=pose.to_world(self.exploration_points),
            frame_id=frame_id,
            pose=pose,
        )
