"""Range features: 3D points around the robot with an evidence value each.

A :class:`Features` set is what every reader produces and what the sensor model
consumes. Points are in the robot frame centred at the sensor (REP-103: x forward,
y left, z up, metres). A :class:`RangeLog` groups the features of a recording by
robot :class:`Position`, each with its pose in the world frame when the log has one.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.limits import MAX_COORDINATE

FloatArray = NDArray[np.float64]


def polar(points: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The paper's robot-centred coordinates ``(alpha, h, r)`` of ``(N, 3)`` points.

    ``alpha = atan2(y, x)`` in (-pi, pi], ``h = z`` and ``r = |p|``.

    Examples
    --------
    >>> alpha, h, r = polar([[0.0, 3.0, -4.0]])
    >>> float(alpha[0]), float(h[0]), float(r[0])
    (1.5707963267948966, -4.0, 5.0)
    """
    xyz = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return (
        np.arctan2(xyz[:, 1], xyz[:, 0]),
        xyz[:, 2].copy(),
        np.sqrt(np.einsum("ij,ij->i", xyz, xyz)),
    )


def wrap_angle(alpha: ArrayLike) -> FloatArray:
    """Angles wrapped into [-pi, pi), radians.

    Examples
    --------
    >>> wrap_angle([3.5 * np.pi, -np.pi, np.pi]) / np.pi
    array([-0.5, -1. , -1. ])
    """
    shifted = np.asarray(alpha) + np.pi
    if shifted.ndim == 0:
        return np.mod(shifted, 2.0 * np.pi) - np.pi
    # np.mod gives a value in [0, 2 pi) back unchanged (-0.0 as 0.0, the same once pi is
    # taken off): only the others take it, at a fraction of the cost for a turned pan angle.
    wrapped = shifted - np.pi
    outside = (shifted < 0.0) | ~(shifted < 2.0 * np.pi)
    if outside.any():
        wrapped[outside] = np.mod(shifted[outside], 2.0 * np.pi) - np.pi
    return wrapped


def _pan_angle(points: FloatArray) -> FloatArray:
    """``atan2(y, x)`` of ``(N, 3)`` points: one formula for Features and FeatureGeometry."""
    return np.arctan2(points[:, 1], points[:, 0])


def _distance(points: FloatArray) -> FloatArray:
    """``|p|`` of ``(N, 3)`` points (the same bits wherever a fit or a map asks)."""
    return np.sqrt(np.einsum("ij,ij->i", points, points))


@dataclass(frozen=True, eq=False)
class Features:
    """Range features registered from one robot position.

    Parameters
    ----------
    points
        ``(N, 3)`` array of x, y, z in metres, sensor-centred robot frame.
    evidence
        ``(N,)`` array of evidence values ``m`` in [0, 1].

    Raises
    ------
    InputError
        If the shapes disagree, a value is not finite, a coordinate exceeds
        :data:`MAX_COORDINATE` metres, an evidence value lies outside [0, 1] or a point
        lies at the sensor origin (it has no direction).
    """

    points: FloatArray
    evidence: FloatArray

    def __post_init__(self) -> None:
        points = np.ascontiguousarray(self.points, dtype=np.float64)
        evidence = np.ascontiguousarray(self.evidence, dtype=np.float64).reshape(-1)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"points must have shape (N, 3), got {points.shape}")
        if evidence.shape[0] != points.shape[0]:
            raise InputError(
                f"{points.shape[0]} points but {evidence.shape[0]} evidence values"
            )
        bad = ~np.isfinite(points).all(axis=1) | ~np.isfinite(evidence)
        if bad.any():
            raise InputError(f"feature {int(np.argmax(bad))} has a value that is NaN or infinite")
        far = ~(np.abs(points) <= MAX_COORDINATE).all(axis=1)
        if far.any():
            i = int(np.argmax(far))
            raise InputError(
                f"feature {i} lies at {tuple(float(v) for v in points[i])}, farther than {MAX_COORDINATE:g} m "
                "from the sensor: not range data (wrong units or columns?)"
            )
        outside = (evidence < 0.0) | (evidence > 1.0)
        if outside.any():
            i = int(np.argmax(outside))
            raise InputError(f"feature {i} has evidence {evidence[i]!r} outside [0, 1]")
        at_origin = ~(np.abs(points) > 0.0).any(axis=1)
        if at_origin.any():
            raise InputError(f"feature {int(np.argmax(at_origin))} lies at the sensor origin (0, 0, 0)")
        points.setflags(write=False)
        evidence.setflags(write=False)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "evidence", evidence)

    @classmethod
    def from_xyz(cls, x: ArrayLike, y: ArrayLike, z: ArrayLike, evidence: ArrayLike | float) -> Features:
        """Build a set from coordinate arrays and an evidence array or constant."""
        points = np.column_stack([np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)])
        m = np.broadcast_to(np.asarray(evidence, dtype=np.float64), (points.shape[0],))
        return cls(points, m.copy())

    @classmethod
    def concatenate(cls, parts: list[Features]) -> Features:
        """Join several sets into one."""
        if not parts:
            return cls(np.empty((0, 3)), np.empty(0))
        return cls(
            np.concatenate([p.points for p in parts]), np.concatenate([p.evidence for p in parts])
        )

    def __len__(self) -> int:
        return int(self.points.shape[0])

    @property
    def alpha(self) -> FloatArray:
        """Pan angle ``atan2(y, x)`` in radians, in (-pi, pi]."""
        return _pan_angle(self.points)

    @property
    def height(self) -> FloatArray:
        """Height ``z`` relative to the sensor, metres."""
        return self.points[:, 2].copy()

    @property
    def range(self) -> FloatArray:
        """Distance ``|p|`` from the sensor, metres."""
        return _distance(self.points)

    def polar(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return ``(alpha, h, r)``, the paper's robot-centred coordinates (:func:`polar`)."""
        return polar(self.points)

    def select(self, mask: ArrayLike) -> Features:
        """The features where ``mask`` is true (or at the given indices)."""
        index = np.asarray(mask)
        points, evidence = self.points[index], self.evidence[index]
        if points.ndim != 2 or evidence.shape != points.shape[:1]:
            return Features(points, evidence)  # not a selection of rows: the checks say why
        # Rows of a checked set need no checking again (a million features: 0.1 s).
        selected = object.__new__(Features)
        points.setflags(write=False)
        evidence.setflags(write=False)
        object.__setattr__(selected, "points", points)
        object.__setattr__(selected, "evidence", evidence)
        return selected

    def transformed(self, rotation: ArrayLike, translation: ArrayLike = (0.0, 0.0, 0.0)) -> Features:
        """Features moved by ``p' = R p + t`` (rotation a 3x3 matrix)."""
        R = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
        t = np.asarray(translation, dtype=np.float64).reshape(3)
        return Features(self.points @ R.T + t, self.evidence)

    def rotated(self, yaw: float) -> Features:
        """Features rotated by ``yaw`` radians about z (counter-clockwise seen from above)."""
        return self.transformed(Pose(yaw=yaw).rotation)


class FeatureGeometry:
    """What several steps of a fit read of every feature, each computed once on first use:
    the polar coordinates (:func:`polar`) and the horizontal distance ``hypot(x, y)``.

    The fit's screen, return guard, samples and range profile each computed these
    themselves (a million features: four pan angles and seven horizontal distances,
    0.3 s). The values are those the features' own methods give, bit for bit.
    """

    def __init__(self, points: FloatArray) -> None:
        self.points = points

    @classmethod
    def of(cls, features: Features) -> FeatureGeometry:
        return cls(features.points)

    @cached_property
    def alpha(self) -> FloatArray:
        """Pan angle ``atan2(y, x)``, as :attr:`Features.alpha`."""
        return _pan_angle(self.points)

    @cached_property
    def h(self) -> FloatArray:
        """Height ``z`` (a copy), as :attr:`Features.height`."""
        return self.points[:, 2].copy()

    @cached_property
    def r(self) -> FloatArray:
        """Distance ``|p|`` from the sensor, as :attr:`Features.range`."""
        return _distance(self.points)

    @cached_property
    def horizontal(self) -> FloatArray:
        """Horizontal distance ``hypot(x, y)``."""
        return np.hypot(self.points[:, 0], self.points[:, 1])

    def polar(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(alpha, h, r)``, as :meth:`Features.polar`."""
        return self.alpha, self.h, self.r

    def turned(self, origin: float) -> FloatArray:
        """Pan angles measured from ``origin``, ``wrap_angle(alpha - origin)`` (the last
        origin's kept: the samples and the range profile both read them)."""
        cached = self.__dict__.get("_turned")
        if cached is None or cached[0] != origin:
            cached = self.__dict__["_turned"] = (origin, wrap_angle(self.alpha - origin))
        return cached[1]

    def select(self, index: ArrayLike, points: FloatArray) -> FeatureGeometry:
        """The geometry of the features ``points`` selected by ``index`` from these: the
        values computed already are selected, not computed again."""
        selected = FeatureGeometry(points)
        for name in ("alpha", "h", "r", "horizontal"):
            if name in self.__dict__:
                selected.__dict__[name] = self.__dict__[name][index]
        return selected


@dataclass(frozen=True)
class Pose:
    """A robot pose in the world (``map``/``odom``) frame: planar position, height and yaw."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0

    @property
    def rotation(self) -> FloatArray:
        """The 3x3 rotation matrix about z."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    @property
    def translation(self) -> FloatArray:
        return np.array([self.x, self.y, self.z])

    def to_world(self, xy: ArrayLike) -> FloatArray:
        """Move ``(K, 2)`` robot-frame x, y coordinates into the world frame."""
        pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.column_stack([self.x + c * pts[:, 0] - s * pts[:, 1], self.y + s * pts[:, 0] + c * pts[:, 1]])

    def to_dict(self) -> dict[str, float]:
        return {"x": float(self.x), "y": float(self.y), "z": float(self.z), "yaw": float(self.yaw)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Pose:
        return cls(**{k: float(data[k]) for k in ("x", "y", "z", "yaw") if k in data})


@dataclass(frozen=True, eq=False)
class Position:
    """The features registered at one robot position, with the position's world pose.

    ``pose`` is ``None`` when the log carries no poses. ``scan_origins`` ``(K, 3)`` and
    ``scan_sizes`` ``(K,)``, when the position gathers scans taken at different poses
    (:func:`occtool.io.positions.group_scans`): each scan's sensor in the position's frame and
    its count of features, in the order of ``features`` (a 3D map starts each ray at its own
    scan's sensor and holds scans out one by one); ``None``: every feature's sensor is the
    position's.
    """

    index: int
    features: Features
    pose: Pose | None = None
    stamp: float | None = None
    source: str = ""
    scan_origins: FloatArray | None = None
    scan_sizes: NDArray[np.int64] | None = None


def scans_apart(position: Any) -> NDArray[np.int64] | None:
    """How many features each scan of ``position`` holds, when it keeps its scans apart
    (:attr:`Position.scan_origins` and :attr:`Position.scan_sizes`, which account for every
    feature); ``None`` when every feature's sensor is the position's (or it is no
    :class:`Position`: a fitted model's position keeps no scans)."""
    origins, sizes = getattr(position, "scan_origins", None), getattr(position, "scan_sizes", None)
    if origins is None or sizes is None or int(np.sum(sizes)) != position.features.points.shape[0]:
        return None
    return np.asarray(sizes, dtype=np.int64)


class Note(str):
    """A note a reader leaves for the user: its text, and the logging level it is reported at.

    A reader's ``notes`` are plain strings for routine facts (the constant evidence used, the
    features kept after a budget, the no-return readings found, where the poses came from):
    they are logged at INFO, shown with ``-v`` and always by ``occtool info``. A note the user
    should act on (lines skipped as unparsable, records of unknown type, invalid rows dropped,
    poses that could not be used, data that disagrees with the options) is a
    ``Note.warn(text)``: logged at WARNING, shown by default. :func:`log_notes` is the one
    place that tells them apart. A ``Note`` is a ``str`` (it compares, formats and pickles
    as its text), so code that only reads notes needs no change.

    Examples
    --------
    >>> note_level("constant evidence 0.9 for laser readings (evidence=)") == logging.INFO
    True
    >>> note = Note.warn("skipped 2 laser line(s) that do not parse")
    >>> note, note_level(note) == logging.WARNING
    ('skipped 2 laser line(s) that do not parse', True)
    """

    level: int

    def __new__(cls, text: str, level: int = logging.INFO) -> Note:
        note = super().__new__(cls, text)
        note.level = level
        return note

    def __reduce__(self) -> tuple[Any, ...]:  # a worker process's notes keep their level
        return (Note, (str(self), self.level))

    @classmethod
    def warn(cls, text: str) -> Note:
        """A note the user should act on (logged at WARNING)."""
        return cls(text, logging.WARNING)


def note_level(note: str) -> int:
    """The logging level of a note: a :class:`Note`'s own, INFO for a plain string."""
    return getattr(note, "level", logging.INFO)


def log_notes(logger: logging.Logger, where: str, notes: Iterable[str]) -> None:
    """Log each note as ``where: note`` at its level (:class:`Note`): routine facts at INFO,
    what the user should act on at WARNING."""
    for note in notes:
        logger.log(note_level(note), "%s: %s", where, note)


@dataclass(eq=False)
class RangeLog:
    """What a reader returns: the positions of a recording and notes for the user.

    ``notes`` are routine facts (plain strings, logged at INFO) and, as :class:`Note` s at
    WARNING (``Note.warn``), what the user should act on; :func:`log_notes` logs them.
    """

    positions: list[Position]
    source: str = ""
    notes: list[str] = field(default_factory=list)
    #: What the poses are, where the reader knows: ``"odometry"`` (wheel odometry, drifting),
    #: ``"tf"``, ``"log"`` (the log's own pose fields, e.g. CARMEN's), ``"registered"``
    #: (:mod:`occtool.register`); ``None`` when unknown or the log has none.
    pose_kind: str | None = None
    #: ``(4, 4)`` rigid transform from the frame of the file's own poses to the frame of
    #: :attr:`positions`' poses, where a reader moved them (a depth folder levels its world
    #: on the floor it finds); ``None``: the same frame. A 3D world map stores it, so that it
    #: answers in the frame of the user's poses.
    to_log_frame: Any = None

    @property
    def has_poses(self) -> bool:
        return any(p.pose is not None for p in self.positions)

    def single(self, position: int | None = None) -> Position:
        """One position: the one given, or the only one; an error if the choice is ambiguous."""
        if not self.positions:
            raise InputError(f"{self.source or 'the log'} holds no range data")
        if position is None:
            if len(self.positions) > 1:
                raise InputError(
                    f"{self.source or 'the log'} holds {len(self.positions)} robot positions: "
                    "pick one with position=N or write a model set to a folder"
                )
            return self.positions[0]
        if not 0 <= position < len(self.positions):
            raise InputError(f"position {position} is out of range (the log has {len(self.positions)})")
        return self.positions[position]
