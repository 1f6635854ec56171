"""Rooms the simulator's defaults do not make: the fit's cost and quality on any room.

Issue 21, item 2. Each scene differs from the built-in office seen by the default stereo
camera in one way: the room's size, the density of its clutter, the range noise and
mismatches, the evidence the features carry, or the sensor's pattern (a 16-row laser
scanner with constant range noise instead of the pan-tilt stereo camera). Each is
compared with the 5 cm dense grid by :func:`occtool.compare.compare_grid` (its own
timing: the parametric fit + extraction against the grid's build + extraction on the
same 90 % of the features) in a fresh Python process per run, so every figure is a first
call in its process; a few runs per scene give the spread.

Issue 21, item 3: the same scenes and a narrow aisle (0.55 m passages between shelf
rows, things sticking into them; not the built-in ``aisle``) at 1k, 10k and 100k
features, seeds 0-2: IoU and violation against the truth of the parametric polygon and
of the careful grid (``compare-grid --unknown occupied``), and the held-out AUC in front
of the first obstacle (:func:`run_quality`, :func:`render_quality`).

    python bench/unseen_rooms.py [--runs 3] [--json out.json]

:func:`unseen_rooms_section` returns ``(markdown, json_dict)`` for bench/run.py.
"""

from __future__ import annotations

import json
import math
import statistics
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
FEATURES = 10_000
RUNS = 3
RESOLUTION = 0.05
#: Feature counts and seeds (0 .. QUALITY_SEEDS - 1) of the quality rows.
QUALITY_COUNTS = (1_000, 10_000, 100_000)
QUALITY_SEEDS = 3
#: Scene name -> what differs from the simulator's defaults.
SCENES = {
    "small room": "the office scaled to 0.6 of its size",
    "large room": "the office scaled 2.5 times (walls up to 10 m away, sensor range 10 m)",
    "dense clutter": "40 random boxes 0.1-1.8 m high in a 7 m x 7 m room",
    "sparse clutter": "6 random boxes in a 12 m x 12 m room",
    "noisy stereo": "the office, range noise 0.03 r^2 (3x) and 15 % mismatches (3x)",
    "weak evidence": "the clutter scene, evidence uniform in [0.3, 1] (the default matcher's is mostly 0.7-1)",
    "laser-like": "the office seen by a 16-row scanner (tilt -15 to +10 degrees), 1 cm constant noise, "
                  "2 % mismatches, evidence 0.9",
    "narrow aisle": "a 1 m aisle with two 0.55 m passages between shelf rows opening off it, boxes and beams "
                    "protruding into the passages and the aisle, the whole turned 20 degrees",
}


def _scaled(name: str, scale: float) -> Any:
    from occtool.simulate import build_scene

    scene = build_scene(name)
    obstacles = tuple(replace(o, footprint=tuple((scale * x, scale * y) for x, y in o.footprint))
                      for o in scene.obstacles)
    return replace(scene, obstacles=obstacles, name=f"{name} x{scale:g}")


def _boxes_room(count: int, half_width: float, seed: int) -> Any:
    """A square room with ``count`` random boxes, none within 0.8 m of the robot."""
    from occtool.robot import Robot
    from occtool.simulate import WALL_HEIGHT, Scene, box

    rng = np.random.default_rng(seed)
    w = half_width
    obstacles = [box("wall north", -w, w, w, w + 0.1, 0.0, WALL_HEIGHT), box("wall south", -w, -w - 0.1, w, -w, 0.0, WALL_HEIGHT),
                 box("wall east", w, -w, w + 0.1, w, 0.0, WALL_HEIGHT), box("wall west", -w - 0.1, -w, -w, w, 0.0, WALL_HEIGHT)]
    while len(obstacles) < count + 4:
        x, y = rng.uniform(-w + 0.3, w - 0.3, 2)
        sx, sy = rng.uniform(0.15, 0.8, 2)
        if math.hypot(x, y) < 0.8 + 0.5 * math.hypot(sx, sy):
            continue
        low = 0.0 if rng.random() < 0.8 else rng.uniform(0.3, 0.8)  # some hang (shelves, table tops)
        obstacles.append(box(f"box {len(obstacles) - 4}", x - sx / 2, y - sy / 2, x + sx / 2, y + sy / 2,
                             low, low + rng.uniform(0.1, 1.8)))
    return Scene(tuple(obstacles), Robot(), f"{count} boxes", "random boxes")


def _laser(scene: Any, n: int, seed: int) -> Any:
    """Features of a 16-row scanner at the sensor: constant 1 cm noise, 2 % mismatches."""
    from occtool.features import Features
    from occtool.simulate import NOTHING, cast_rays

    rng = np.random.default_rng(seed)
    rows = np.radians(np.linspace(-15.0, 10.0, 16))
    dirs_kept, ranges_kept, have = [], [], 0
    while have < n:
        pan = rng.uniform(-math.pi, math.pi, 2 * n)
        tilt = rows[rng.integers(0, rows.size, 2 * n)]
        dirs = np.column_stack([np.cos(tilt) * np.cos(pan), np.cos(tilt) * np.sin(pan), np.sin(tilt)])
        ranges, surface = cast_rays(scene, dirs, max_range=8.0)
        seen = (surface != NOTHING) & (ranges >= 0.2)
        dirs_kept.append(dirs[seen])
        ranges_kept.append(ranges[seen])
        have += int(seen.sum())
    dirs, ranges = np.concatenate(dirs_kept)[:n], np.concatenate(ranges_kept)[:n]
    measured = ranges + rng.normal(0.0, 0.01, n)
    wrong = rng.random(n) < 0.02
    measured[wrong] = rng.uniform(0.2, 8.0, int(wrong.sum()))
    return Features(dirs * np.maximum(measured, 0.1)[:, None], np.full(n, 0.9))


def _narrow_aisle() -> Any:
    """Shelf rows with 0.55 m passages between them, things sticking into the passages.

    Unlike the built-in ``aisle`` (a 1.1 m aisle along x with 0.5/0.6 m gaps in its
    walls): the robot stands 0.45 m from a continuous shelf row on its right; on its left
    perpendicular shelf rows leave two 0.55 m passages (0.05 m wide in configuration
    space for a 0.25 m robot) that a box and a low beam narrow further; a box and a beam
    stick out of the right row into the aisle. The whole is turned 20 degrees, so no
    face lies along the simulator's axes.
    """
    from occtool.robot import Robot
    from occtool.simulate import WALL_HEIGHT, Scene, box

    obstacles = [
        box("shelf right", -3.0, -1.05, 3.5, -0.45, 0.0, 2.0),
        box("shelf row left 1", -3.0, 0.55, -0.6, 3.0, 0.0, 2.0),
        box("shelf row left 2", -0.05, 0.55, 1.2, 3.0, 0.0, 2.0),
        box("shelf row left 3", 1.75, 0.55, 3.5, 3.0, 0.0, 2.0),
        box("wall end", 3.5, -1.2, 3.6, 3.1, 0.0, WALL_HEIGHT),
        box("wall back", -3.1, -1.2, -3.0, 3.1, 0.0, WALL_HEIGHT),
        box("wall passages", -3.0, 3.0, 3.5, 3.1, 0.0, WALL_HEIGHT),
        # in passage 1 (x -0.6..-0.05): a box out of its right side, 0.12 m into it
        box("box in passage 1", -0.17, 1.0, -0.05, 1.3, 0.0, 0.6),
        # in passage 2 (x 1.2..1.75): a beam 0.3-0.4 m high, 0.2 m into it
        box("beam in passage 2", 1.2, 0.9, 1.4, 0.95, 0.3, 0.4),
        # out of the right row into the aisle: a box (to 0.5 m) and a beam at 0.5-0.6 m
        box("box in aisle", 0.8, -0.45, 1.1, -0.3, 0.0, 0.5),
        box("beam in aisle", -1.0, -0.45, -0.9, -0.2, 0.5, 0.6),
    ]
    return Scene(tuple(obstacles), Robot(), "narrow aisle", SCENES["narrow aisle"]).rotated(math.radians(20.0))


def make_scene(name: str, seed: int, n: int = FEATURES) -> tuple[Any, Any]:
    """The features (``n`` of them, ``FEATURES`` by default) and truth of scene ``name`` for run ``seed``."""
    from occtool.features import Features
    from occtool.simulate import simulate_scene

    if name == "small room":
        return simulate_scene(_scaled("office", 0.6), n_features=n, seed=seed)
    if name == "large room":
        return simulate_scene(_scaled("office", 2.5), n_features=n, seed=seed, sensor_range=10.0)
    if name == "dense clutter":
        return simulate_scene(_boxes_room(40, 3.5, 7), n_features=n, seed=seed)
    if name == "sparse clutter":
        return simulate_scene(_boxes_room(6, 6.0, 8), n_features=n, seed=seed, sensor_range=8.0)
    if name == "noisy stereo":
        return simulate_scene("office", n_features=n, seed=seed, range_noise=0.03, outlier_rate=0.15)
    if name == "weak evidence":
        features, scene = simulate_scene("clutter", n_features=n, seed=seed)
        evidence = np.random.default_rng(seed + 100).uniform(0.3, 1.0, len(features))
        return Features(features.points, evidence), scene
    if name == "laser-like":
        from occtool.simulate import build_scene

        scene = build_scene("office")
        return _laser(scene, n, seed), scene
    if name == "narrow aisle":
        return simulate_scene(_narrow_aisle(), n_features=n, seed=seed)
    raise ValueError(f"unknown scene {name!r}")


def _child(name: str, seed: int) -> None:
    """One comparison in this (fresh) process; its figures as one JSON line."""
    from occtool.compare import compare_grid
    from occtool.fit import OccupancyRegressor
    from occtool.robot import Robot

    features, scene = make_scene(name, seed)
    robot = Robot()
    started = time.process_time()
    report = compare_grid(features, regressor=OccupancyRegressor(robot=robot, seed=seed),
                          navigation={"robot": robot}, resolution=RESOLUTION, truth=scene, seed=seed,
                          repeat=1, file_sizes=False)
    models = report["models"]
    print(json.dumps({
        "scene": name, "seed": seed, "features": len(features),
        "fit_s": models["parametric"]["build_s"], "extract_s": models["parametric"]["extract_s"],
        "grid_build_s": models["grid"]["build_s"], "grid_extract_s": models["grid"]["extract_s"],
        "pieces": models["parametric"]["pieces"],
        "iou": report.get("truth", {}).get("parametric", {}).get("iou"),
        "grid_iou": report.get("truth", {}).get("grid", {}).get("iou"),
        "compare_cpu_s": time.process_time() - started,
    }))


#: The sensor's field of view in each scene, as the simulator draws its rays: tilts (radians)
#: and the nearest range registered. What lies below the lowest tilt near the robot (the
#: blind zone) no feature can show; the violation is also split by it (:func:`quality_row`).
STEREO_FIELD = ((math.radians(-50.0), math.radians(30.0)), 0.2)
LASER_FIELD = ((math.radians(-15.0), math.radians(10.0)), 0.2)


def sensor_field(name: str) -> tuple[tuple[float, float], float]:
    """``(tilt_range, min_range)`` of the sensor that sees scene ``name`` (:func:`make_scene`)."""
    from occtool.simulate._camera import MIN_SENSOR_RANGE, TILT_RANGE

    # The bench's copies must match the simulator's: a drift would split the violation wrongly.
    assert STEREO_FIELD == (TILT_RANGE, MIN_SENSOR_RANGE)
    return LASER_FIELD if name == "laser-like" else STEREO_FIELD


def quality_row(name: str, seed: int, n: int) -> dict[str, Any]:
    """The parametric polygon and the careful grid (``compare-grid --unknown occupied``) on
    ``n`` features of ``name``: IoU and violation against the truth, the violation split
    into the part on obstacles the sensor could see and the part in its blind zone
    (:func:`occtool.scoring.violation_by_observability`), held-out AUC in front of the
    first obstacle."""
    import shapely

    from occtool.compare import compare_grid
    from occtool.fit import OccupancyRegressor
    from occtool.robot import Robot
    from occtool.scoring import violation_by_observability

    features, scene = make_scene(name, seed, n)
    robot = Robot()
    report = compare_grid(features, regressor=OccupancyRegressor(robot=robot, seed=seed),
                          navigation={"robot": robot}, resolution=RESOLUTION, truth=scene, seed=seed,
                          repeat=1, file_sizes=False, unknown="occupied")
    truth = report["truth"]
    tilt_range, min_range = sensor_field(name)
    split = {model: violation_by_observability(shapely.from_geojson(json.dumps(report["polygons"][model])), scene,
                                               tilt_range=tilt_range, min_range=min_range, robot_radius=robot.radius)
             for model in ("parametric", "grid")}
    return {
        "scene": name, "seed": seed, "features": n, "pieces": report["models"]["parametric"]["pieces"],
        "fit_s": report["models"]["parametric"]["build_s"],
        "iou": truth["parametric"]["iou"], "grid_iou": truth["grid"]["iou"],
        "violation": truth["parametric"]["violation"], "grid_violation": truth["grid"]["violation"],
        "violation_observable": split["parametric"]["observable"],
        "violation_blind": split["parametric"]["unobservable"],
        "grid_violation_observable": split["grid"]["observable"],
        "grid_violation_blind": split["grid"]["unobservable"],
        "auc_front": report["auc_front"]["parametric"], "grid_auc_front": report["auc_front"]["grid"],
    }


def _quality_child(name: str, seed: int, n: int) -> None:
    """:func:`quality_row` in this (fresh) process, as one JSON line."""
    print(json.dumps(quality_row(name, seed, n)))


def run_quality(seeds: int = QUALITY_SEEDS, counts: tuple[int, ...] = QUALITY_COUNTS) -> list[dict[str, Any]]:
    """:func:`_quality_child` for every scene, count and seed, each in a fresh process."""
    rows = []
    for name in SCENES:
        for n in counts:
            for seed in range(seeds):
                out = subprocess.run([sys.executable, __file__, "--quality-child", name, str(seed), str(n)],
                                     check=True, capture_output=True, text=True, cwd=ROOT).stdout
                rows.append(json.loads(out.strip().splitlines()[-1]))
    return rows


def run_scenes(runs: int = RUNS) -> list[dict[str, Any]]:
    """Every scene ``runs`` times, each run in a fresh process (seeds 0 .. runs - 1)."""
    rows = []
    for name in SCENES:
        for seed in range(runs):
            out = subprocess.run([sys.executable, __file__, "--child", name, str(seed)], check=True,
                                 capture_output=True, text=True, cwd=ROOT).stdout
            rows.append(json.loads(out.strip().splitlines()[-1]))
    return rows


def summarise(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per scene: median, min and max of each time, and how many runs the fit + extract
    took no longer than the grid's build + extract."""
    out = []
    for name in SCENES:
        mine = [r for r in rows if r["scene"] == name]
        if not mine:
            continue
        param = [r["fit_s"] + r["extract_s"] for r in mine]
        grid = [r["grid_build_s"] + r["grid_extract_s"] for r in mine]

        def spread(values: list[float]) -> dict[str, float]:
            return {"median": statistics.median(values), "min": min(values), "max": max(values)}

        out.append({
            "scene": name, "runs": len(mine),
            "fit_s": spread([r["fit_s"] for r in mine]), "extract_s": spread([r["extract_s"] for r in mine]),
            "parametric_s": spread(param), "grid_s": spread(grid),
            "ratio": spread([p / g for p, g in zip(param, grid)]),
            "holds": sum(p <= g for p, g in zip(param, grid)),
            "iou": statistics.median(r["iou"] for r in mine) if all(r["iou"] is not None for r in mine) else None,
            "grid_iou": (statistics.median(r["grid_iou"] for r in mine)
                         if all(r["grid_iou"] is not None for r in mine) else None),
        })
    return out


def render(summary: list[dict[str, Any]]) -> str:
    def ms(s: dict[str, float]) -> str:
        return f"{1000 * s['median']:.0f} ({1000 * s['min']:.0f}-{1000 * s['max']:.0f})"

    lines = [f"{FEATURES:,} features; times in ms from compare-grid's own timing (wall clock, one thread), median "
             "(min-max) over fresh processes, each the first call in its process; the target: fit + extract no "
             "longer than the 5 cm dense grid's build + extract, in every run.", "",
             "| scene | differs by | fit | extract | fit + extract | grid build + extract | ratio | runs holding | "
             "IoU (param / grid) |", "|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        iou = f"{s['iou']:.3f} / {s['grid_iou']:.3f}" if s["iou"] is not None else "-"
        lines.append(f"| {s['scene']} | {SCENES[s['scene']]} | {ms(s['fit_s'])} | {ms(s['extract_s'])} | "
                     f"{ms(s['parametric_s'])} | {ms(s['grid_s'])} | {s['ratio']['median']:.2f} "
                     f"({s['ratio']['min']:.2f}-{s['ratio']['max']:.2f}) | {s['holds']} of {s['runs']} | {iou} |")
    return "\n".join(lines)


def summarise_quality(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per scene and feature count: medians over the seeds of the parametric and careful
    grid's IoU with the truth and AUC in front of the first obstacle, the median and the
    worst seed's IoU difference (parametric - grid), the largest violations."""
    out = []
    for name in SCENES:
        for n in sorted({r["features"] for r in rows}):
            mine = [r for r in rows if r["scene"] == name and r["features"] == n]
            if not mine:
                continue
            gaps = [r["iou"] - r["grid_iou"] for r in mine]
            out.append({
                "scene": name, "features": n, "seeds": len(mine),
                "iou": statistics.median(r["iou"] for r in mine),
                "grid_iou": statistics.median(r["grid_iou"] for r in mine),
                "gap": statistics.median(gaps), "worst_gap": min(gaps),
                "auc_front": statistics.median(r["auc_front"] for r in mine),
                "grid_auc_front": statistics.median(r["grid_auc_front"] for r in mine),
                "violation": max(r["violation"] for r in mine),
                "grid_violation": max(r["grid_violation"] for r in mine),
                # The split of each seed's violation (rows of runs before the split have none).
                **{key: max(r[key] for r in mine) if all(key in r for r in mine) else None
                   for key in ("violation_observable", "violation_blind", "grid_violation_observable",
                               "grid_violation_blind")},
            })
    return out


def render_quality(quality: list[dict[str, Any]]) -> str:
    seeds = max((q["seeds"] for q in quality), default=0)
    lines = ["Quality against the truth, parametric model vs the careful grid (5 cm, `compare-grid --unknown "
             f"occupied`: unseen columns read occupied), medians over seeds 0-{seeds - 1}; gap = parametric - "
             "grid IoU (median, worst seed); AUC on held-out features in front of the first obstacle; violation "
             "the largest over the seeds, in full and split: on the parts of obstacles some ray of the sensor "
             "reaches (observable) and on parts in its blind zone below its lowest tilt, which no feature can show "
             "(docs/scenes.md, *Observable and blind violation*; each the largest over the seeds, so the two need not "
             "add up to the full column).", "",
             "| scene | features | IoU param | IoU grid | gap (worst) | AUC front param / grid | violation param / grid "
             "| observable param / grid | blind zone param / grid |",
             "|---|---|---|---|---|---|---|---|---|"]

    def pair(q: dict[str, Any], key: str) -> str:
        if q.get(key) is None:
            return "-"
        return f"{100 * q[key]:.2f} % / {100 * q['grid_' + key]:.2f} %"

    for q in quality:
        lines.append(f"| {q['scene']} | {q['features']:,} | {q['iou']:.3f} | {q['grid_iou']:.3f} | "
                     f"{q['gap']:+.3f} ({q['worst_gap']:+.3f}) | {q['auc_front']:.3f} / {q['grid_auc_front']:.3f} | "
                     f"{pair(q, 'violation')} | {pair(q, 'violation_observable')} | {pair(q, 'violation_blind')} |")
    return "\n".join(lines)


def unseen_targets(data: dict[str, Any] | None) -> list[tuple[str, str, bool | None]]:
    """Issue 21's target on these rooms, for the bench's table of targets."""
    summary = (data or {}).get("summary", [])
    if not summary:
        return []
    held = sum(s["holds"] for s in summary)
    runs = sum(s["runs"] for s in summary)
    worst = max(summary, key=lambda s: s["ratio"]["max"])
    targets: list[tuple[str, str, bool | None]] = [
        (f"Unseen rooms ({len(summary)} scenes, {FEATURES:,} features, first call in a fresh process): "
         "fit + extract <= the dense grid's build + extract in compare-grid's timing, every run",
         f"{held} of {runs} runs; largest ratio {worst['ratio']['max']:.2f} ({worst['scene']})", held == runs)]
    quality = (data or {}).get("quality", [])
    if quality:
        counts = sorted({q["features"] for q in quality})
        span = f"{counts[0]:,}-{counts[-1]:,}"
        low = min(quality, key=lambda q: q["gap"])
        targets.append((f"Unseen rooms ({len({q['scene'] for q in quality})} scenes, {span} features, median over "
                        "seeds): no scene more than 0.05 IoU below the careful grid (`--unknown occupied`)",
                        f"smallest gap {low['gap']:+.3f} ({low['scene']}, {low['features']:,})", low["gap"] >= -0.05))
        big = [q for q in quality if q["features"] >= 10_000]
        if big:
            behind = [q for q in big if q["auc_front"] < q["grid_auc_front"]]
            worst_auc = min(big, key=lambda q: q["auc_front"] - q["grid_auc_front"])
            targets.append(("Unseen rooms, 10k+ features: held-out AUC in front of the first obstacle >= the careful "
                            "grid's on every scene",
                            f"{len(big) - len(behind)} of {len(big)} scene-counts; worst "
                            f"{worst_auc['auc_front']:.3f} vs {worst_auc['grid_auc_front']:.3f} "
                            f"({worst_auc['scene']}, {worst_auc['features']:,})", not behind))
        over = [q for q in quality if q["violation"] > 0.005]
        shown = "; ".join(f"{q['scene']} {q['features']:,}: {100 * q['violation']:.1f} % (grid "
                          f"{100 * q['grid_violation']:.1f} %)" for q in over)
        targets.append(("Unseen rooms: the parametric polygon's violation <= 0.5 % in every run",
                        f"over it: {shown}" if over else "every run", not over))
        # The full target above stays; this one says how much of it the sensor could have seen.
        split = [q for q in quality if q.get("violation_observable") is not None]
        if split:
            seen_over = [q for q in split if q["violation_observable"] > 0.005]
            shown = "; ".join(f"{q['scene']} {q['features']:,}: {100 * q['violation_observable']:.2f} % (grid "
                              f"{100 * q['grid_violation_observable']:.2f} %)" for q in seen_over)
            worst = max(split, key=lambda q: q["violation_observable"])
            targets.append(("Unseen rooms: the parametric polygon's violation on obstacles the sensor can see "
                            "(outside its blind zone) <= 0.5 % in every run",
                            f"over it: {shown}" if seen_over else
                            f"every run; largest {100 * worst['violation_observable']:.2f} % ({worst['scene']}, "
                            f"{worst['features']:,})", not seen_over))
    return targets


def unseen_rooms_section(runs: int = RUNS) -> tuple[str, dict[str, Any]]:
    """The section's markdown and figures for bench/run.py."""
    rows = run_scenes(runs)
    summary = summarise(rows)
    quality_rows = run_quality(QUALITY_SEEDS if runs > 1 else 1)
    quality = summarise_quality(quality_rows)
    return (render(summary) + "\n\n" + render_quality(quality),
            {"runs": rows, "summary": summary, "quality_runs": quality_rows, "quality": quality})


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--quality-child":
        sys.path.insert(0, str(ROOT))
        _quality_child(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
    elif len(sys.argv) == 4 and sys.argv[1] == "--child":
        sys.path.insert(0, str(ROOT))
        _child(sys.argv[2], int(sys.argv[3]))
    else:
        runs = int(sys.argv[sys.argv.index("--runs") + 1]) if "--runs" in sys.argv else RUNS
        started = time.perf_counter()
        markdown, data = unseen_rooms_section(runs)
        print(markdown)
        print(f"\n{time.perf_counter() - started:.0f} s", file=sys.stderr)
        if "--json" in sys.argv:
            Path(sys.argv[sys.argv.index("--json") + 1]).write_text(json.dumps(data, indent=1) + "\n")
