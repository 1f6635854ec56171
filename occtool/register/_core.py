"""Registration's parts: its settings and report, SE(2)/SE(3) helpers, a scan's points and
one alignment call of the chosen library (small_gicp or KISS-ICP)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError, MissingDependencyError
from occtool.features import Features, Pose

FloatArray = NDArray[np.float64]

#: Heights (metres) a planar scan is repeated at, so GICP sees walls, not lines.
PLANAR_EXTRUSION = (-0.1, 0.0, 0.1)
#: More than this share of the scans refused is an error, not a map.
MAX_REFUSED_SHARE = 0.5
#: A scan's points spread over less than this height (metres) make it planar.
PLANAR_SPREAD = 0.02


@dataclass
class RegistrationSettings:
    """How scans are registered and loops closed (every distance in metres).

    ``submap_scans`` scans (each at least ``submap_step`` metres or ``submap_turn`` radians
    from the one before it) form the local map a scan is registered against;
    ``downsample`` is the voxel size the scans and the map are thinned to; a result with
    fewer than ``min_inliers`` of the scan's points within ``max_correspondence`` of the map
    is refused and the seed kept. Loops: every ``loop_every`` metres of travel a scan is
    registered against the scans near it that lie more than ``loop_gap`` metres of travel
    back, within ``loop_radius`` of it by the current estimate (the nearest such scan and
    its ``loop_neighbours`` on either side; the query is the scan with the
    ``loop_source_scans`` before it), first with correspondences within ``loop_search``,
    then ``loop_match``; a result with at least ``loop_inliers`` of its points within
    ``loop_match / 2`` joins the graph, for ``loop_rounds`` rounds of search and solve.
    The graph weighs steps by ``odometry_sigma`` and loops by ``loop_sigma`` (metres,
    radians) and drops loops left more than ``loop_chi`` standard deviations off.
    A scan whose result brings fewer than ``retry_below`` of its points within
    ``retry_radius`` of the map (a seed too far off: an odometry jump) is registered again
    from other seeds (the previous step repeated, no motion, the odometry seed turned by each
    of ``retry_turns`` radians), each first with correspondences within ``retry_search``, and
    the result that brings most points within ``retry_radius`` kept if it brings
    ``retry_margin`` more of them than the first. A step whose result still fits poorly (or
    was refused) is ``weak_step_scale`` times less certain in the pose graph, so loops can
    overrule a jump it kept. ``step_information``: the graph weighs each step by GICP's own
    information (its Hessian), scaled so that the median step keeps ``odometry_sigma``;
    ``loop_information`` the loops by ``loop_sigma`` plus their registration's own
    uncertainty (its Hessian turned into a covariance by the factor that gives the median
    step ``odometry_sigma``): a loop matched along a corridor is loose along it, a loop
    that pins the place down keeps ``loop_sigma``. Before each solve,
    loops whose ends lie within ``loop_pair_travel`` metres of travel of each other are
    checked against each other through the sequential steps between them, and a loop that
    disagrees with more of its neighbours than agree is dropped (0 turns the check off).
    ``backend``: ``"small_gicp"`` (the default, the ``register`` extra) or ``"kiss_icp"``
    (KISS-ICP's point-to-point ICP, kept for the comparison in docs/register.md).
    """

    downsample: float = 0.05
    max_correspondence: float = 0.5
    submap_scans: int = 20
    submap_step: float = 0.05
    submap_turn: float = 0.05
    min_inliers: float = 0.3
    max_iterations: int = 30
    loop_closure: bool = True
    loop_every: float = 1.0
    loop_gap: float = 10.0
    loop_radius: float = 3.0
    loop_inliers: float = 0.6
    loop_search: float = 1.5
    loop_source_scans: int = 2
    loop_match: float = 0.2
    loop_neighbours: int = 5
    loop_rounds: int = 3
    odometry_sigma: tuple[float, float] = (0.02, 0.01)
    loop_sigma: tuple[float, float] = (0.05, 0.02)
    backend: str = "small_gicp"
    loop_chi: float = 5.0
    retry_below: float = 0.6
    retry_radius: float = 0.1
    retry_search: float = 1.5
    retry_turns: tuple[float, ...] = (-0.35, -0.17, 0.17, 0.35)
    retry_margin: float = 0.1
    weak_step_scale: float = 10.0
    step_information: bool = True
    loop_information: bool = True
    loop_pair_travel: float = 5.0


@dataclass
class RegistrationReport:
    """What :func:`register_log` did: counts, times and the registered pose of every scan."""

    scans: int
    seeded_by: str
    backend: str
    refused: int = 0
    loop_closures: int = 0
    loop_candidates: int = 0
    seconds: dict[str, float] = field(default_factory=dict)
    poses: list[Pose] = field(default_factory=list)
    stamps: list[float | None] = field(default_factory=list)
    odometry: list[Pose | None] = field(default_factory=list)
    loops: list[tuple[int, int, Pose]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def describe(self) -> str:
        loops = f", {self.loop_closures} loop closures of {self.loop_candidates} tried" if self.loop_candidates else ""
        return (f"{self.scans} scans registered with {self.backend} ({self.seeded_by}), {self.refused} refused "
                f"(seed kept){loops}, {sum(self.seconds.values()):.1f} s of CPU")

    def to_dict(self) -> dict[str, Any]:
        return {"scans": self.scans, "seeded_by": self.seeded_by, "backend": self.backend, "refused": self.refused,
                "loop_closures": self.loop_closures, "loop_candidates": self.loop_candidates,
                "seconds": {k: round(v, 3) for k, v in self.seconds.items()}}


# ---------------------------------------------------------------------- SE(2) / SE(3) helpers
def _matrix(pose: Pose) -> FloatArray:
    out = np.eye(4)
    out[:3, :3] = pose.rotation
    out[:3, 3] = pose.translation
    return out


def _pose(matrix: FloatArray, planar: bool) -> Pose:
    yaw = math.atan2(matrix[1, 0], matrix[0, 0])
    return Pose(float(matrix[0, 3]), float(matrix[1, 3]), 0.0 if planar else float(matrix[2, 3]), yaw)


def relative(a: Pose, b: Pose) -> Pose:
    """``b`` in the frame of ``a`` (``a^-1 b``)."""
    c, s = math.cos(a.yaw), math.sin(a.yaw)
    dx, dy = b.x - a.x, b.y - a.y
    return Pose(c * dx + s * dy, -s * dx + c * dy, b.z - a.z, _wrap(b.yaw - a.yaw))


def compose(a: Pose, b: Pose) -> Pose:
    """``a b``: the pose ``b`` (given in ``a``'s frame) in the world."""
    c, s = math.cos(a.yaw), math.sin(a.yaw)
    return Pose(a.x + c * b.x - s * b.y, a.y + s * b.x + c * b.y, a.z + b.z, _wrap(a.yaw + b.yaw))


def _wrap(angle: float) -> float:
    return float((angle + math.pi) % (2.0 * math.pi) - math.pi)


# ---------------------------------------------------------------------- the scans' points
def scan_points(features: Features, max_range: float | None = None) -> FloatArray:
    """The returns of a scan for registration: evidence > 0 (free rays are not surfaces),
    within ``max_range`` if given."""
    keep = features.evidence > 0.0
    if max_range is not None:
        keep &= features.range <= max_range
    return np.ascontiguousarray(features.points[keep], dtype=np.float64)


def _extruded(points: FloatArray) -> FloatArray:
    flat = np.column_stack([points[:, 0], points[:, 1], np.zeros(len(points))])
    return np.concatenate([flat + np.array([0.0, 0.0, z]) for z in PLANAR_EXTRUSION])


class _Aligner:
    """One registration call of the chosen library: source points onto target points."""

    #: The last small_gicp result's 6x6 information (rotation x, y, z, translation x, y, z,
    #: in the source's frame), ``None`` for kiss_icp.
    information: FloatArray | None = None

    def __init__(self, settings: RegistrationSettings) -> None:
        self.settings = settings
        if settings.backend == "small_gicp":
            try:
                import small_gicp
            except ImportError:
                raise MissingDependencyError("small_gicp", "register", "registering scans") from None
            self._lib: Any = small_gicp
        elif settings.backend == "kiss_icp":
            try:
                from kiss_icp.pybind import kiss_icp_pybind
            except ImportError:
                # Not part of the register extra: kept for the comparison in docs/register.md.
                raise InputError("the kiss_icp registration backend needs kiss-icp: pip install kiss-icp") from None
            self._lib = kiss_icp_pybind
            self._registration = kiss_icp_pybind._Registration(
                max_num_iterations=settings.max_iterations, convergence_criterion=1e-4, max_num_threads=1)
        else:
            raise InputError(f"registration backend must be small_gicp or kiss_icp, got {settings.backend!r}")

    def align(self, target: FloatArray, source: FloatArray, guess: FloatArray,
              max_correspondence: float | None = None) -> FloatArray:
        """``T_target_source``, from ``guess``."""
        s = self.settings
        reach = max_correspondence or s.max_correspondence
        lib = self._lib
        if self.settings.backend == "small_gicp":
            tgt, tgt_tree = lib.preprocess_points(target, downsampling_resolution=s.downsample, num_neighbors=10)
            src, _ = lib.preprocess_points(source, downsampling_resolution=s.downsample, num_neighbors=10)
            result = lib.align(tgt, src, tgt_tree, init_T_target_source=guess, registration_type="GICP",
                               max_correspondence_distance=reach, max_iterations=s.max_iterations)
            self.information = np.asarray(result.H)
            return np.asarray(result.T_target_source)
        self.information = None
        grid = lib._VoxelHashMap(voxel_size=s.downsample, max_distance=1e6, max_points_per_voxel=20)
        grid._add_points(lib._Vector3dVector(target))
        return np.asarray(self._registration._align_points_to_map(
            points=lib._Vector3dVector(_voxel_down(source, s.downsample)), voxel_map=grid, initial_guess=guess,
            max_correspondance_distance=reach, kernel=reach / 3.0))


def matched_share(target: FloatArray, source: FloatArray, matrix: FloatArray, radius: float) -> float:
    """The share of ``source`` points that ``matrix`` brings within ``radius`` of a ``target`` point."""
    # scipy's k-d tree, not occtool.neighbours' cell grid: the same answers, but a planar scan
    # is registered as a thin wall repeated at three heights, where the grid's 27-cell
    # blocks made the CCNY log's registration 35 times slower (1.8 s -> 53 s, measured).
    from scipy.spatial import cKDTree

    if not len(source) or not len(target) or not radius > 0:
        return 0.0
    if math.isinf(radius):
        return 1.0
    moved = source @ matrix[:3, :3].T + matrix[:3, 3]
    distance, _ = cKDTree(target).query(moved, distance_upper_bound=radius)
    return float(np.isfinite(distance).mean())


def planar_information(h: FloatArray | None, turn: float) -> FloatArray | None:
    """The x, y, yaw block of small_gicp's 6x6 information ``h`` (given in the source's
    frame) turned by ``turn`` radians into the frame an edge's residual is written in (the
    edge's first pose), or ``None`` when there is none or it is not finite."""
    if h is None or not np.isfinite(h).all():
        return None
    sub = h[np.ix_([3, 4, 2], [3, 4, 2])]
    g = np.eye(3)
    g[:2, :2] = [[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]]
    return g @ sub @ g.T


def information_scale(blocks: list[FloatArray | None], sigma: tuple[float, float]) -> float | None:
    """The factor that turns GICP's Hessians into information: the one that gives the
    median of ``blocks`` the translation information of ``sigma`` (metres, radians);
    ``None`` without any block."""
    scales = [0.5 * (b[0, 0] + b[1, 1]) for b in blocks if b is not None]
    if not scales:
        return None
    return (1 / sigma[0] ** 2) / float(np.median(scales))


def information_roots(blocks: list[FloatArray | None], sigma: tuple[float, float]) -> FloatArray:
    """Square roots (upper Cholesky factors) of each edge's information, ``(len(blocks), 3, 3)``:
    the blocks scaled so that the median one has the translation information of ``sigma``
    (metres, radians), a block missing (or not positive definite) the plain sigmas three
    times wider."""
    st, sr = sigma
    plain = np.diag([1 / st, 1 / st, 1 / sr])
    out = np.repeat(plain[None] / 3.0, len(blocks), axis=0)
    factor = information_scale(blocks, sigma)
    if factor is None:
        return out
    floor = np.diag([1e-6 / st**2, 1e-6 / st**2, 1e-6 / sr**2])
    for n, block in enumerate(blocks):
        if block is None:
            continue
        try:
            out[n] = np.linalg.cholesky(factor * 0.5 * (block + block.T) + floor).T
        except np.linalg.LinAlgError:
            pass
    return out


def _voxel_down(points: FloatArray, voxel: float) -> FloatArray:
    keys = np.floor(points / voxel).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return points[np.sort(first)]



def _in_world(points: FloatArray, pose: Pose) -> FloatArray:
    matrix = _matrix(pose)
    return points @ matrix[:3, :3].T + matrix[:3, 3]
