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
  OctoMap, with bytes), the same held-out frames scored in 3D (:func:`held_out_3d`: the
  local models vs a 5 cm 3D log-odds grid and OctoMap), and ``compare-grid`` on the
  turning-in-place frames (parametric vs a 5 cm 3D log-odds grid and OctoMap on held-out
  features, with bytes).
* Real frames: ``fixtures/tum-fr3-cabinet`` (58 Kinect key frames of TUM RGB-D's
  freiburg3_cabinet, 320x240, with their poses; its SOURCE.md): the same held-out 3D
  scoring (:func:`held_out_3d`) with 10 % held out in blocks of 10 and 20 % in blocks of 5,
  and ``evaluate-log`` (20 % in blocks of 5: the fused map and the world map in 2D against a
  5 cm 2D log-odds grid and OctoMap), with bytes.
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

from occtool.fit import OccupancyRegressor  # noqa: E402
from occtool.io import read_log  # noqa: E402
from occtool.io.depth import PinholeCamera, back_project  # noqa: E402
from occtool.navigation import NavigationWarning  # noqa: E402
from occtool.scoring import evaluate_navigation  # noqa: E402
from occtool.simulate import SCENES, simulate_scene  # noqa: E402
from occtool.simulate._depth import (  # noqa: E402
    render_depth_frames,
    walk,
    write_depth_bag,
    write_depth_folder,
    write_depth_mcap,
)

SEEDS = (0, 1, 2)
GROUND_CLEARANCE = 0.05  # Robot()'s: returns lower than this above the floor are floor
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
    from occtool.scoring import evaluate_log

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
        out["walk_3d"] = held_out_3d(folder / "depth.txt")
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


def world_grid_3d(starts: Any, ends: Any, hits: Any, resolution: float = 0.05) -> Any:
    """A dense 3D log-odds grid in the world frame from rays (OctoMap's hit/miss model and
    clamping, the 3D twin of :func:`occtool.scoring.world_grid`); a ray that is not a hit
    (a floor return) is a miss all along, as the sensor model's floor features are."""
    import numpy as np

    from occtool.grid import OCTOMAP_DEFAULTS, OccupancyGrid, observation_log_odds, traverse

    lower = np.floor(np.minimum(starts.min(axis=0), ends.min(axis=0)) / resolution).astype(np.int64)
    upper = np.floor(np.maximum(starts.max(axis=0), ends.max(axis=0)) / resolution).astype(np.int64)
    shape = upper - lower + 1
    log_odds = np.zeros(int(np.prod(shape)), dtype=np.float32)
    lengths = np.linalg.norm(ends - starts, axis=1)
    for lo in range(0, lengths.size, 20_000):
        hi = min(lengths.size, lo + 20_000)
        seg = traverse(starts[lo:hi], ends[lo:hi], resolution)
        values = observation_log_odds(seg, lengths[lo:hi], hits[lo:hi].astype(np.float64), hits[lo:hi], None,
                                      OCTOMAP_DEFAULTS)
        cell = seg.cell - lower
        index = (cell[:, 0] * shape[1] + cell[:, 1]) * shape[2] + cell[:, 2]
        np.add.at(log_odds, index, values.astype(np.float32))
    np.clip(log_odds, *OCTOMAP_DEFAULTS.clamp_log_odds, out=log_odds)
    return OccupancyGrid(log_odds.reshape(*(int(v) for v in shape)), float(resolution), lower,
                         params=OCTOMAP_DEFAULTS)


def held_out_3d(path: Path, *, features: int = 2000, holdout: float = 0.1, block: int = 10) -> dict[str, Any]:
    """Frames held out in blocks, scored in 3D: each held-out return's end point occupied and
    points along its ray up to 0.1 m before it free (evaluate-log's test points, in 3D),
    against the local parametric model of the nearest training position that looked the test
    point's way (its direction within the pan angles of the position's features; the nearest
    position when none did), a 5 cm 3D log-odds grid and a 5 cm OctoMap of the training frames."""
    import numpy as np

    from occtool.io.positions import Scan, build_log
    from occtool.scoring import END_MARGIN, FREE_POINTS_PER_BEAM, holdout_blocks, roc_auc, world_rays
    from occtool.scoring._log import _octomap_scores

    scans = read_log(path, group_by="message", depth_features=features).positions
    held = holdout_blocks(len(scans), holdout, block, 0)
    train = [s for s, out in zip(scans, held) if not out]
    test = [s for s, out in zip(scans, held) if out]
    # Each held-out frame's test points. As compare-grid's,
    # floor returns (below the ground clearance) are free-only: their rays give free points,
    # their ends no occupied one (the parametric model does not take the floor for an obstacle).
    rng = np.random.default_rng(0)

    def frame_points(frame: Any) -> tuple[Any, Any]:
        pose = frame.pose
        hits = frame.features.evidence > 0
        ends = frame.features.points[hits] @ pose.rotation.T + pose.translation
        start = pose.translation
        length = np.linalg.norm(ends - start, axis=1)
        usable = length > END_MARGIN
        reach = ((length[usable] - END_MARGIN) / length[usable])[:, None] * rng.uniform(
            0.0, 1.0, (int(usable.sum()), FREE_POINTS_PER_BEAM))
        free = (start + reach[:, :, None] * (ends[usable] - start)[:, None, :]).reshape(-1, 3)
        return ends[ends[:, 2] >= GROUND_CLEARANCE], free

    parts = [frame_points(frame) for frame in test]
    occupied = np.concatenate([o for o, _ in parts])
    free = np.concatenate([f for _, f in parts])
    points = np.concatenate([occupied, free])
    n_occupied = len(occupied)
    log = build_log([Scan(s.features.points, s.features.evidence, s.pose, s.stamp, s.source) for s in train],
                    source=str(path))
    started = time.perf_counter()
    models = [OccupancyRegressor(seed=0).fit(position.features) for position in log.positions]
    fit_s = time.perf_counter() - started
    # Each test point is scored by the nearest training position that looked its way: its
    # direction from the position within the pan angles the position's features span.
    locals_, seen, distance = [], [], []
    for position in log.positions:
        pose = position.pose
        local = (points - pose.translation) @ pose.rotation
        alpha = np.arctan2(local[:, 1], local[:, 0])
        span = position.features.alpha
        seen.append((alpha >= span.min()) & (alpha <= span.max()))
        distance.append(np.linalg.norm(local, axis=1))
        locals_.append(local)
    seen_array, distance_array = np.array(seen), np.array(distance)
    choice = np.argmin(np.where(seen_array, distance_array, distance_array + 1e6), axis=0)
    parametric = np.empty(len(points))
    for i, model in enumerate(models):
        mine = choice == i
        local = locals_[i][mine]
        parametric[mine] = model.predict(np.arctan2(local[:, 1], local[:, 0]), local[:, 2],
                                         np.linalg.norm(local, axis=1))
    unseen = float((~seen_array.any(axis=0)).mean())
    starts, ends, train_returns, _ = world_rays(train)
    keep = train_returns  # returns only (no free rays in this log)
    started = time.perf_counter()
    grid = world_grid_3d(starts[keep], ends[keep], ends[keep][:, 2] >= GROUND_CLEARANCE)
    grid_s = time.perf_counter() - started
    grid_p = grid.occupancy(points)
    grid_unknown = float(np.mean(grid_p == 0.5))
    octomap = _octomap_scores(train, points, n_occupied, 0.05)
    model_bytes = sum(len(json_bytes(m)) for m in models)
    return {
        "frames": len(scans), "held_out": int(held.sum()), "positions": len(models),
        "occupied_points": n_occupied, "free_points": len(free),
        "auc": {"parametric (local models)": roc_auc(parametric[:n_occupied], parametric[n_occupied:]),
                "grid 3D": roc_auc(grid_p[:n_occupied], grid_p[n_occupied:]), **octomap.get("auc", {})},
        "bytes": {"parametric (local models)": model_bytes, "grid 3D": int(grid.nbytes),
                  "octomap": octomap.get("octomap_bytes")},
        "fit_s": fit_s, "grid_s": grid_s, "unseen_share": unseen, "grid_unknown_share": grid_unknown,
    }


REAL_TUM = ROOT / "fixtures" / "tum-fr3-cabinet"
#: (share held out, block) of the real frames' held-out 3D scoring.
REAL_SPLITS = ((0.1, 10), (0.2, 5))


def real_frames(folder: Path = REAL_TUM) -> dict[str, Any]:
    """The real TUM frames (``fixtures/tum-fr3-cabinet``): :func:`held_out_3d` for each of
    :data:`REAL_SPLITS`, and ``evaluate-log`` with 20 % held out in blocks of 5."""
    from occtool.scoring import evaluate_log

    path = folder / "depth.txt"
    out: dict[str, Any] = {"source": str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)}
    out["held_out_3d"] = [{"holdout": share, "block": block, **held_out_3d(path, holdout=share, block=block)}
                          for share, block in REAL_SPLITS]
    started = time.perf_counter()
    score = evaluate_log(str(path), OccupancyRegressor(seed=0), holdout=0.2, block=5, resolution=0.05,
                         no_return_range=None, read_options={"depth_features": 2000})
    figures = score.as_dict()
    out["evaluate_log"] = {key: figures.get(key) for key in ("scans", "held_out_scans", "auc", "fused_bytes",
                                                             "grid_bytes", "octomap_bytes", "world_bytes", "coverage")}
    out["evaluate_log"]["seconds"] = time.perf_counter() - started
    return out


def json_bytes(model: Any) -> bytes:
    """A fitted model's file, as ``occtool fit`` writes it."""
    from occtool.formats.model import model_text

    return model_text(model).encode()


def depth_section() -> tuple[str, dict[str, Any]]:
    """The markdown section and its figures."""
    started = time.perf_counter()
    results = {"throughput": throughput(), "scenes": scenes(), "hand_held": hand_held(), "real": real_frames()}
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
        "The same walk scored in 3D (the held-out frames' returns above the ground clearance occupied, "
        "points along their rays up to 0.1 m before the end free; each frame's points against the local model "
        "of the nearest training position that looked its way):",
        "",
        "| model | held-out AUC | bytes (the parametric models: their files; the grids: memory) |",
        "|---|---|---|",
        *[f"| {name} | {value:.3f} | {results['hand_held']['walk_3d']['bytes'].get(name) or 0:,} |"
          for name, value in results["hand_held"]["walk_3d"]["auc"].items()],
        "",
        f"({results['hand_held']['walk_3d']['positions']} training positions fitted in "
        f"{results['hand_held']['walk_3d']['fit_s']:.1f} s; the 3D grid built in {results['hand_held']['walk_3d']['grid_s']:.1f} s; "
        f"{results['hand_held']['walk_3d']['occupied_points']:,} occupied and {results['hand_held']['walk_3d']['free_points']:,} free test points, "
        f"{100 * results['hand_held']['walk_3d']['unseen_share']:.0f} % of them in no training position's pan span.)",
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
    if "real" in results:
        lines += ["", *render_real(results["real"])]
    lines += ["", f"Section time: {results['seconds']:.0f} s."]
    return "\n".join(lines)


def render_real(real: dict[str, Any]) -> list[str]:
    """The real frames' lines of the section."""
    lines = [
        f"Real frames: `{real['source']}` (58 Kinect key frames of TUM RGB-D's freiburg3_cabinet, 320x240, "
        "2,000 features a frame), held out in blocks and scored in 3D as the walk above:",
        "",
        "| held out | model | held-out AUC | bytes (the parametric models: their files; the grids: memory) |",
        "|---|---|---|---|",
    ]
    for split in real["held_out_3d"]:
        label = f"{split['held_out']} of {split['frames']} frames ({100 * split['holdout']:.0f} %, blocks of {split['block']})"
        for name, value in split["auc"].items():
            lines.append(f"| {label} | {name} | {value:.3f} | {split['bytes'].get(name) or 0:,} |")
    lines.append("")
    lines.append("; ".join(
        f"{100 * s['holdout']:.0f} % held out: {s['positions']} training positions, {s['occupied_points']:,} occupied "
        f"and {s['free_points']:,} free test points, {100 * s['grid_unknown_share']:.0f} % of them in unknown cells of "
        f"the 3D grid, {100 * s['unseen_share']:.0f} % in no training position's pan span" for s in real["held_out_3d"]) + ".")
    e = real["evaluate_log"]
    auc = e["auc"] or {}
    names = [k for k in ("fused_log_odds", "world", "grid", "textbook_0.05m", "octomap") if k in auc]
    lines += ["", f"`evaluate-log` on the same folder ({e['held_out_scans']} of {e['scans']} frames held out in blocks of 5, "
              "2D): AUC " + ", ".join(f"{k} {auc[k]:.3f}" for k in names)
              + f"; fused map {e['fused_bytes'] / 1e3:.1f} KB, world map {(e['world_bytes'] or 0) / 1e3:.1f} KB, "
              f"2D grid {e['grid_bytes'] / 1e3:.1f} KB"
              + (f", OctoMap {e['octomap_bytes'] / 1e6:.2f} MB" if e.get("octomap_bytes") else "")
              + f"; the fused map covers {100 * (e['coverage'] or 0):.0f} % of the test points ({e['seconds']:.0f} s)."]
    return lines


if __name__ == "__main__":
    import json

    args = sys.argv[1:]
    if args[:1] == ["--real"]:  # the real frames' lines alone
        figures: dict[str, Any] = {"real": real_frames()}
        markdown = "\n".join(render_real(figures["real"]))
        args = args[1:]
    else:
        markdown, figures = depth_section()
    print(markdown)
    if args:
        Path(args[0]).write_text(json.dumps(figures, indent=1, default=float) + "\n")
