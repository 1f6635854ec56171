"""The 3D map's own CPU against pyoctomap inserting the very same rays (issue 35), in one process.

``bench/heldout3d.py`` charges ``occtool map`` its whole process (imports, reading the frames,
the 2D keyframe fits for ``navigation.geojson``, every output) and pyoctomap its insertion
of the bench's own frames. This compares like for like: it runs ``occtool map`` with the
given arguments in this process, keeps the rays its 3D map is built from
(:func:`occtool.fuse._log3d.rays_of_log`, every feature of every position), and then times,
with ``time.process_time`` and the best of ``--repeat`` runs each:

* ``occtool_3d``: what :func:`occtool.fuse.map_log_3d` does with them, the cell and the
  saturation chosen on the inner split (:func:`occtool.fuse.choose_resolution`) and the map
  built and encoded (its file's bytes);
* ``octomap_<r>``: ``pyoctomap.OcTree(r).insertPointCloud`` of each position's rays from its
  origin (a free-only ray made 1 % longer and cut at ``--max-range``, as the bench does).

Usage: ``python bench/cpu3d.py --max-range 8 -- TRAIN -o DIR --sensor-height 0.95 ...``
(everything after ``--`` is ``occtool map``'s). One thread a library, as the bench.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def captured_rays(map_arguments: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Run ``occtool map ARGS`` here and return the rays its 3D map was built from."""
    import occtool.fuse._mapping as mapping
    from occtool.cli.main import main as occtool_main
    from occtool.fuse._log3d import rays_of_log

    kept: dict[str, Any] = {}
    build = mapping.map_log_3d

    def keeping(log: Any, *args: Any, **kwargs: Any) -> Any:
        kept["rays"] = rays_of_log(log)
        return build(log, *args, **kwargs)

    mapping.map_log_3d = keeping  # type: ignore[assignment]
    try:
        occtool_main(["-q", "map", *map_arguments])
    except SystemExit as exc:
        if exc.code:
            raise
    finally:
        mapping.map_log_3d = build  # type: ignore[assignment]
    if "rays" not in kept:
        raise SystemExit("occtool map built no 3D map from these arguments")
    return kept["rays"]


def occtool_3d(origins: np.ndarray, ends: np.ndarray, hits: np.ndarray, groups: np.ndarray) -> int:
    """The 3D map of the rays as ``map_log_3d`` makes it; its file's bytes."""
    from occtool.fuse import build_world_map_3d, choose_resolution

    resolution, choice = choose_resolution(origins, ends, hits, groups, seed=0)
    options = {"saturation": choice["saturation"]} if "saturation" in choice else {}
    return len(build_world_map_3d(origins, ends, hits, resolution=resolution, **options).to_bytes())


def octomap(origins: np.ndarray, ends: np.ndarray, hits: np.ndarray, groups: np.ndarray, resolution: float,
            max_range: float) -> int:
    """pyoctomap's insertion of each position's rays from its origin; the tree's leaf count."""
    import pyoctomap

    tree = pyoctomap.OcTree(resolution)
    starts = np.r_[0, np.flatnonzero(np.diff(groups)) + 1, groups.size]
    for begin, end in zip(starts[:-1], starts[1:]):
        origin = origins[begin]
        beyond = origin + (ends[begin:end] - origin) * np.where(hits[begin:end], 1.0, 1.01)[:, None]
        tree.insertPointCloud(np.ascontiguousarray(beyond), np.ascontiguousarray(origin), max_range=max_range)
    return int(tree.getNumLeafNodes())


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    split = argv.index("--") if "--" in argv else len(argv)
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--max-range", type=float, required=True, help="OctoMap's max range (the bench's: 8 or 20).")
    parser.add_argument("--resolutions", type=float, nargs="+", default=[0.1, 0.05], help="OctoMap's cells.")
    parser.add_argument("--repeat", type=int, default=2, help="Runs of each; the least CPU is kept.")
    args = parser.parse_args(argv[:split])
    origins, ends, hits, groups = captured_rays(argv[split + 1:])
    # Rays of one position share its origin in every reader; pyoctomap takes one origin a call.
    starts = np.r_[0, np.flatnonzero(np.diff(groups)) + 1]
    if not all(np.all(origins[a:b] == origins[a]) for a, b in zip(starts, np.r_[starts[1:], groups.size])):
        raise SystemExit("a position's rays do not share one origin")
    jobs: list[tuple[str, Any]] = [("occtool_3d", lambda: occtool_3d(origins, ends, hits, groups))]
    jobs += [(f"octomap_{r:g}", lambda r=r: octomap(origins, ends, hits, groups, r, args.max_range))
             for r in args.resolutions]
    out: dict[str, Any] = {"rays": int(groups.size), "positions": int(groups.max()) + 1 if groups.size else 0}
    for name, job in jobs:
        best = float("inf")
        for _ in range(max(1, args.repeat)):
            started = time.process_time()
            job()
            best = min(best, time.process_time() - started)
        out[f"{name}_cpu_s"] = round(best, 3)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
