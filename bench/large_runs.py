"""The two largest shared logs mapped by the real command: CPU, wall and peak RSS (issue 36).

``occtool map`` of the Freiburg campus and of the MIT infinite corridor (a laser 0.3 m up
on a 0.5 m robot, beams without a return clearing 5 m), each in its own process under
``/usr/bin/time -v``, then ``occtool plot map`` of each map; the targets are issue 36's:
each map in <= 1 GB of peak RSS and <= 40 s of CPU, each plot in <= 500 MB.

Then the campus's Nav2 raster at 0.02 m (:data:`FINE_RESOLUTION`, 129 M cells) in <= 1 GB,
read back by ``occtool plot map`` in <= 500 MB (the Nav2 reader reads it decimated), and runs :data:`COPIES` times the campus (:func:`repeated_log`: the campus log's scans again,
each copy beside the last), each in <= 1 GB with CPU growing at most linearly in scans
(the exponent of a power law fitted to CPU against scans <= 1.1). These take about 17
times the campus's CPU (20 minutes and more on a 2-core machine).

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
#: The campus's raster at this cell size, metres, and its target.
FINE_RESOLUTION = 0.02
MAX_FINE_RSS_MB = 1024.0
#: Runs this many times the campus, and the targets of the largest and of the CPU's growth.
COPIES = (1, 2, 4, 10)
MAX_REPEATED_RSS_MB = 1024.0
MAX_SCAN_EXPONENT = 1.1


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


def repeated_log(log: str | Path, target: str | Path, copies: int, *, gap: float = 40.0) -> Path:
    """Write a CARMEN log of ``copies`` runs of ``log`` (a CARMEN log, gzipped or not) one
    beside the other: copy k's poses (``FLASER`` and ``ODOM`` lines) shifted along x by k
    times the log's own x extent plus ``gap`` metres (more than the walls' 16 m reach, so
    that no copy's walls meet another's), its stamps by k times the log's duration; its
    ``PARAM`` lines once. A run ``copies`` times as long over ``copies`` times the area."""
    import gzip

    opener: Any = gzip.open if str(log).endswith(".gz") else open
    with opener(log, "rt", encoding="ascii", errors="replace") as handle:
        lines = handle.read().splitlines()
    scans = [line.split() for line in lines if line.startswith("FLASER ")]
    xs = [float(f[int(f[1]) + 2]) for f in scans]
    stamps = [float(f[int(f[1]) + 8]) for f in scans]
    width = max(xs) - min(xs) + 2 * 16.0 + gap
    duration = max(stamps) - min(stamps) + 1.0
    target = Path(target)
    with open(target, "w", encoding="ascii") as out:
        out.writelines(line + "\n" for line in lines if line.startswith("PARAM "))
        for k in range(copies):
            for f in scans:
                n = int(f[1])
                moved = list(f)
                for at in (n + 2, n + 5):  # x of the corrected pose and of the odometry
                    moved[at] = f"{float(f[at]) + k * width:.6f}"
                for at in (n + 8, n + 10):  # the stamp and the logger's stamp
                    moved[at] = f"{float(f[at]) + k * duration:.6f}"
                out.write(" ".join(moved) + "\n")
    return target


def _exponent(scans: list[float], seconds: list[float]) -> float:
    """The exponent b of seconds = a * scans ** b fitted in log-log (least squares)."""
    import math

    x = [math.log(v) for v in scans]
    y = [math.log(v) for v in seconds]
    mx, my = sum(x) / len(x), sum(y) / len(y)
    return sum((a - mx) * (b - my) for a, b in zip(x, y)) / sum((a - mx) ** 2 for a in x)


def large_run(log: str | Path, out: str | Path, *extra: str, plot: bool = True) -> dict[str, Any]:
    """``occtool map LOG -o OUT`` and ``occtool plot map OUT`` under ``/usr/bin/time -v``: each
    one's wall, CPU (user + system) and peak RSS, and from summary.json the map's stages, its
    raster and its files' sizes (and map.pgm's SHA-256, so that a change of the map shows)."""
    out = Path(out)
    row: dict[str, Any] = {"log": Path(log).name}
    row["map"] = _timed([sys.executable, "-m", "occtool", "-q", "map", str(log), "-o", str(out), *MAP_ARGS, *extra])
    if row["map"]["exit_status"] == 0:
        summary = json.loads((out / "summary.json").read_text())
        row.update(positions=summary["positions"], fit_seconds=summary.get("fit_seconds"),
                   seconds=summary.get("seconds", {}), raster_cells=summary["raster"]["rows"] * summary["raster"]["columns"],
                   world_bytes=(out / "world.occmap").stat().st_size, pgm_bytes=(out / "map.pgm").stat().st_size,
                   pgm_sha256=hashlib.sha256((out / "map.pgm").read_bytes()).hexdigest())
        if plot:
            row["plot"] = _timed([sys.executable, "-m", "occtool", "-q", "plot", "map", str(out),
                                  "-o", str(out / "plot.png")])
    print(f"[bench] occtool map {row['log']}: {row['map']['cpu_s']:.0f} s CPU, "
          f"{row['map']['peak_rss_mb']:.0f} MB peak", flush=True)
    return row


def scaled_runs(campus: str | Path, scratch: str | Path, copies: tuple[int, ...] = COPIES, *,
                fine: bool = True) -> dict[str, Any]:
    """The campus's raster at :data:`FINE_RESOLUTION` (``fine``), and the campus ``copies``
    times over (``repeated``: :func:`repeated_log`), each mapped by the command under
    ``/usr/bin/time -v``; ``exponent``: CPU's power law in scans over the repeated runs."""
    scratch = Path(scratch)
    fine_run = large_run(campus, scratch / "fine", "--resolution", str(FINE_RESOLUTION)) if fine else None
    repeated = []
    for k in copies:
        log = repeated_log(campus, scratch / f"campus-x{k}.log", k)
        repeated.append({"copies": k, **large_run(log, scratch / f"x{k}", plot=False)})
        log.unlink()
        print(f"[bench] campus x{k}: {repeated[-1]['map']['cpu_s']:.0f} s CPU", flush=True)
    done = [r for r in repeated if r["map"]["exit_status"] == 0]
    # Scans grow as the copies, exactly (the summary's positions are the fused keyframes).
    exponent = (_exponent([r["copies"] for r in done], [r["map"]["cpu_s"] for r in done])
                if len(done) >= 2 else float("nan"))
    return {"fine": fine_run, "repeated": repeated, "exponent": exponent}


def _scaled_lines(scaled: dict[str, Any]) -> tuple[list[str], list[Any]]:
    fine, repeated = scaled["fine"], scaled["repeated"]
    lines = ["", f"The campus's Nav2 raster at {FINE_RESOLUTION} m (`--resolution {FINE_RESOLUTION}`), "
             "and the campus repeated side by side (bench/large_runs.repeated_log: each copy's poses moved along x "
             "by the campus's width and 72 m, its stamps after the last copy's), each under /usr/bin/time -v.",
             "", "| run | fused positions | raster cells | CPU | wall | peak RSS |", "|---|---|---|---|---|---|"]
    targets: list[Any] = []
    runs = [(f"campus at {FINE_RESOLUTION} m", fine)] if fine is not None else []
    for name, row in runs + [(f"campus x{r['copies']}", r) for r in repeated]:
        run = row["map"]
        if run["exit_status"]:
            lines.append(f"| {name} | failed: {run.get('error')} | | | | |")
            continue
        lines.append(f"| {name} | {row['positions']} | {row['raster_cells'] / 1e6:.1f} M | {run['cpu_s']:.1f} s | "
                     f"{run['wall_s']:.1f} s | {run['peak_rss_mb']:.0f} MB |")
    if fine is not None:
        run = fine["map"]
        targets.append((f"campus at {FINE_RESOLUTION} m: Nav2 raster in <= {MAX_FINE_RSS_MB:.0f} MB peak RSS",
                        "failed" if run["exit_status"] else f"{run['peak_rss_mb']:.0f} MB "
                        f"({fine['raster_cells'] / 1e6:.0f} M cells)",
                        not run["exit_status"] and run["peak_rss_mb"] <= MAX_FINE_RSS_MB))
        plot = fine.get("plot", {})
        targets.append((f"campus at {FINE_RESOLUTION} m: plot map reads it back in <= {MAX_PLOT_RSS_MB:.0f} MB",
                        f"{plot.get('peak_rss_mb', float('nan')):.0f} MB" if plot.get("exit_status") == 0 else "failed",
                        bool(plot.get("exit_status") == 0 and plot["peak_rss_mb"] <= MAX_PLOT_RSS_MB)))
    largest = repeated[-1]
    run = largest["map"]
    targets.append((f"campus x{largest['copies']}: map peak RSS <= {MAX_REPEATED_RSS_MB:.0f} MB",
                    "failed" if run["exit_status"] else f"{run['peak_rss_mb']:.0f} MB",
                    not run["exit_status"] and run["peak_rss_mb"] <= MAX_REPEATED_RSS_MB))
    exponent = scaled["exponent"]
    targets.append((f"CPU against scans (campus x{', x'.join(str(r['copies']) for r in repeated)}): "
                    f"exponent <= {MAX_SCAN_EXPONENT}", f"{exponent:.2f}", exponent <= MAX_SCAN_EXPONENT))
    lines += ["", f"CPU against scans: fitted exponent {exponent:.2f}."]
    return lines, targets


def large_runs_section(data: str | Path = "../shared/data", *, keep: str | None = None,
                       copies: tuple[int, ...] = COPIES) -> tuple[str, dict[str, Any]]:
    """Map each of :data:`LARGE_LOGS` found in ``data`` (a log missing is a note), then the
    campus's fine raster and its repeated runs (:func:`scaled_runs`); the markdown table
    and the figures (``rows``, ``scaled``, ``notes``, ``targets``)."""
    rows, notes = [], []
    scaled = None
    with tempfile.TemporaryDirectory(dir=keep) as scratch:
        for n, (name, folder, file) in enumerate(LARGE_LOGS):
            log = Path(data) / folder / file
            if not log.exists():
                notes.append(f"{name}: {log} missing, not mapped")
                continue
            rows.append({"name": name, **large_run(log, Path(scratch) / f"map{n}")})
        campus = Path(data) / LARGE_LOGS[0][1] / LARGE_LOGS[0][2]
        if campus.exists():
            scaled = scaled_runs(campus, scratch, copies)
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
    if scaled is not None:
        more, scaled_targets = _scaled_lines(scaled)
        lines += more
        targets += scaled_targets
    lines += [""] + [f"- {note}" for note in notes]
    return "\n".join(lines) + "\n", {"rows": rows, "scaled": scaled, "notes": notes, "targets": targets}


if __name__ == "__main__":  # pragma: no cover
    if len(sys.argv) > 2 and sys.argv[1] == "--scaled":  # python bench/large_runs.py --scaled DATA [COPIES,... [nofine]]
        campus_log = Path(sys.argv[2]) / LARGE_LOGS[0][1] / LARGE_LOGS[0][2]
        counts = tuple(int(k) for k in sys.argv[3].split(",")) if len(sys.argv) > 3 else COPIES
        with tempfile.TemporaryDirectory() as scratch_folder:
            scaled_figures = scaled_runs(campus_log, scratch_folder, counts, fine="nofine" not in sys.argv[4:])
        print("\n".join(_scaled_lines(scaled_figures)[0]))
        print(json.dumps(scaled_figures, indent=1, default=float))
        sys.exit(0)
    markdown, figures = large_runs_section(sys.argv[1] if len(sys.argv) > 1 else "../shared/data")
    print(markdown)
    print(json.dumps(figures, indent=1, default=float))
