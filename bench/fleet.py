"""Fleet benchmark: every position of the six CARMEN logs in one `occtool fit` call.

The same call runs with ``-j 1``, ``-j N`` local processes and on a Dask ``LocalCluster``
this script starts (``--scheduler``). Each run's wall time, CPU time (user + system, of
the command and its worker processes) and peak RSS come from ``/usr/bin/time -v`` (the
peak is that of the largest single process, not the sum); the Dask workers' CPU time is
read from the workers themselves (psutil), the scheduler's and nannies' from this process. The
cluster is started with :data:`occtool.executor.DASK_CLUSTER_CONFIG`. The models of every run are compared with
those of ``-j 1`` outside their ``run`` object: they must be the same.

    python bench/fleet.py ../shared/data [--jobs 2] [--dask-workers 2] [--json out.json]

:func:`fleet_section` returns ``(markdown, json_dict)`` for bench/run.py.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

CARMEN_LOGS = (
    "intel_lab/intel-corrected.log.gz",
    "fr079/freiburg-079-corrected.log.gz",
    "fr_campus/freiburg-campus-corrected.log.gz",
    "aces3_austin/aces-corrected.log.gz",
    "mit_csail/csail-corrected.log.gz",
    "mit_infinite_corridor/infinite-corridor-corrected.log.gz",
)
ROOT = Path(__file__).resolve().parent.parent


def _time_v(stderr: str) -> dict[str, float]:
    """Wall, user, system seconds and peak RSS (MB) from ``/usr/bin/time -v``."""
    def field(name: str) -> str:
        match = re.search(rf"{re.escape(name)}: (.+)", stderr)
        return match.group(1).strip() if match else "nan"

    wall = field("Elapsed (wall clock) time (h:mm:ss or m:ss)")
    seconds = 0.0
    for part in wall.split(":"):
        seconds = seconds * 60 + float(part)
    return {"wall_s": seconds, "user_s": float(field("User time (seconds)")),
            "system_s": float(field("System time (seconds)")),
            "peak_rss_mb": float(field("Maximum resident set size (kbytes)")) / 1024}


def _models(folder: Path) -> dict[str, str]:
    out = {}
    for path in sorted(folder.rglob("model_*.json")):
        data = json.loads(path.read_text())
        data.pop("run", None)
        out[str(path.relative_to(folder))] = json.dumps(data, sort_keys=True)
    return out


def _run_fit(logs: list[Path], out: Path, extra: list[str], fit_args: tuple[str, ...]) -> dict[str, Any]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    command = ["/usr/bin/time", "-v", sys.executable, "-m", "occtool", "-q", "fit", *map(str, logs),
               "-o", f"{out}/", *fit_args, *extra]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False)
    figures = _time_v(done.stderr)
    figures["exit_status"] = done.returncode
    if done.returncode != 0:
        figures["error"] = done.stderr.strip().splitlines()[-1:] or ["?"]
    return figures


def fleet_section(data_dir: str | os.PathLike[str], *, jobs: int = 2, dask_workers: int = 2,
                  fit_args: tuple[str, ...] = (), keep: str | None = None) -> tuple[str, dict[str, Any]]:
    """Fit all positions of the six CARMEN logs with -j 1, -j ``jobs`` and a Dask LocalCluster.

    Returns the markdown of a results section and its figures.
    """
    data = Path(data_dir)
    logs = [data / name for name in CARMEN_LOGS if (data / name).exists()]
    results: dict[str, Any] = {"logs": [str(p.relative_to(data)) for p in logs], "fit_args": list(fit_args),
                               "runs": {}}
    if not logs:
        return "No CARMEN logs found; fleet benchmark skipped.\n", results
    with tempfile.TemporaryDirectory(dir=keep) as scratch:
        base = Path(scratch)
        runs = results["runs"]
        runs["-j 1"] = _run_fit(logs, base / "j1", ["-j", "1"], fit_args)
        runs[f"-j {jobs}"] = _run_fit(logs, base / f"j{jobs}", ["-j", str(jobs)], fit_args)
        try:
            import psutil
            from distributed import Client, LocalCluster
        except ImportError:
            runs["dask"] = {"error": "dask[distributed] is not installed (occtool[dask])"}
        else:
            import dask

            from occtool.executor import DASK_CLUSTER_CONFIG

            def cpu() -> float:
                times = psutil.Process().cpu_times()
                return times.user + times.system

            # Started as occtool documents for its fits (the workers read the settings as
            # they start); the scheduler and the nannies run in this process.
            with dask.config.set(DASK_CLUSTER_CONFIG), \
                    LocalCluster(n_workers=dask_workers, threads_per_worker=1, processes=True,
                                 dashboard_address=None) as cluster, Client(cluster) as client:
                before, scheduler_before = sum(client.run(cpu).values()), cpu()
                figures = _run_fit(logs, base / "dask", ["--scheduler", cluster.scheduler_address], fit_args)
                figures["workers_cpu_s"] = sum(client.run(cpu).values()) - before
                figures["scheduler_cpu_s"] = cpu() - scheduler_before
                figures["workers"] = dask_workers
                runs["dask"] = figures
        reference = _models(base / "j1")
        results["models"] = len(reference)
        for name, figures in runs.items():
            folder = base / {"-j 1": "j1", f"-j {jobs}": f"j{jobs}", "dask": "dask"}[name]
            if "wall_s" in figures:
                figures["identical_models"] = name == "-j 1" or _models(folder) == reference
                figures["speedup"] = runs["-j 1"]["wall_s"] / figures["wall_s"] if figures["wall_s"] else None
    lines = [
        (f"All positions of {len(logs)} CARMEN logs ({results.get('models', 0):,} models) in one "
         "`occtool fit LOG... -o DIR/` call. Wall and CPU from /usr/bin/time -v (CPU: the command and "
         "its local workers; Dask workers' CPU read from the workers, the scheduler's and nannies' not "
         "included); peak RSS of the largest process. The LocalCluster runs with "
         "`occtool.executor.DASK_CLUSTER_CONFIG`."),
        "",
        "| run | wall | CPU | peak RSS | speed-up over -j 1 | models identical to -j 1 |",
        "|---|---|---|---|---|---|",
    ]
    for name, figures in results["runs"].items():
        if "wall_s" not in figures:
            lines.append(f"| {name} | {figures.get('error', 'failed')} | | | | |")
            continue
        cpu_s = figures["user_s"] + figures["system_s"] + figures.get("workers_cpu_s", 0.0)
        lines.append(f"| {name} | {figures['wall_s']:.1f} s | {cpu_s:.1f} s | {figures['peak_rss_mb']:.0f} MB | "
                     f"{figures['speedup']:.2f}x | {'yes' if figures['identical_models'] else 'NO'} |")
    dask_run = results["runs"].get("dask", {})
    if "scheduler_cpu_s" in dask_run:
        lines += ["", f"The Dask scheduler and nannies (the bench's process) used {dask_run['scheduler_cpu_s']:.1f} s "
                  "of CPU besides."]
    return "\n".join(lines) + "\n", results


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", nargs="?", default=str(ROOT.parent / "shared" / "data"))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--dask-workers", type=int, default=2)
    parser.add_argument("--json", default=None)
    parser.add_argument("--fit-args", default="", help="further `occtool fit` options, one string")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    import shlex

    fit_args = tuple(shlex.split(args.fit_args))
    markdown, figures = fleet_section(args.data, jobs=args.jobs, dask_workers=args.dask_workers, fit_args=fit_args)
    figures["bench_seconds"] = time.perf_counter() - start
    print(markdown)
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
