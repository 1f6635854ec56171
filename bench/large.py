"""One robot position with a million and ten million features: fit CPU time and peak memory.

Each count is fitted in a fresh Python process (``python bench/large.py --child FILE``), so
its peak RSS is the fit's own plus the features it holds, read from a ``.npy`` file. Ten
million features are the office's million simulated features ten times over, each copy
jittered by 2 mm (simulating ten million camera rays would take minutes for the same kind
of data).
"""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

#: Feature counts of the section.
LARGE_COUNTS = (1_000_000, 10_000_000)


def _features(n: int, folder: Path) -> Path:
    from occtool.simulate import simulate_scene

    base, _ = simulate_scene("office", n_features=min(n, 1_000_000), seed=0)
    points, evidence = base.points, base.evidence
    copies = -(-n // len(base))
    if copies > 1:
        rng = np.random.default_rng(0)
        points = np.concatenate([points + rng.normal(0.0, 0.002, points.shape) for _ in range(copies)])[:n]
        evidence = np.tile(evidence, copies)[:n]
    path = folder / f"features_{n}.npy"
    np.save(path, np.column_stack([points, evidence]))
    return path


def _child(path: str) -> None:
    from occtool.features import Features
    from occtool.fit import OccupancyRegressor

    data = np.load(path)
    features = Features(data[:, :3], data[:, 3])
    del data
    # A small fit first, so the timed one does not pay for imports (scipy.spatial, ...).
    OccupancyRegressor(seed=0).fit(features.select(np.arange(min(len(features), 2000))))
    loaded = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    started = time.process_time()
    wall = time.perf_counter()
    model = OccupancyRegressor(seed=0).fit(features)
    print(f"{time.process_time() - started} {time.perf_counter() - wall} {loaded} {model.n_samples_}")


def large_section() -> list[dict[str, Any]]:
    """Fit CPU, wall time and peak RSS of one position per count in :data:`LARGE_COUNTS`."""
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for n in LARGE_COUNTS:
            path = _features(n, Path(folder))
            before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
            output = subprocess.run([sys.executable, __file__, "--child", str(path)], check=True,
                                    capture_output=True, text=True).stdout.split()
            peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
            cpu, wall, loaded, samples = (float(v) for v in output)
            rows.append({"features": n, "fit_cpu_s": cpu, "fit_wall_s": wall, "samples": int(samples),
                         "rss_with_features_mb": loaded,
                         # ru_maxrss of children is the largest child so far: grows with the counts.
                         "peak_rss_mb": max(peak, before) / 1024})
            path.unlink()
            print(f"[bench] large position {n:,}: fit {cpu:.1f} s CPU, peak {rows[-1]['peak_rss_mb']:.0f} MB", flush=True)
    return rows


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        _child(sys.argv[2])
    else:
        for row in large_section():
            print(row)
