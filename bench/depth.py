"""Depth cameras (issue 23), for the bench (``bench/run.py`` calls :func:`depth_section`;
``python bench/depth.py`` runs it alone and prints the markdown).

* Throughput: 640x480 frames of the office, rendered once, back-projected and cut to
  the feature budget (10,000) on one core (``time.process_time``).
* Every built-in scene rendered as depth images (a 160x120 pinhole camera at the sensor,
  8 frames 45 degrees apart, 25 degrees down) and written as a ROS 2 MCAP
  (``sensor_msgs/msg/Image`` 16UC1 + CameraInfo + tf), a ROS 1 bag and a TUM RGB-D folder;
  each is read (about 10,000 features), fitted and extracted, and scored against the truth
  beside the pan-tilt point cloud of the same scene with as many features.
* A hand-held walk round the office (120 frames, TUM layout): ``evaluate-log`` (10 % of
  the frames held out in blocks of 10: fused map vs a 5 cm 2D log-odds grid and a 5 cm
  OctoMap, with bytes) and ``compare-grid`` on the turning-in-place frames (parametric vs a
  5 cm 3D log-odds grid and OctoMap on held-out features, with bytes).
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from occtool.evaluate import evaluate_navigation  # noqa: E402
from occtool.fit import OccupancyRegressor  # noqa: E402
from occtool.io import read_log  # noqa: E402
from occtool.io.depth import PinholeCamera, back_project  # noqa: E402
from occtool.navigation import NavigationWarning  # noqa: E402
from occtool.simulate import SCENES, simulate_scene  # noqa: E402
from occtool.simulate._depth import (  # noqa: E402
    render_depth_frames,
    walk,
    write_depth_bag,
    write_depth_folder,
    write_depth_mcap,
)

SEEDS = (0, 1, 2)
PER_FRAME = 1250  # 8 frames: about 10,000 features a position, the bench's headline size
MAX_RANGE = 1.5


def _score(features: Any, scene: Any) -> tuple[float, float]:
    model = OccupancyRegressor(seed=0).fit(features)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NavigationWarning)
        nav = model.navigation_map(max_range=MAX_RANGE)
    result = evaluate_navigation(nav.polygon, scene, robot_radius=nav.robot_radius, max_range=nav.max_range)
    return float(result.iou), float(result.violation)


def throughput() -> dict[str, Any]:
    vga = PinholeCamera(640, 480, 525.0, 525.0, 319.5, 239.5)
    frames, _ = render_depth_frames("office", camera=vga, yaws=[0.0, math.pi])
    millimetres = [(f.depth.astype("f8") * 1000.0).round().astype("u2") for f in frames]
    out: dict[str, Any] = {"frame": "640x480 16UC1 (office, rendered)"}
    for label, budget in (("budget_10000", 10_000), ("all_pixels", None)):
        n = 60 if budget else 10
        back_project(millimetres[0], vga, scale=1e-3, budget=budget)
        start = time.process_time()
        kept = 0
        for i in range(n):
            points, _ = back_project(millimetres[i % 2], vga, scale=1e-3, budget=budget, phase=i)
            kept += len(points)
        seconds = time.process_time() - start
        out[label] = {"frames_per_s": n / seconds, "ms_per_frame": 1000.0 * seconds / n, "features": kept / n}
    return out


def scenes() -> list[dict[str, Any]]:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name in SCENES:
            for seed in SEEDS:
                frames, scene = render_depth_frames(name, seed=seed)
                paths = {
                    "mcap": write_depth_mcap(frames, folder / f"{name}-{seed}.mcap"),
                    "tum": write_depth_folder(frames, folder / f"{name}-{seed}-tum", layout="tum"),
                }
                try:
                    paths["bag"] = write_depth_bag(frames, folder / f"{name}-{seed}.bag")
                except ImportError:
                    pass
                row: dict[str, Any] = {"scene": name, "seed": seed}
                count = 0
                for kind, path in paths.items():
                    log = read_log(path, depth_features=PER_FRAME, position_tolerance=(0.25, 3.2))
                    features = log.single().features
                    count = len(features)
                    row[kind] = dict(zip(("iou", "violation"), _score(features, scene)))
                    row[kind]["features"] = count
                points, truth = simulate_scene(name, n_features=count, seed=seed)
                row["points"] = dict(zip(("iou", "violation"), _score(points, truth)))
                rows.append(row)
    return rows


def hand_held() -> dict[str, Any]:
    from occtool.compare import compare_grid
    from occtool.log_score import evaluate_log

    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        yaws, positions = walk(120)
        frames, scene = render_depth_frames("office", yaws=yaws, positions=positions)
        folder = write_depth_folder(frames, Path(tmp) / "walk", layout="tum")
        started = time.perf_counter()
        score = evaluate_log(str(folder / "depth.txt"), OccupancyRegressor(seed=0), holdout=0.1, block=10,
                             resolution=0.05, no_return_range=None, read_options={"depth_features": 2000})
        figures = score.as_dict()
        out["walk"] = {key: figures.get(key) for key in ("scans", "held_out_scans", "auc", "fused_bytes",
                                                          "grid_bytes", "octomap_bytes", "coverage")}
        out["walk"]["seconds"] = time.perf_counter() - started
        turn, _ = render_depth_frames("office")
        turn_folder = write_depth_folder(turn, Path(tmp) / "turn", layout="tum")
        features = read_log(turn_folder, depth_features=PER_FRAME, position_tolerance=(0.25, 3.2)).single().features
        report = compare_grid(features, regressor=OccupancyRegressor(seed=0),
                              navigation={"max_range": MAX_RANGE}, resolution=0.05, octomap=True, truth=scene)
        out["turn"] = {name: {"auc": report["auc"][name], "auc_front": report["auc_front"][name],
                              "memory_bytes": model["memory_bytes"], "file_bytes": model["file_bytes"],
                              "iou_truth": report["truth"][name]["iou"],
                              "violation": report["truth"][name]["violation"]}
                       for name, model in report["models"].items()}
    return out


def depth_section() -> tuple[str, dict[str, Any]]:
    """The markdown section and its figures."""
    started = time.perf_counter()
    results = {"throughput": throughput(), "scenes": scenes(), "hand_held": hand_held()}
    results["seconds"] = time.perf_counter() - started
    return render(results), results


def render(results: dict[str, Any]) -> str:
    t = results["throughput"]
    lines = [
        "## Depth cameras (issue 23)",
        "",
        f"Back-projection of {t['frame']} on one core: "
        f"{t['budget_10000']['frames_per_s']:.0f} frames/s with the 10,000-feature budget "
        f"({t['budget_10000']['ms_per_frame']:.1f} ms a frame, {t['budget_10000']['features']:,.0f} features), "
        f"{t['all_pixels']['frames_per_s']:.0f} frames/s keeping every pixel.",
        "",
        "Each scene rendered as 8 depth frames (160x120, 60 degrees wide, 25 degrees down, 45 degrees apart) "
        f"and read at {PER_FRAME} features a frame; the pan-tilt point cloud of the same scene and seed with as "
        f"many features beside it. IoU with the truth and collision area, robot radius 0.25 m, max range {MAX_RANGE} m, "
        f"seeds {', '.join(map(str, SEEDS))}:",
        "",
        "| scene | seed | features | point cloud IoU / collision | depth MCAP | ROS 1 bag | TUM folder |",
        "|---|---|---|---|---|---|---|",
    ]

    def cell(entry: dict[str, Any] | None) -> str:
        return "-" if entry is None else f"{entry['iou']:.3f} / {100 * entry['violation']:.2f} %"

    worst_gap, worst_collision = -1.0, 0.0
    for row in results["scenes"]:
        lines.append(f"| {row['scene']} | {row['seed']} | {row['mcap']['features']:,} | {cell(row['points'])} | "
                     f"{cell(row['mcap'])} | {cell(row.get('bag'))} | {cell(row['tum'])} |")
        for kind in ("mcap", "bag", "tum"):
            if kind in row:
                worst_gap = max(worst_gap, row["points"]["iou"] - row[kind]["iou"])
                worst_collision = max(worst_collision, row[kind]["violation"])
    lines += ["", f"Largest IoU shortfall of a depth path below its point cloud: {worst_gap:+.3f} (target <= 0.02); "
              f"largest depth-path collision: {100 * worst_collision:.2f} % (target <= 0.5 %).", ""]
    walk_figures = results["hand_held"]["walk"]
    auc = walk_figures["auc"] or {}
    lines += [
        f"Hand-held walk round the office (120 frames, TUM layout, 2,000 features a frame): {walk_figures['scans']} "
        f"frames, {walk_figures['held_out_scans']} held out in blocks of 10. Held-out AUC: "
        + ", ".join(f"{k} {v:.3f}" for k, v in auc.items())
        + f"; fused map {walk_figures['fused_bytes'] / 1e6:.2f} MB, 2D grid {walk_figures['grid_bytes'] / 1e6:.2f} MB"
        + (f", OctoMap {walk_figures['octomap_bytes'] / 1e6:.2f} MB" if walk_figures.get("octomap_bytes") else "")
        + f" ({walk_figures['seconds']:.0f} s).",
        "",
        "The turning-in-place frames of the office (one position) against 5 cm 3D grids, 10 % of the "
        "features held out:",
        "",
        "| model | held-out AUC | in front of the first obstacle | memory | file | IoU with truth | collision |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, model in results["hand_held"]["turn"].items():
        lines.append(f"| {name} | {model['auc']:.3f} | {model['auc_front']:.3f} | {model['memory_bytes'] / 1e3:,.1f} KB | "
                     f"{model['file_bytes'] / 1e3:,.1f} KB | {model['iou_truth']:.3f} | {100 * model['violation']:.2f} % |")
    lines += ["", f"Section time: {results['seconds']:.0f} s."]
    return "\n".join(lines)


if __name__ == "__main__":
    import json

    markdown, figures = depth_section()
    print(markdown)
    if len(sys.argv) > 1:
        Path(sys.argv[1]).write_text(json.dumps(figures, indent=1, default=float) + "\n")
