"""Loop closure: loop edges found by registration, and the pose graph solved by least squares."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

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
    planar_information,
    relative,
)


def close_loops(prepared: Sequence[FloatArray], poses: list[Pose], planar: bool, aligner: _Aligner,
                settings: RegistrationSettings, report: RegistrationReport | None = None,
                step_weights: FloatArray | None = None, *, information_scale: float | None = None) -> list[Pose]:
    """Re-align revisited places: loop edges found by registration, then the pose graph
    of the sequential steps and the loops solved by :func:`solve_graph` (least squares,
    the loops that disagree with the rest pruned). The graph is planar (x, y, yaw); a 3D
    scan keeps the height its sequential registration gave it. ``information_scale``: the
    factor that turns GICP's Hessian into information (:func:`~occtool.register._core.information_scale`
    of the steps); without it the loops keep the plain ``settings.loop_sigma``."""
    started = time.process_time()
    count = len(poses)
    steps = [(k - 1, k, relative(poses[k - 1], poses[k])) for k in range(1, count)]
    loops: dict[tuple[int, int], Pose] = {}
    information: dict[tuple[int, int], FloatArray | None] = {}
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
            information[(i, j)] = planar_information(aligner.information, loops[(i, j)].yaw)
            added += 1
        if not added:
            break
        if settings.loop_pair_travel > 0.0:
            edges = list(loops.items())
            agree = consistent_loops([(i, j, z) for (i, j), z in edges], poses, settings,
                                     _loop_weights([information[key] for key, _ in edges], settings, information_scale))
            rejected.update(key for (key, _), ok in zip(edges, agree) if not ok)
            loops = {key: z for (key, z), ok in zip(edges, agree) if ok}
        current, kept = solve_graph(poses, steps, [(i, j, z) for (i, j), z in loops.items()], settings,
                                    step_weights, _loop_weights([information[key] for key in loops], settings,
                                                               information_scale))
        rejected.update((i, j) for (i, j) in loops if (i, j) not in {(a, b) for a, b, _ in kept})
        loops = {(a, b): z for a, b, z in kept}
    if report is not None:
        report.loop_closures = len(loops)
        report.loops = [(i, j, z) for (i, j), z in loops.items()]
        report.loop_candidates = tried
        report.seconds["loop_closure"] = time.process_time() - started
    return current


def _batch_relative(a: FloatArray, b: FloatArray) -> FloatArray:
    """``relative`` over rows of x, y, yaw."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, (b[:, 2] - a[:, 2] + np.pi) % (2 * np.pi) - np.pi])


def _batch_compose(a: FloatArray, b: FloatArray) -> FloatArray:
    """``compose`` over rows of x, y, yaw."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    return np.column_stack([a[:, 0] + c * b[:, 0] - s * b[:, 1], a[:, 1] + s * b[:, 0] + c * b[:, 1],
                            (a[:, 2] + b[:, 2] + np.pi) % (2 * np.pi) - np.pi])


def _turned(cov: FloatArray, angle: FloatArray) -> FloatArray:
    """Covariances ``(n, 3, 3)`` of x, y, yaw turned by ``angle`` ``(n,)`` radians."""
    g = np.zeros((len(angle), 3, 3))
    g[:, 0, 0] = g[:, 1, 1] = np.cos(angle)
    g[:, 1, 0] = np.sin(angle)
    g[:, 0, 1] = -g[:, 1, 0]
    g[:, 2, 2] = 1.0
    return g @ cov @ g.transpose(0, 2, 1)


def consistent_loops(loops: Sequence[tuple[int, int, Pose]], chain: Sequence[Pose], settings: RegistrationSettings,
                     loop_weights: FloatArray | None = None) -> NDArray[np.bool_]:
    """Which loops agree with their neighbours, one flag a loop.

    Two loops ``(i, j)`` and ``(k, l)`` whose ends lie within ``settings.loop_pair_travel``
    metres of travel of each other (``i`` near ``k``, ``j`` near ``l``) close a cycle with
    the short stretches of ``chain`` (the sequential registration, accurate over a few
    metres) between their ends: ``z_ij (chain_j^-1 chain_l)`` must equal
    ``(chain_i^-1 chain_k) z_kl``. The pair agrees when the difference is within
    ``settings.loop_chi`` standard deviations of the two loops' covariances (from
    ``loop_weights``, else ``settings.loop_sigma``; the yaw's error levered over the
    stretch) and the stretches' (``settings.odometry_sigma`` a step). Then, the loop
    that disagrees with most of its neighbours (more than agree with it) is dropped and
    the counts redone, until every loop agrees with at least as many neighbours as it
    disagrees with: a wrong loop (a scan matched onto the wrong wall) disagrees with the
    right ones around it, which agree among themselves. A loop without neighbours stays.
    """
    n = len(loops)
    keep = np.ones(n, dtype=bool)
    if n < 2:
        return keep
    lt, lr = settings.loop_sigma
    st, sr = settings.odometry_sigma
    roots = (np.repeat(np.diag([1 / lt, 1 / lt, 1 / lr])[None], n, axis=0) if loop_weights is None
             else np.asarray(loop_weights))
    cov = np.linalg.inv(roots.transpose(0, 2, 1) @ roots)
    s = np.array([[p.x, p.y, p.yaw] for p in chain])
    travel = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(s[:, :2], axis=0).T))])
    ii = np.array([e[0] for e in loops])
    jj = np.array([e[1] for e in loops])
    z = np.array([[e[2].x, e[2].y, e[2].yaw] for e in loops])
    reach = settings.loop_pair_travel
    near = ((np.abs(travel[ii][:, None] - travel[ii][None, :]) <= reach)
            & (np.abs(travel[jj][:, None] - travel[jj][None, :]) <= reach))
    np.fill_diagonal(near, False)
    first, second = np.nonzero(near)
    if not len(first):
        return keep
    a = _batch_relative(s[ii[first]], s[ii[second]])
    b = _batch_relative(s[jj[first]], s[jj[second]])
    p = _batch_compose(z[first], b)
    q = _batch_compose(a, z[second])
    diff = np.column_stack([q[:, :2] - p[:, :2], (q[:, 2] - p[:, 2] + np.pi) % (2 * np.pi) - np.pi])
    steps = np.abs(ii[first] - ii[second]) + np.abs(jj[first] - jj[second])
    lever = np.hypot(b[:, 0], b[:, 1]) ** 2 * cov[first, 2, 2]
    total = (cov[first] + _turned(cov[second], a[:, 2])
             + steps[:, None, None] * np.diag([st**2, st**2, sr**2])[None]
             + lever[:, None, None] * np.diag([1.0, 1.0, 0.0])[None])
    chi2 = np.einsum("ni,ni->n", diff, np.linalg.solve(total, diff[:, :, None])[:, :, 0])
    agree = np.zeros((n, n), dtype=bool)
    agree[first, second] = chi2 <= settings.loop_chi**2
    # The test is symmetric in the two loops up to the linearisation: both must pass.
    agree &= agree.T
    disagree = near & ~agree
    while True:
        votes = (disagree[:, keep].sum(axis=1) - agree[:, keep].sum(axis=1)).astype(float)
        votes[~keep] = -np.inf
        worst = int(np.argmax(votes))
        if votes[worst] <= 0:
            return keep
        keep[worst] = False


def _loop_weights(blocks: list[FloatArray | None], settings: RegistrationSettings,
                  scale: float | None) -> FloatArray | None:
    """The loops' square-root information for the graph, ``(len(blocks), 3, 3)``, or ``None``
    (the plain ``settings.loop_sigma``) without ``settings.loop_information`` or ``scale``.

    A loop's covariance is the plain one plus its registration's own (the inverse of its
    Hessian times ``scale``, the factor that calibrates the steps' Hessians): what a loop
    pinned down in every direction still carries (the 5 cm: the scans of a revisit do not
    agree better with each other), and along a corridor the uncertainty of where along it
    the match settled."""
    if not settings.loop_information or scale is None or not blocks:
        return None
    lt, lr = settings.loop_sigma
    floor = np.diag([1e-6 / lt**2, 1e-6 / lt**2, 1e-6 / lr**2])
    cov = np.repeat(np.diag([lt**2, lt**2, lr**2])[None], len(blocks), axis=0)
    for n, block in enumerate(blocks):
        if block is None:
            continue
        try:
            cov[n] += np.linalg.inv(scale * 0.5 * (block + block.T) + floor)
        except np.linalg.LinAlgError:
            continue
    return np.linalg.cholesky(np.linalg.inv(cov)).transpose(0, 2, 1)


def optimise_graph(initial: list[Pose], steps: list[tuple[int, int, Pose]], loops: list[tuple[int, int, Pose]],
                   settings: RegistrationSettings, step_weights: FloatArray | None = None,
                   loop_weights: FloatArray | None = None) -> list[Pose]:
    """The SE(2) pose graph (x, y, yaw per scan, the first held) solved by
    :func:`scipy.optimize.least_squares` with the analytic sparse Jacobian.

    Each edge's residual (its x, y in the first pose's frame, and yaw) is weighted by a
    3x3 square root of its information: ``step_weights`` ``(len(steps), 3, 3)`` for the
    steps and ``loop_weights`` ``(len(loops), 3, 3)`` for the loops if given, else
    ``diag(1/sigma, 1/sigma, 1/sigma_yaw)`` from ``settings``."""
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
    weights[len(steps):] = np.diag([1 / lt, 1 / lt, 1 / lr]) if loop_weights is None else loop_weights
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


def _loop_residuals(poses: list[Pose], loops: list[tuple[int, int, Pose]], settings: RegistrationSettings,
                    loop_weights: FloatArray | None = None) -> FloatArray:
    """Each loop edge's residual on ``poses``, in standard deviations (the root of its
    chi-square, by ``loop_weights`` if given, else the plain ``settings.loop_sigma``)."""
    out = np.empty(len(loops))
    lt, lr = settings.loop_sigma
    plain = np.diag([1 / lt, 1 / lt, 1 / lr])
    for n, (i, j, z) in enumerate(loops):
        found = relative(poses[i], poses[j])
        e = np.array([found.x - z.x, found.y - z.y, _wrap(found.yaw - z.yaw)])
        out[n] = float(np.linalg.norm((plain if loop_weights is None else loop_weights[n]) @ e))
    return out


def solve_graph(initial: list[Pose], steps: list[tuple[int, int, Pose]], loops: list[tuple[int, int, Pose]],
                settings: RegistrationSettings, step_weights: FloatArray | None = None,
                loop_weights: FloatArray | None = None) -> tuple[list[Pose], list[tuple[int, int, Pose]]]:
    """:func:`optimise_graph` with the loops that disagree with the rest pruned: after each
    solve the loops whose residual exceeds ``settings.loop_chi`` standard deviations (and
    0.7 of the largest) are dropped and the graph solved again, until all agree. Returns
    the poses and the loops kept."""
    kept = list(loops)
    weights = None if loop_weights is None else np.asarray(loop_weights)
    poses = optimise_graph(initial, steps, kept, settings, step_weights, weights)
    for _ in range(50):
        if not kept:
            break
        chi = _loop_residuals(poses, kept, settings, weights)
        worst = float(chi.max())
        if worst <= settings.loop_chi:
            break
        keep = chi <= max(settings.loop_chi, 0.7 * worst)
        kept = [loop for loop, k in zip(kept, keep) if k]
        weights = None if weights is None else weights[keep]
        poses = optimise_graph(initial, steps, kept, settings, step_weights, weights)
    return poses, kept
