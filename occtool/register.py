"""Poses for a log that has none, or only odometry: scan registration and loop closure.

:func:`register_log` takes a log read scan by scan (``read_log(path, group_by="message")``),
registers each scan against a sliding local map of the scans registered before it
(scan-to-map, seeded by the log's odometry where it has some, else by a constant-velocity
guess), closes loops where the path revisits a place (a pose graph over every scan,
solved with :func:`scipy.optimize.least_squares`), and returns the log grouped into
positions on the registered poses, with a :class:`RegistrationReport`.

The registration itself is `small_gicp <https://github.com/koide3/small_gicp>`_'s GICP
(the ``register`` extra); docs/register.md says why it was chosen over KISS-ICP's
point-to-point ICP. A planar scan (a 2D laser) is registered as a thin vertical wall,
its points repeated at three heights, and the result is kept in SE(2); a 3D point
cloud is registered in 3D and kept as x, y, z and yaw (:class:`~occtool.features.Pose`
has no roll or pitch).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError, MissingDependencyError
from occtool.features import Features, Pose, Position, RangeLog

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
            return np.asarray(result.T_target_source)
        grid = lib._VoxelHashMap(voxel_size=s.downsample, max_distance=1e6, max_points_per_voxel=20)
        grid._add_points(lib._Vector3dVector(target))
        return np.asarray(self._registration._align_points_to_map(
            points=lib._Vector3dVector(_voxel_down(source, s.downsample)), voxel_map=grid, initial_guess=guess,
            max_correspondance_distance=reach, kernel=reach / 3.0))


def matched_share(target: FloatArray, source: FloatArray, matrix: FloatArray, radius: float) -> float:
    """The share of ``source`` points that ``matrix`` brings within ``radius`` of a ``target`` point."""
    from scipy.spatial import cKDTree

    if not len(source) or not len(target):
        return 0.0
    moved = source @ matrix[:3, :3].T + matrix[:3, 3]
    distance, _ = cKDTree(target).query(moved, distance_upper_bound=radius)
    return float(np.isfinite(distance).mean())


def _voxel_down(points: FloatArray, voxel: float) -> FloatArray:
    keys = np.floor(points / voxel).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return points[np.sort(first)]


# ---------------------------------------------------------------------- registration
def register_scans(scans: Sequence[FloatArray], odometry: Sequence[Pose | None] | None = None, *,
                   settings: RegistrationSettings | None = None,
                   report: RegistrationReport | None = None) -> list[Pose]:
    """The world pose of every scan (the first at its odometry pose, or the origin).

    Parameters
    ----------
    scans
        ``(N_k, 3)`` returns of each scan in its sensor-centred robot frame.
    odometry
        Each scan's odometry pose or ``None``; relative odometry between consecutive scans
        seeds each registration, else the previous step's motion does.
    """
    settings = settings or RegistrationSettings()
    count = len(scans)
    if count == 0:
        return []
    odometry = list(odometry) if odometry is not None else [None] * count
    if len(odometry) != count:
        raise InputError(f"{count} scans but {len(odometry)} odometry poses")
    planar = all(len(p) == 0 or float(np.ptp(p[:, 2])) <= PLANAR_SPREAD for p in scans)
    aligner = _Aligner(settings)
    started = time.process_time()
    prepared = [_extruded(p) if planar else p for p in scans]
    poses: list[Pose] = [odometry[0] if odometry[0] is not None else Pose()]
    submap: list[int] = [0]
    refused = 0
    for k in range(1, count):
        if odometry[k] is not None and odometry[k - 1] is not None:
            step = relative(odometry[k - 1], odometry[k])  # type: ignore[arg-type]
        elif k >= 2:
            step = relative(poses[k - 2], poses[k - 1])
        else:
            step = Pose()
        guess = compose(poses[k - 1], step)
        source = prepared[k]
        if len(scans[k]) < 10:
            poses.append(guess)
            refused += 1
            continue
        target = np.concatenate([_in_world(prepared[i], poses[i]) for i in submap])
        matrix = aligner.align(target, source, _matrix(guess))
        if matched_share(target, source, matrix, settings.max_correspondence) >= settings.min_inliers:
            poses.append(_pose(matrix, planar))
        else:
            poses.append(guess)
            refused += 1
        last = poses[submap[-1]]
        moved = relative(last, poses[k])
        if math.hypot(moved.x, moved.y) >= settings.submap_step or abs(moved.yaw) >= settings.submap_turn:
            submap.append(k)
            if len(submap) > settings.submap_scans:
                submap.pop(0)
    if report is not None:
        report.refused += refused
        report.seconds["registration"] = time.process_time() - started
    if settings.loop_closure and count > 2:
        poses = close_loops(prepared, poses, planar, aligner, settings, report)
    return poses


def _in_world(points: FloatArray, pose: Pose) -> FloatArray:
    matrix = _matrix(pose)
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def close_loops(prepared: Sequence[FloatArray], poses: list[Pose], planar: bool, aligner: _Aligner,
                settings: RegistrationSettings, report: RegistrationReport | None = None,
                step_weights: FloatArray | None = None) -> list[Pose]:
    """Re-align revisited places: loop edges found by registration, then the pose graph
    of the sequential steps and the loops solved by :func:`solve_graph` (least squares,
    the loops that disagree with the rest pruned). The graph is planar (x, y, yaw); a 3D
    scan keeps the height its sequential registration gave it."""
    started = time.process_time()
    count = len(poses)
    steps = [(k - 1, k, relative(poses[k - 1], poses[k])) for k in range(1, count)]
    loops: dict[tuple[int, int], Pose] = {}
    rejected: set[tuple[int, int]] = set()
    tried = 0
    current = list(poses)
    for _ in range(settings.loop_rounds):
        xy = np.array([[p.x, p.y] for p in current])
        travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        queries = []
        mark = 0.0
        for k in range(count):
            if travel[k] >= mark:
                queries.append(k)
                mark = travel[k] + settings.loop_every
        from scipy.spatial import cKDTree

        tree = cKDTree(xy)
        added = 0
        for j in queries:
            if len(prepared[j]) < 30:
                continue
            near = [i for i in tree.query_ball_point(xy[j], settings.loop_radius)
                    if travel[j] - travel[i] > settings.loop_gap]
            if not near:
                continue
            i = min(near, key=lambda n: float(np.hypot(*(xy[n] - xy[j]))))
            if any(abs(a - i) <= settings.loop_neighbours and b == j for a, b in (*loops, *rejected)):
                continue
            lo, hi = max(0, i - settings.loop_neighbours), min(count, i + settings.loop_neighbours + 1)
            neighbours = [n for n in range(lo, hi) if travel[j] - travel[n] > settings.loop_gap]
            target = np.concatenate([_in_world(prepared[n], current[n]) for n in neighbours])
            tried += 1
            # The query: scan j with the scans just before it, in j's frame (more of the place
            # than one scan shows, and still without the drift of a long stretch).
            own = current[j]
            source = np.concatenate([_in_world(prepared[n], relative(own, current[n]))
                                     for n in range(max(0, j - settings.loop_source_scans), j + 1)])
            matrix = aligner.align(target, source, _matrix(own), settings.loop_search)
            matrix = aligner.align(target, source, matrix, settings.loop_match)
            if matched_share(target, source, matrix, settings.loop_match / 2) < settings.loop_inliers:
                continue
            found = _pose(matrix, planar)
            loops[(i, j)] = relative(current[i], found)
            added += 1
        if not added:
            break
        current, kept = solve_graph(poses, steps, [(i, j, z) for (i, j), z in loops.items()], settings,
                                    step_weights)
        rejected.update((i, j) for (i, j) in loops if (i, j) not in {(a, b) for a, b, _ in kept})
        loops = {(a, b): z for a, b, z in kept}
    if report is not None:
        report.loop_closures = len(loops)
        report.loops = [(i, j, z) for (i, j), z in loops.items()]
        report.loop_candidates = tried
        report.seconds["loop_closure"] = time.process_time() - started
    return current


def optimise_graph(initial: list[Pose], steps: list[tuple[int, int, Pose]], loops: list[tuple[int, int, Pose]],
                   settings: RegistrationSettings, step_weights: FloatArray | None = None) -> list[Pose]:
    """The SE(2) pose graph (x, y, yaw per scan, the first held) solved by
    :func:`scipy.optimize.least_squares` with the analytic sparse Jacobian.

    Each edge's residual (its x, y in the first pose's frame, and yaw) is weighted by a
    3x3 square root of its information: ``step_weights`` ``(len(steps), 3, 3)`` for the
    steps if given, else ``diag(1/sigma, 1/sigma, 1/sigma_yaw)`` from ``settings``."""
    from scipy.optimize import least_squares
    from scipy.sparse import csr_matrix

    count = len(initial)
    edges = steps + loops
    m = len(edges)
    a = np.array([e[0] for e in edges])
    b = np.array([e[1] for e in edges])
    z = np.array([[e[2].x, e[2].y, e[2].yaw] for e in edges])
    weights = np.zeros((m, 3, 3))
    st, sr = settings.odometry_sigma
    lt, lr = settings.loop_sigma
    weights[:len(steps)] = np.diag([1 / st, 1 / st, 1 / sr]) if step_weights is None else step_weights
    weights[len(steps):] = np.diag([1 / lt, 1 / lt, 1 / lr])
    x0 = np.array([[p.x, p.y, p.yaw] for p in initial])
    anchor = x0[0].copy()

    def unpack(v: FloatArray) -> FloatArray:
        return np.vstack([anchor, v.reshape(-1, 3)])

    def fun(v: FloatArray) -> FloatArray:
        x = unpack(v)
        xi, xj = x[a], x[b]
        c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
        dx, dy = xj[:, 0] - xi[:, 0], xj[:, 1] - xi[:, 1]
        e = np.column_stack([c * dx + s * dy - z[:, 0], -s * dx + c * dy - z[:, 1],
                             (xj[:, 2] - xi[:, 2] - z[:, 2] + np.pi) % (2 * np.pi) - np.pi])
        return np.einsum("mij,mj->mi", weights, e).ravel()

    rows = (3 * np.arange(m)[:, None, None] + np.arange(3)[None, :, None]) * np.ones((1, 1, 3), dtype=np.int64)

    def jac(v: FloatArray) -> Any:
        x = unpack(v)
        xi, xj = x[a], x[b]
        c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
        dx, dy = xj[:, 0] - xi[:, 0], xj[:, 1] - xi[:, 1]
        zero, one = np.zeros(m), np.ones(m)
        ja = np.stack([np.stack([-c, -s, -s * dx + c * dy], axis=1),
                       np.stack([s, -c, -c * dx - s * dy], axis=1),
                       np.stack([zero, zero, -one], axis=1)], axis=1)
        jb = np.stack([np.stack([c, s, zero], axis=1), np.stack([-s, c, zero], axis=1),
                       np.stack([zero, zero, one], axis=1)], axis=1)
        parts_rows, parts_cols, parts_vals = [], [], []
        for node, block in ((a, weights @ ja), (b, weights @ jb)):
            free = node > 0
            cols = (node[:, None, None] - 1) * 3 + np.arange(3)[None, None, :] + np.zeros((1, 3, 1), dtype=np.int64)
            parts_rows.append(rows[free].ravel())
            parts_cols.append(cols[free].ravel())
            parts_vals.append(block[free].ravel())
        return csr_matrix((np.concatenate(parts_vals), (np.concatenate(parts_rows), np.concatenate(parts_cols))),
                          shape=(3 * m, 3 * (count - 1)))

    result = least_squares(fun, x0[1:].ravel(), jac=jac, method="trf", x_scale="jac", max_nfev=50,
                           tr_solver="lsmr")
    x = unpack(result.x)
    return [Pose(float(p[0]), float(p[1]), initial[k].z, _wrap(float(p[2]))) for k, p in enumerate(x)]


def _loop_residuals(poses: list[Pose], loops: list[tuple[int, int, Pose]],
                    settings: RegistrationSettings) -> FloatArray:
    """Each loop edge's residual on ``poses``, in standard deviations (the root of its chi-square)."""
    out = np.empty(len(loops))
    for n, (i, j, z) in enumerate(loops):
        found = relative(poses[i], poses[j])
        t = math.hypot(found.x - z.x, found.y - z.y) / settings.loop_sigma[0]
        r = abs(_wrap(found.yaw - z.yaw)) / settings.loop_sigma[1]
        out[n] = math.hypot(t, r)
    return out


def solve_graph(initial: list[Pose], steps: list[tuple[int, int, Pose]], loops: list[tuple[int, int, Pose]],
                settings: RegistrationSettings, step_weights: FloatArray | None = None
                ) -> tuple[list[Pose], list[tuple[int, int, Pose]]]:
    """:func:`optimise_graph` with the loops that disagree with the rest pruned: after each
    solve the loops whose residual exceeds ``settings.loop_chi`` standard deviations (and
    0.7 of the largest) are dropped and the graph solved again, until all agree. Returns
    the poses and the loops kept."""
    kept = list(loops)
    poses = optimise_graph(initial, steps, kept, settings, step_weights)
    for _ in range(50):
        if not kept:
            break
        chi = _loop_residuals(poses, kept, settings)
        worst = float(chi.max())
        if worst <= settings.loop_chi:
            break
        kept = [loop for loop, c in zip(kept, chi) if c <= max(settings.loop_chi, 0.7 * worst)]
        poses = optimise_graph(initial, steps, kept, settings, step_weights)
    return poses, kept


# ---------------------------------------------------------------------- whole logs
def register_log(log: RangeLog, *, settings: RegistrationSettings | None = None,
                 position_tolerance: Sequence[float] | None = None, use_odometry: bool = True,
                 max_range: float | None = None) -> tuple[RangeLog, RegistrationReport]:
    """Register the scans of ``log`` (one scan a position: ``read_log(..., group_by="message")``)
    and group them into positions on the registered poses.

    The log's poses, where it has them, seed the registration as odometry
    (``use_odometry=False`` ignores them). Returns the regrouped log (its notes say how
    its poses were made) and the report, whose ``poses`` hold every scan's registered pose.
    """
    from occtool.io.positions import DEFAULT_POSITION_TOLERANCE, Scan, build_log

    if not log.positions:
        raise InputError(f"{log.source or 'the log'} holds no range data")
    odometry = [p.pose for p in log.positions] if use_odometry else [None] * len(log.positions)
    seeded = "seeded by the log's poses" if any(o is not None for o in odometry) else "no odometry: constant velocity"
    settings = settings or RegistrationSettings()
    report = RegistrationReport(scans=len(log.positions), seeded_by=seeded, backend=settings.backend)
    points = [scan_points(p.features, max_range) for p in log.positions]
    poses = register_scans(points, odometry, settings=settings, report=report)
    if len(points) > 1 and report.refused > MAX_REFUSED_SHARE * (len(points) - 1):
        what = ("the log has no poses and its scans" if all(o is None for o in odometry)
                else "the log's scans")
        raise InputError(
            f"{log.source or 'the log'}: {what} could not be registered ({report.refused} of {len(points) - 1} "
            "refused: too few returns, or too little overlap from one scan to the next); "
            "map it without registration (--no-register, register=False)")
    report.poses = poses
    report.stamps = [p.stamp for p in log.positions]
    report.odometry = [p.pose for p in log.positions]
    scans = [Scan(p.features.points, p.features.evidence, pose, p.stamp, p.source)
             for p, pose in zip(log.positions, poses)]
    notes = [n for n in log.notes if not n.startswith("the log has no poses")]
    notes.append(f"poses registered: {report.describe()}")
    regrouped = build_log(scans, source=log.source, tolerance=position_tolerance or DEFAULT_POSITION_TOLERANCE,
                          notes=notes)
    regrouped.pose_kind = "registered"
    return regrouped, report


def pose_kind(log: RangeLog) -> str | None:
    """What a log's poses are: its reader's word (``log.pose_kind``), else from its notes
    (``"odometry"``, ``"tf"``), else ``"log"`` (its own pose fields), ``None`` without poses."""
    if not log.has_poses:
        return None
    if log.pose_kind:
        return log.pose_kind
    if any(n.startswith("poses from odometry") for n in log.notes):
        return "odometry"
    if any(n.startswith("poses from /tf") for n in log.notes):
        return "tf"
    return "log"


def needs_registration(log: RangeLog) -> bool:
    """Whether ``occtool map`` registers a log by default: it has no poses, or only odometry."""
    return pose_kind(log) in (None, "odometry")


def read_registered_log(path: str, read_options: dict[str, Any], register: bool | None = None, *,
                        settings: RegistrationSettings | None = None
                        ) -> tuple[RangeLog, RegistrationReport | None]:
    """Read a log for ``occtool map``: scan by scan, registered when ``register`` is true,
    or by default (``None``) when :func:`needs_registration`; grouped into positions as
    ``read_options`` ask either way. Returns the log and the report (``None`` when the
    log's own poses are kept)."""
    from occtool.io import read_log
    from occtool.io.positions import DEFAULT_POSITION_TOLERANCE, Scan, build_log

    options = dict(read_options)
    group_by = options.pop("group_by", "position") or "position"
    tolerance = options.get("position_tolerance") or DEFAULT_POSITION_TOLERANCE
    if register is False:
        return read_log(path, group_by=group_by, **options), None
    scans = read_log(path, group_by="message", **options)
    if register is None and not needs_registration(scans):
        regrouped = build_log([Scan(p.features.points, p.features.evidence, p.pose, p.stamp, p.source)
                               for p in scans.positions], source=scans.source, tolerance=tolerance,
                              group_by=group_by, notes=scans.notes)
        regrouped.pose_kind = scans.pose_kind
        return regrouped, None
    registered, report = register_log(scans, settings=settings, position_tolerance=tolerance)
    if group_by == "message":
        registered = positions_with_poses(scans, report.poses)
        registered.notes.append(f"poses registered: {report.describe()}")
        registered.pose_kind = "registered"
    return registered, report


def write_poses_csv(report: RegistrationReport, path: str | Any, *, overwrite: bool = True) -> None:
    """Every scan's registered pose as CSV: ``scan,stamp,x,y,z,yaw`` (the world ``map``
    frame, metres and radians; ``stamp`` in seconds, empty when the log has none)."""
    from occtool._files import atomic_write

    with atomic_write(path, "w", overwrite=overwrite) as handle:
        handle.write("scan,stamp,x,y,z,yaw\n")
        for k, (pose, stamp) in enumerate(zip(report.poses, report.stamps)):
            when = "" if stamp is None else f"{stamp:.6f}"
            handle.write(f"{k},{when},{pose.x:.6f},{pose.y:.6f},{pose.z:.6f},{pose.yaw:.6f}\n")


# ---------------------------------------------------------------------- tests and benchmarks
def degrade_poses(poses: Sequence[Pose], *, distance_share: float = 0.03, turn_per_metre: float = math.radians(1.5),
                  seed: int = 0) -> list[Pose]:
    """Odometry-like poses from true ones: each step's motion with a scale error and a
    heading error that grow with the distance driven.

    Per step of length ``d`` (metres) and turn ``dtheta``: the translation is scaled by
    ``1 + distance_share`` (a systematic wheel-radius error) plus noise of standard
    deviation ``distance_share * d`` on each axis; the heading gains a bias of
    ``turn_per_metre * d`` (a drift to one side) plus noise of ``turn_per_metre * d`` and
    1 % of ``dtheta``. The first pose is kept.
    """
    rng = np.random.default_rng(seed)
    out = [poses[0]]
    for k in range(1, len(poses)):
        step = relative(poses[k - 1], poses[k])
        d = math.hypot(step.x, step.y)
        noise = rng.normal(size=3)
        dx = step.x * (1.0 + distance_share) + distance_share * d * noise[0]
        dy = step.y * (1.0 + distance_share) + distance_share * d * noise[1]
        dyaw = step.yaw + turn_per_metre * d * (1.0 + noise[2]) + 0.01 * step.yaw * rng.normal()
        out.append(compose(out[-1], Pose(dx, dy, step.z, dyaw)))
    return out


def trajectory_error(estimate: Sequence[Pose], truth: Sequence[Pose], *, align: bool = True) -> float:
    """RMS of the position error (metres), after the rigid 2D motion that fits the
    estimate to the truth best (``align=True``, as the absolute trajectory error is
    usually given) or as it is."""
    e = np.array([[p.x, p.y] for p in estimate])
    t = np.array([[p.x, p.y] for p in truth])
    if align:
        e = _aligned(e, t)
    return float(np.sqrt(np.mean(np.sum((e - t) ** 2, axis=1))))


def _aligned(e: FloatArray, t: FloatArray) -> FloatArray:
    ce, ct = e.mean(axis=0), t.mean(axis=0)
    u, _, vt = np.linalg.svd((e - ce).T @ (t - ct))
    d = np.sign(np.linalg.det(u @ vt))
    rotation = (u @ np.diag([1.0, d]) @ vt).T
    return (e - ce) @ rotation.T + ct


def segment_errors(estimate: Sequence[Pose], truth: Sequence[Pose], length: float = 10.0) -> FloatArray:
    """The translation error (metres) of the relative motion over every stretch of
    ``length`` metres of travel (by the truth), one per starting scan."""
    t = np.array([[p.x, p.y] for p in truth])
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(t, axis=0).T))])
    errors = []
    for i in range(len(truth)):
        j = int(np.searchsorted(travel, travel[i] + length))
        if j >= len(truth):
            break
        true_step, step = relative(truth[i], truth[j]), relative(estimate[i], estimate[j])
        errors.append(math.hypot(true_step.x - step.x, true_step.y - step.y))
    return np.array(errors)


def positions_with_poses(log: RangeLog, poses: Sequence[Pose]) -> RangeLog:
    """``log`` (one scan a position) with its poses replaced by ``poses``."""
    if len(poses) != len(log.positions):
        raise InputError(f"{len(log.positions)} scans but {len(poses)} poses")
    return RangeLog([Position(p.index, p.features, pose, p.stamp, p.source) for p, pose in zip(log.positions, poses)],
                    source=log.source, notes=list(log.notes))


__all__ = ["RegistrationReport", "RegistrationSettings", "close_loops", "compose", "degrade_poses",
           "needs_registration", "optimise_graph", "pose_kind", "positions_with_poses", "read_registered_log",
           "register_log", "register_scans", "relative", "scan_points", "segment_errors", "solve_graph",
           "trajectory_error", "write_poses_csv"]
