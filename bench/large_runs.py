"""The two largest shared logs mapped by the real command: CPU, wall and peak RSS (issue 36).

``occtool map`` of the Freiburg campus and of the MIT infinite corridor (a laser 0.3 m up
on a 0.5 m robot, beams without a return clearing 5 m), each in its own process under
``/usr/bin/time -v``, then ``occtool plot map`` of each map; the targets are issue 36's:
each map in <= 1 GB of peak RSS and <= 40 s of CPU, each plot in <= 500 MB.

``python bench/large_runs.py [DATA]`` prints the table and the figures (DATA: the shared
data folder, ``../shared/data`` by default).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from fleet import ROOT, _time_v

#: The logs, as (name, folder, file) in the shared data folder.
LARGE_LOGS = (
    ("Freiburg campus", "fr_campus", "freiburg-campus-corrected.log.gz"),
    ("MIT infinite corridor", "mit_infinite_corridor", "infinite-corridor-corrected.log.gz"),
)
#: The command's options: the laser robot of bench/log_map.py, as a new user would type it.
MAP_ARGS = ("--sensor-height", "0.3", "--body-height", "0.5", "--no-return-range", "5")
#: Issue 36's targets: peak RSS and CPU of a map, peak RSS of its plot.
MAX_MAP_RSS_MB = 1024.0
MAX_MAP_CPU_S = 40.0
MAX_PLOT_RSS_MB = 500.0


def _timed(command: list[str]) -> dict[str, Any]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    done = subprocess.run(["/usr/bin/time", "-v", *command], env=env, capture_output=True, text=True, check=False)
    row: dict[str, Any] = {**_time_v(done.stderr), "exit_status": done.returncode}
    row["cpu_s"] = row["user_s"] + row["system_s"]
    if done.returncode:
        # /usr/bin/time's own lines follow the command's: its last line of its own is the error.
        own = done.stderr.split("\tCommand being timed:")[0].strip().splitlines()
        row["error"] = own[-1] if own else "?"
    return row


def large_run(log: str | Path, out: str | Path) -> dict[str, Any]:
    """``occtool map LOG -o OUT`` and ``occtool plot map OUT`` under ``/usr/bin/time -v``: each
    one's wall, CPU (user + system) and peak RSS, and from summary.json the map's stages, its
    raster and its files' sizes (and map.pgm's SHA-256, so that a change of the map shows)."""
    out = Path(out)
    row: dict[str, Any] = {"log": Path(log).name}
    row["map"] = _timed([sys.executable, "-m", "occtool", "-q", "map", str(log), "-o", str(out), *MAP_ARGS])
    if row["map"]["exit_status"] == 0:
        summary = json.loads((out / "summary.json").read_text())
        row.update(positions=summary["positions"], fit_seconds=summary.get("fit_seconds"),
                   seconds=summary.get("seconds", {}), raster_cells=summary["raster"]["rows"] * summary["raster"]["columns"],
                   world_bytes=(out / "world.occmap").stat().st_size, pgm_bytes=(out / "map.pgm").stat().st_size,
                   pgm_sha256=hashlib.sha256((out / "map.pgm").read_bytes()).hexdigest())
        row["plot"] = _timed([sys.executable, "-m", "occtool", "-q", "plot", "map", str(out),
                              "-o", str(out / "plot.png")])
    print(f"[bench] occtool map {row['log']}: {row['map']['cpu_s']:.0f} s CPU, "
          f"{row['map']['peak_rss_mb']:.0f} MB peak", flush=True)
    return row


def large_runs_section(data: str | Path = "../shared/data", *, keep: str | None = None) -> tuple[str, dict[str, Any]]:
    """Map each of :data:`LARGE_LOGS` found in ``data`` (a log missing is a note); the
    markdown table and the figures (``rows``, ``notes``, ``targets``)."""
    rows, notes = [], []
    with tempfile.TemporaryDirectory(dir=keep) as scratch:
        for n, (name, folder, file) in enumerate(LARGE_LOGS):
            log = Path(data) / folder / file
            if not log.exists():
                notes.append(f"{name}: {log} missing, not mapped")
                continue
            rows.append({"name": name, **large_run(log, Path(scratch) / f"map{n}")})
    lines = ["", "The two largest shared logs through the real command: `occtool map LOG -o DIR "
             + " ".join(MAP_ARGS) + "` and `occtool plot map DIR`, each under /usr/bin/time -v (CPU: user + system).",
             "", "| log | positions | raster cells | map CPU | map wall | map peak RSS | raster step (wall) | "
             "plot peak RSS | world.occmap | map.pgm |", "|---|---|---|---|---|---|---|---|---|---|"]
    targets = []
    for row in rows:
        run = row["map"]
        if run["exit_status"]:
            lines.append(f"| {row['name']} | failed: {run.get('error')} | | | | | | | | |")
            targets.append((f"{row['name']}: maps", "failed", False))
            continue
        plot = row.get("plot", {})
        lines.append(f"| {row['name']} | {row['positions']} | {row['raster_cells'] / 1e6:.1f} M | {run['cpu_s']:.1f} s | "
                     f"{run['wall_s']:.1f} s | {run['peak_rss_mb']:.0f} MB | {row['seconds'].get('raster', 0):.1f} s | "
                     f"{plot.get('peak_rss_mb', float('nan')):.0f} MB | {row['world_bytes'] / 1e3:.0f} KB | "
                     f"{row['pgm_bytes'] / 1e6:.1f} MB |")
        targets += [(f"{row['name']}: map peak RSS <= {MAX_MAP_RSS_MB:.0f} MB", f"{run['peak_rss_mb']:.0f} MB",
                     run["peak_rss_mb"] <= MAX_MAP_RSS_MB),
                    (f"{row['name']}: map CPU <= {MAX_MAP_CPU_S:.0f} s", f"{run['cpu_s']:.1f} s",
                     run["cpu_s"] <= MAX_MAP_CPU_S),
                    (f"{row['name']}: plot map peak RSS <= {MAX_PLOT_RSS_MB:.0f} MB",
                     f"{plot.get('peak_rss_mb', float('nan')):.0f} MB",
                     bool(plot.get("exit_status") == 0 and plot["peak_rss_mb"] <= MAX_PLOT_RSS_MB))]
    lines += [""] + [f"- {note}" for note in notes]
    return "\n".join(lines) + "\n", {"rows": rows, "notes": notes, "targets": targets}


if __name__ == "__main__":  # pragma: no cover
    markdown, figures = large_runs_section(sys.argv[1] if len(sys.argv) > 1 else "../shared/data")
    print(markdown)
    print(json.dumps(figures, indent=1, default=float))
