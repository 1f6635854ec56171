"""A synthetic CARMEN log of a 2D laser driving round a rectangular room (tests of occtool map)."""

from __future__ import annotations

import numpy as np

ROOM = (-3.0, -2.0, 5.0, 2.5)  # x_min, y_min, x_max, y_max, metres


def room_ranges(x: float, y: float, yaw: float, beams: int = 180) -> np.ndarray:
    """Ranges of a 180-degree laser at (x, y, yaw) to the room's walls (exact ray-box exits)."""
    angles = yaw - np.pi / 2 + np.arange(beams) * np.pi / beams
    dx, dy = np.cos(angles), np.sin(angles)
    x0, y0, x1, y1 = ROOM
    with np.errstate(divide="ignore"):
        tx = np.where(dx > 0, (x1 - x) / dx, np.where(dx < 0, (x0 - x) / dx, np.inf))
        ty = np.where(dy > 0, (y1 - y) / dy, np.where(dy < 0, (y0 - y) / dy, np.inf))
    return np.minimum(tx, ty)


def write_room_log(path, scans: int = 60) -> list[tuple[float, float, float]]:
    """Write ``scans`` scans along a loop inside the room; returns the poses."""
    t = np.linspace(0.0, 2.0 * np.pi, scans, endpoint=False)
    poses = [(1.0 + 2.0 * np.cos(a), 0.25 + 1.0 * np.sin(a), a + np.pi / 2) for a in t]
    lines = ["# synthetic room for occtool's tests"]
    for k, (x, y, yaw) in enumerate(poses):
        ranges = room_ranges(x, y, yaw)
        stamp = 10.0 + 0.5 * k
        lines.append("FLASER 180 " + " ".join(f"{r:.3f}" for r in ranges)
                     + f" {x:.4f} {y:.4f} {yaw:.5f} {x:.4f} {y:.4f} {yaw:.5f} {stamp} test {stamp}")
    with open(path, "w", encoding="utf-8") as handle:
        handle.write("\n".join(lines) + "\n")
    return poses
