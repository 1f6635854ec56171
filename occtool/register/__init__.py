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

from occtool.register._core import (
    RegistrationReport,
    RegistrationSettings,
    compose,
    matched_share,
    relative,
    scan_points,
)
from occtool.register._evaluate import (
    NOISE_MODELS,
    degrade_odometry,
    degrade_poses,
    segment_errors,
    trajectory_error,
)
from occtool.register._graph import close_loops, consistent_loops, optimise_graph, solve_graph
from occtool.register._poses import read_map_log, trajectory, write_map_poses, write_poses_csv
from occtool.register._scans import (
    needs_registration,
    pose_kind,
    positions_with_poses,
    read_registered_log,
    register_log,
    register_scans,
)

__all__ = ["NOISE_MODELS", "RegistrationReport", "RegistrationSettings", "close_loops", "compose",
           "consistent_loops", "degrade_odometry",
           "degrade_poses",
           "matched_share", "needs_registration", "optimise_graph", "pose_kind", "positions_with_poses",
           "read_map_log", "read_registered_log", "register_log", "register_scans", "relative", "scan_points",
           "segment_errors", "solve_graph", "trajectory", "trajectory_error", "write_map_poses", "write_poses_csv"]
