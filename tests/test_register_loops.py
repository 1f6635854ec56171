"""Loop closure's checks (occtool.register): loops verified against each other before they join
the pose graph, and each loop weighed by its own registration's information.

Synthetic pose graphs only (no scans, no small_gicp): cheap.
"""

from __future__ import annotations

import math

import numpy as np

from occtool.features import Pose
from occtool.register import RegistrationSettings, compose, consistent_loops, relative, solve_graph
from occtool.register._core import information_roots, planar_information
from occtool.register._graph import _loop_weights


def _square(side: float = 10.0, step: float = 0.5) -> list[Pose]:
    """A robot driving a square twice (anticlockwise), a pose every ``step`` metres."""
    poses = []
    for _lap in range(2):
        for edge in range(4):
            yaw = edge * math.pi / 2
            corner = [(0.0, 0.0), (side, 0.0), (side, side), (0.0, side)][edge]
            for n in range(int(side / step)):
                poses.append(Pose(corner[0] + n * step * math.cos(yaw), corner[1] + n * step * math.sin(yaw), 0.0, yaw))
    return poses


def _drifting(truth: list[Pose], bias: float = 0.004) -> list[Pose]:
    """The true steps with a heading bias each step: metres off after a lap, right over a few steps."""
    out = [truth[0]]
    for k in range(1, len(truth)):
        step = relative(truth[k - 1], truth[k])
        out.append(compose(out[-1], Pose(step.x, step.y, 0.0, step.yaw + bias)))
    return out


def _second_lap_loops(truth: list[Pose], wrong: dict[int, Pose]) -> list[tuple[int, int, Pose]]:
    """Loops from the second lap's first edge onto the first lap's, every second pose; those in
    ``wrong`` (by their index in the list) moved by that much."""
    lap = len(truth) // 2
    loops = []
    for n, i in enumerate(range(0, 20, 2)):
        z = relative(truth[i], truth[lap + i])
        if n in wrong:
            z = compose(z, wrong[n])
        loops.append((i, lap + i, z))
    return loops


def test_a_loop_that_disagrees_with_its_neighbours_is_rejected():
    truth = _square()
    chain = _drifting(truth)
    assert math.hypot(chain[-1].x - truth[-1].x, chain[-1].y - truth[-1].y) > 3.0  # the drift loops must undo
    settings = RegistrationSettings()
    # A scan matched onto the wrong wall: 0.5 m and 3 degrees off; every other loop right.
    loops = _second_lap_loops(truth, {4: Pose(0.0, 0.5, 0.0, math.radians(3.0))})
    keep = consistent_loops(loops, chain, settings)
    assert keep.tolist() == [n != 4 for n in range(len(loops))]
    # 0.1 m off is within the loops' own noise (5 cm, 1.1 degrees, at 5 standard deviations): kept.
    assert consistent_loops(_second_lap_loops(truth, {4: Pose(0.0, 0.1, 0.0, 0.0)}), chain, settings).all()
    # Checked against each other only: the global drift of the chain does not count against them.
    assert consistent_loops(_second_lap_loops(truth, {}), chain, settings).all()


def test_loops_without_neighbours_or_with_the_check_off_are_kept():
    truth = _square()
    chain = _drifting(truth)
    loops = _second_lap_loops(truth, {4: Pose(0.0, 0.5, 0.0, 0.0)})
    lonely = [loops[0], loops[-1]]  # 18 poses (9 m of travel) apart at both ends
    assert consistent_loops(lonely, chain, RegistrationSettings()).all()
    assert consistent_loops(loops, chain, RegistrationSettings(loop_pair_travel=0.0)).all()


def test_two_wrong_loops_among_right_ones_are_both_rejected():
    truth = _square()
    loops = _second_lap_loops(truth, {3: Pose(0.8, 0.0, 0.0, 0.0), 6: Pose(0.0, -0.6, 0.0, math.radians(-4.0))})
    keep = consistent_loops(loops, _drifting(truth), RegistrationSettings())
    assert np.flatnonzero(~keep).tolist() == [3, 6]


def test_a_loop_loose_along_a_corridor_does_not_pull_along_it():
    # One loop, 0.5 m off along x (a corridor along x: the scan match cannot tell where along it);
    # its information says so, and the graph follows the steps along x. The steps are right,
    # the solve starts from a drifting estimate.
    truth = _square()
    chain = _drifting(truth)
    lap = len(truth) // 2
    steps = [(k - 1, k, relative(truth[k - 1], truth[k])) for k in range(1, len(truth))]
    z = compose(relative(truth[0], truth[lap]), Pose(0.5, 0.0, 0.0, 0.0))
    settings = RegistrationSettings()
    # GICP's Hessian (x, y, yaw) of a match that cannot tell where along x it is.
    loose_along_x = _loop_weights([np.diag([1e-6, 1.0, 1.0]) * 100.0], settings, 2500.0)
    plain, _ = solve_graph(chain, steps, [(0, lap, z)], settings)
    weighed, kept = solve_graph(chain, steps, [(0, lap, z)], settings, loop_weights=loose_along_x)
    assert len(kept) == 1
    end_plain = relative(plain[0], plain[lap])
    end_weighed = relative(weighed[0], weighed[lap])
    truth_end = relative(truth[0], truth[lap])
    assert abs(end_plain.x - truth_end.x) > 0.4  # the plain loop drags the pose along x
    assert abs(end_weighed.x - truth_end.x) < 0.1 * abs(end_plain.x - truth_end.x)
    assert abs(end_weighed.y - truth_end.y) < 0.01


def test_information_is_scaled_to_the_median_and_turned_into_the_edge_frame():
    sigma = (0.05, 0.02)
    blocks = [np.diag([4.0, 4.0, 1.0]), np.diag([1.0, 1.0, 1.0]), np.diag([100.0, 1.0, 1.0]), None]
    roots = information_roots(blocks, sigma)
    info = roots.transpose(0, 2, 1) @ roots
    # The median block (translation 1 + 1, 4 + 4 and 100 + 1: 4) gets 1 / sigma^2.
    assert np.allclose(info[0][:2, :2], np.diag([1.0, 1.0]) / 0.05**2, rtol=1e-4)
    assert np.allclose(roots[3], np.diag([1 / 0.05, 1 / 0.05, 1 / 0.02]) / 3.0)  # none: plain, 3 times wider
    # small_gicp's order is rotation x, y, z then translation x, y, z; a quarter turn swaps x and y.
    h = np.zeros((6, 6))
    h[3, 3], h[4, 4], h[2, 2] = 9.0, 1.0, 5.0
    turned = planar_information(h, math.pi / 2)
    assert turned is not None and np.allclose(turned, np.diag([1.0, 9.0, 5.0]))
    assert planar_information(np.full((6, 6), np.nan), 0.0) is None


def test_a_loop_is_as_certain_as_the_plain_sigma_at_most_and_loose_where_its_match_is():
    settings = RegistrationSettings()
    lt, lr = settings.loop_sigma
    scale = 1 / 0.02**2  # a Hessian of 1 is a 2 cm step
    pinned = np.diag([1e4, 1e4, 1e6])  # a match that pins the place down: its own error is tiny
    corridor = np.diag([1e-4, 1e4, 1e6])  # ... except along x (Hessian 1e-4: 2 m)
    roots = _loop_weights([pinned, corridor, None], settings, scale)
    assert roots is not None
    sigma = np.sqrt(np.diagonal(np.linalg.inv(roots.transpose(0, 2, 1) @ roots), axis1=1, axis2=2))
    assert np.allclose(sigma[0], [lt, lt, lr], rtol=0.01)  # the plain sigmas, never tighter
    assert np.allclose(sigma[2], [lt, lt, lr])  # no Hessian: the plain sigmas
    assert sigma[1][0] > 1.0 and np.isclose(sigma[1][1], lt, rtol=0.01)
    # Without the calibration (or with the weights off) the loops keep the plain sigmas.
    assert _loop_weights([pinned], settings, None) is None
    assert _loop_weights([pinned], RegistrationSettings(loop_information=False), scale) is None
