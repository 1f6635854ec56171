"""What a fresh process pays: one `occtool fit` of 10k features, and the first fit in a
process against the second (issue 21, item 1).

``occtool fit FEATURES.csv -o model.json`` runs ``RUNS`` times as a child process; its CPU
time (user + system, interpreter start included) and peak RSS are the operating system's
accounting of the finished child as ``/usr/bin/time -v`` reports it (from inside bench/run.py,
whose process holds hundreds of MB, ``getrusage(RUSAGE_CHILDREN)`` charged the fork from it to the
child: 0.39-0.44 s against 0.27-0.29 s from a small parent). One run before
them is not counted: it writes the bytecode cache, as installing a package does (the
environment's ``PYTHONDONTWRITEBYTECODE`` is dropped for these children). The first and
second fit come from ``RUNS`` other fresh processes that read the features and fit them
twice (process CPU time of each fit).

    python bench/cold_start.py

:func:`cold_start_section` returns ``(markdown, json_dict)`` for bench/run.py.
"""

from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
FEATURES = 10_000
RUNS = 7
TIME = "/usr/bin/time"

TWO_FITS = """
import sys, time
from occtool.io import read_log
features = read_log(sys.argv[1]).single().features
from occtool.fit import OccupancyRegressor
seconds = []
for _ in range(2):
    started = time.process_time()
    OccupancyRegressor(seed=0).fit(features)
    seconds.append(time.process_time() - started)
print(*seconds)
"""


def _environment() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _child_cost(command: list[str], env: dict[str, str]) -> tuple[float, float, float]:
    """CPU seconds, wall seconds and peak RSS (MB) of one child run of ``command``, as
    ``/usr/bin/time -v`` reports them: a small process starts the command, so neither the
    CPU of copying a large parent's page tables (bench/run.py holds hundreds of MB when it
    gets here) nor its resident pages are charged to the command. Without ``time``: the
    operating system's accounting of this process's children."""
    if Path(TIME).is_file():
        from fleet import _time_v  # the bench's one reader of /usr/bin/time -v

        wall = time.perf_counter()
        done = subprocess.run([TIME, "-v", *command], check=True, capture_output=True, text=True, env=env, cwd=ROOT)
        wall = time.perf_counter() - wall
        figures = _time_v(done.stderr)
        return figures["user_s"] + figures["system_s"], wall, figures["peak_rss_mb"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall = time.perf_counter()
    subprocess.run(command, check=True, capture_output=True, env=env, cwd=ROOT)
    wall = time.perf_counter() - wall
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, after.ru_maxrss / 1024  # the largest child so far


def cold_start_section(runs: int = RUNS) -> tuple[str, dict[str, Any]]:
    """The section's markdown and figures for bench/run.py."""
    env = _environment()
    with tempfile.TemporaryDirectory() as folder:
        subprocess.run([sys.executable, "-m", "occtool", "simulate", "office", "-o", folder,
                        "--features", str(FEATURES), "--seed", "1"], check=True, capture_output=True, env=env, cwd=ROOT)
        csv = str(Path(folder) / "features.csv")
        command = [sys.executable, "-m", "occtool", "fit", csv, "-o", str(Path(folder) / "model.json")]
        _child_cost(command, env)  # writes the bytecode cache; not counted
        costs = [_child_cost(command, env) for _ in range(runs)]
        fits = []
        for _ in range(runs):
            out = subprocess.run([sys.executable, "-c", TWO_FITS, csv], check=True, capture_output=True, text=True,
                                 env=env, cwd=ROOT).stdout.split()
            fits.append((float(out[0]), float(out[1])))
    cpu = [c for c, _, _ in costs]
    wall = [w for _, w, _ in costs]
    ratios = [first / second for first, second in fits]
    data = {
        "features": FEATURES, "runs": runs,
        "fit_command_cpu_s": {"median": statistics.median(cpu), "min": min(cpu), "max": max(cpu)},
        "fit_command_wall_s": {"median": statistics.median(wall), "min": min(wall), "max": max(wall)},
        "fit_command_peak_rss_mb": max(p for _, _, p in costs),
        "first_fit_s": statistics.median(f for f, _ in fits), "second_fit_s": statistics.median(s for _, s in fits),
        "first_over_second": {"median": statistics.median(ratios), "min": min(ratios), "max": max(ratios)},
    }
    c, w, r = data["fit_command_cpu_s"], data["fit_command_wall_s"], data["first_over_second"]
    markdown = "\n".join([
        f"`occtool fit features.csv -o model.json`, {FEATURES:,} office features (seed 1), {runs} fresh processes "
        "after one that writes the bytecode cache; CPU is user + system of the whole process, interpreter start "
        "included.", "",
        "| | median | min | max |", "|---|---|---|---|",
        f"| fit command, CPU s | {c['median']:.3f} | {c['min']:.3f} | {c['max']:.3f} |",
        f"| fit command, wall s | {w['median']:.3f} | {w['min']:.3f} | {w['max']:.3f} |",
        f"| first fit / second fit in one process | {r['median']:.2f} | {r['min']:.2f} | {r['max']:.2f} |", "",
        f"Peak RSS of the fit command {data['fit_command_peak_rss_mb']:.0f} MB (the largest of its runs, `/usr/bin/time -v`); "
        f"first fit {1000 * data['first_fit_s']:.0f} ms, second {1000 * data['second_fit_s']:.0f} ms of CPU (medians).",
    ])
    return markdown, data


def cold_start_targets(data: dict[str, Any] | None) -> list[tuple[str, str, bool | None]]:
    """Issue 21's targets for a fresh process, for the bench's table of targets."""
    if not data:
        return []
    cpu, ratio = data["fit_command_cpu_s"]["median"], data["first_over_second"]["median"]
    return [(f"A fresh `occtool fit` of {data['features']:,} features <= 0.3 s of CPU (whole process, median)",
             f"{cpu:.3f} s", cpu <= 0.3),
            ("First fit in a process <= 1.3x the second (median)", f"{ratio:.2f}x", ratio <= 1.3)]


if __name__ == "__main__":
    started = time.perf_counter()
    text, _ = cold_start_section()
    print(text)
    print(f"\n{time.perf_counter() - started:.0f} s", file=sys.stderr)
