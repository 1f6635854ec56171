"""Loop closure: loop edges found by registration, and the pose graph solved by least squares."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from occtool.features import Pose
from occtool.register._core import (
    FloatArray,
    RegistrationReport,
    RegistrationSettings,
    _Aligner,
    _in_world,
    _matrix,
    _pose,
    _wrap,
    matched_share,
    relative,
)


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
        # Not occtool.neighbours: its queries are nearest-k below a reach (strictly), where
        # this wants every pose within loop_radius (cKDTree's ball includes the boundary)
        # in cKDTree's order, which picks the nearest among equally near poses.
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
