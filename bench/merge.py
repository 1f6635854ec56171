"""Four robots, one map: ``occtool merge`` against mapping the union of their scans (issue 36).

A CARMEN log's training scans (bench/heldout.py's split: 10 % of the scans held out in
blocks of 40, seed 0) are cut into four time-contiguous quarters, as if four robots had
each driven a quarter of the run; each quarter is mapped on its own by the real command
(``python -m occtool -q map QUARTER.log -o DIR`` with bench/heldout.py's options), the
four ``world.occmap`` files are merged by the real ``occtool merge``, and the merged map
is scored against the single run over all the training scans by bench/heldout.py's
independent scorer, on the same held-out test points (returns occupied, points along the
beams free). The merge is also timed, and checked to give the same bytes for every order
of its four inputs.

Standalone (not part of ``make bench``): ``python bench/merge.py [--log PATH]
[--seed 0] [--keep DIR] [-o merge.md]``; it writes a markdown table.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from heldout import _time_v, fused_row, run_map, split_log  # noqa: E402

DEFAULT_LOG = ROOT.parent / "shared" / "data" / "intel_lab" / "intel-corrected.log.gz"
#: Robots the training scans are shared among, each a time-contiguous part.
ROBOTS = 4


def _write_log(path: Path, lines: list[str], title: str) -> None:
    path.write_text(f"# {title}\n" + "\n".join(lines) + "\n", encoding="ascii")


def _merge(inputs: list[Path], out: Path) -> dict[str, Any]:
    """``python -m occtool -q merge INPUTS -o OUT`` under /usr/bin/time -v."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    timer = ["/usr/bin/time", "-v"] if Path("/usr/bin/time").is_file() else []
    command = [sys.executable, "-m", "occtool", "-q", "merge", *map(str, inputs), "-o", str(out)]
    started = time.perf_counter()
    done = subprocess.run(timer + command, env=env, capture_output=True, text=True, check=False)
    row: dict[str, Any] = {"exit_status": done.returncode, "wall_s": time.perf_counter() - started,
                           **(_time_v(done.stderr) if timer else {})}
    if done.returncode:
        row["error"] = (done.stderr.strip().splitlines() or ["?"])[-1]
    return row


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def score_merge(log: str | os.PathLike[str], *, seed: int = 0, robots: int = ROBOTS,
                keep: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """The single run, each robot's map and the merged map, scored on the same held-out points."""
    scans, test, train, occupied, free = split_log(log, seed)
    xy = np.concatenate([occupied, free])
    n = len(occupied)
    scratch = Path(keep) if keep is not None else Path(tempfile.mkdtemp(prefix="merge-"))
    scratch.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    try:
        whole = scratch / "train.log"
        if not (scratch / "single" / "world.occmap").is_file():
            _write_log(whole, train.lines, f"{len(train)} training scans of {Path(log).name} (seed {seed})")
            command = run_map(whole, scratch / "single")
            if command["exit_status"]:
                raise SystemExit(f"occtool map failed on the training scans: {command.get('error')}")
        rows.append({"name": "single run (all training scans)", "scans": len(train),
                     **fused_row(scratch / "single", xy, n)})
        # Time-contiguous parts of the training scans: robot k drove scans [cut k, cut k+1).
        cuts = np.linspace(0, len(train), robots + 1).round().astype(int)
        parts = []
        for k in range(robots):
            part = scratch / f"robot{k + 1}"
            if not (part / "world.occmap").is_file():
                lines = train.lines[cuts[k]:cuts[k + 1]]
                _write_log(scratch / f"robot{k + 1}.log", lines, f"robot {k + 1} of {robots}: {len(lines)} scans")
                command = run_map(scratch / f"robot{k + 1}.log", part)
                if command["exit_status"]:
                    raise SystemExit(f"occtool map failed on robot {k + 1}'s scans: {command.get('error')}")
            parts.append(part / "world.occmap")
            rows.append({"name": f"robot {k + 1} alone", "scans": int(cuts[k + 1] - cuts[k]), **fused_row(part, xy, n)})
        merged = scratch / "merged"
        merged.mkdir(exist_ok=True)
        timing = _merge(parts, merged / "world.occmap")
        if timing["exit_status"]:
            raise SystemExit(f"occtool merge failed: {timing.get('error')}")
        rows.append({"name": f"merged ({robots} robots, occtool merge)", "scans": len(train),
                     **fused_row(merged, xy, n)})
        # Merged in pairs first, merge(merge(1, 2), merge(3, 4)): nested merges differ in a few
        # segments and the region's snap rounding (docs/map.md, "Merging maps").
        half = len(parts) // 2
        for name, group in (("pairs-a", parts[:half]), ("pairs-b", parts[half:])):
            (scratch / name).mkdir(exist_ok=True)
            done = _merge(group, scratch / name / "world.occmap")
            if done["exit_status"]:
                raise SystemExit(f"occtool merge failed: {done.get('error')}")
        (scratch / "nested").mkdir(exist_ok=True)
        done = _merge([scratch / "pairs-a" / "world.occmap", scratch / "pairs-b" / "world.occmap"],
                      scratch / "nested" / "world.occmap")
        if done["exit_status"]:
            raise SystemExit(f"occtool merge failed: {done.get('error')}")
        rows.append({"name": "merged in pairs, merge(merge(1, 2), merge(3, 4))", "scans": len(train),
                     **fused_row(scratch / "nested", xy, n)})
        nested_same = _digest(scratch / "nested" / "world.occmap") == _digest(merged / "world.occmap")
        # The single run's map merged alone: what the merge's own dropping of covered segments does.
        (scratch / "single-merged").mkdir(exist_ok=True)
        done = _merge([scratch / "single" / "world.occmap"], scratch / "single-merged" / "world.occmap")
        if done["exit_status"]:
            raise SystemExit(f"occtool merge failed: {done.get('error')}")
        rows.append({"name": "single run's map merged alone (its covered segments dropped)", "scans": len(train),
                     **fused_row(scratch / "single-merged", xy, n)})
        # Every order of the inputs gives the same bytes.
        digests = set()
        for order in itertools.permutations(parts):
            again = scratch / "merged-order.occmap"
            done = _merge(list(order), again)
            if done["exit_status"]:
                raise SystemExit(f"occtool merge failed: {done.get('error')}")
            digests.add(_digest(again))
        same_bytes = digests == {_digest(merged / "world.occmap")}
    finally:
        if keep is None:
            shutil.rmtree(scratch, ignore_errors=True)
    return {"log": Path(log).name, "seed": seed, "scans": len(scans), "held_out_scans": int(test.sum()),
            "occupied_points": n, "free_points": len(free), "robots": robots, "rows": rows, "merge": timing,
            "orders": len(list(itertools.permutations(range(robots)))), "same_bytes_every_order": same_bytes,
            "nested_same_bytes": nested_same}


def markdown(result: dict[str, Any]) -> str:
    """The table of :func:`score_merge` and the issue's target."""
    rows = {row["name"]: row for row in result["rows"]}
    single = result["rows"][0]
    merged = rows[f"merged ({result['robots']} robots, occtool merge)"]
    timing = result["merge"]
    lines = [f"**{result['log']}**, seed {result['seed']}: {result['held_out_scans']} of {result['scans']} scans held "
             f"out in blocks of 40 (bench/heldout.py); {result['occupied_points']:,} returns and "
             f"{result['free_points']:,} free points. The training scans cut into {result['robots']} time-contiguous "
             "quarters, each mapped by `occtool map` on its own, merged by `occtool merge`.", "",
             "| map | training scans | held-out AUC | world.occmap bytes |", "|---|---|---|---|"]
    for name, row in rows.items():
        auc = "not available" if row["auc"] is None else f"{row['auc']:.4f}"
        lines.append(f"| {name} | {row['scans']} | {auc} | {row['bytes'] / 1e3:.1f} KB |")
    ok_auc = merged["auc"] is not None and single["auc"] is not None and (
        merged["auc"] >= single["auc"] - 0.005 and merged["auc"] >= 0.95)
    ok_bytes = merged["bytes"] <= 1.1 * single["bytes"]
    lines += ["", f"- merged - single AUC: {merged['auc'] - single['auc']:+.4f} (target: within 0.005 and >= 0.95: "
              f"{'met' if ok_auc else 'NOT met'})",
              f"- merged / single bytes: {merged['bytes'] / single['bytes']:.3f} (target <= 1.1: "
              f"{'met' if ok_bytes else 'NOT met'})",
              f"- same bytes for all {result['orders']} orders of the inputs: "
              f"{'yes' if result['same_bytes_every_order'] else 'NO'}",
              "- merged in pairs first, the same bytes as merged at once: "
              f"{'yes' if result['nested_same_bytes'] else 'no (a few segments and the region differ; its AUC above)'}",
              f"- `occtool merge` of the {result['robots']} maps: {timing['wall_s']:.2f} s wall"
              + (f", {timing['user_s'] + timing['system_s']:.2f} s CPU, peak RSS {timing['peak_rss_kb'] / 1024:.0f} MB"
                 if "user_s" in timing else "")]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--log", default=str(DEFAULT_LOG), help="A CARMEN log with corrected poses (default: Intel).")
    parser.add_argument("--seed", type=int, default=0, help="Seed of the held-out blocks.")
    parser.add_argument("--robots", type=int, default=ROBOTS, help="Time-contiguous parts of the training scans.")
    parser.add_argument("--keep", help="Keep (and reuse) the logs and maps in this folder.")
    parser.add_argument("-o", "--output", help="Write the markdown table here (default: stdout).")
    parser.add_argument("--json", help="Write the figures here as JSON.")
    args = parser.parse_args(argv)
    result = score_merge(args.log, seed=args.seed, robots=args.robots, keep=args.keep)
    text = "## Four robots, one map (bench/merge.py)\n\n" + markdown(result)
    if args.output:
        Path(args.output).write_text(text, encoding="utf-8")
    else:
        print(text)
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
