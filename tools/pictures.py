"""Redraw the pictures in docs/images/ from occtool's current outputs (issue 38).

Each picture is made by the commands the README and docs/*.md show for it, run here
with ``python -m occtool`` in a temporary folder, the last of them ``occtool plot ...``
into ``docs/images/NAME.png``. The commands live in one table, ``PICTURES``, so they can
be read beside the docs' (``--list`` prints them); pictures that do not come from
occtool's outputs are in ``NOT_OURS`` with the reason.

    python tools/pictures.py                 # every picture (minutes: Intel, CCNY, MINES)
    python tools/pictures.py --only cabinet-map
    python tools/pictures.py --list          # each picture and its commands, nothing run

Paths in the table are written with three placeholders: ``{fixtures}`` (the repo's
bundled data), ``{data}`` (the shared data sets, ``../shared/data`` beside the repo, or
``--data DIR``) and ``{images}`` (docs/images/). Every other relative path lands in the temporary folder.
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
IMAGES = REPO / "docs" / "images"
PLACES = {
    "fixtures": REPO / "fixtures",
    "data": REPO.parent / "shared" / "data",
    "images": IMAGES,
}

# name -> the occtool commands (argv after `occtool`) that make docs/images/NAME.png,
# as the doc named in the comment shows them.
PICTURES: dict[str, list[list[str]]] = {
    # README "First session" / Makefile `demo`, docs/plotting.md: the paper's Figure 5.
    "fig5a-features": [
        ["plot", "features", "{fixtures}/office/features.csv", "-o", "{images}/fig5a-features.png"],
    ],
    "fig5b-model": [
        ["fit", "{fixtures}/office/features.csv", "-o", "model.json"],
        ["plot", "model", "model.json", "-o", "{images}/fig5b-model.png", "--pieces"],
    ],
    "fig5c-navigation": [
        ["fit", "{fixtures}/office/features.csv", "-o", "model.json"],
        ["extract", "model.json", "-o", "nav.geojson", "--slices"],
        ["plot", "nav", "nav.geojson", "--features", "{fixtures}/office/features.csv",
         "--truth", "{fixtures}/office/truth.json", "-o", "{images}/fig5c-navigation.png"],
    ],
    # README "A laser log to a Nav2 map" (docs/map.md the same without the data path).
    "intel-map": [
        ["map", "{data}/intel_lab/intel-corrected.log.gz", "-o", "intel-map/",
         "--sensor-height", "0.3", "--body-height", "0.5", "--no-return-range", "5"],
        ["plot", "map", "intel-map/", "-o", "{images}/intel-map.png"],
    ],
    # README "A depth-camera folder".
    "cabinet-map": [
        ["map", "{fixtures}/tum-fr3-cabinet/depth.txt", "-o", "cabinet-map/",
         "--sensor-height", "0.95"],
        ["plot", "map", "cabinet-map/", "-o", "{images}/cabinet-map.png", "--walls"],
    ],
    # README "A bag without poses", docs/map.md, docs/register.md.
    "ccny-registered-map": [
        ["map", "{data}/ccny_hokuyo_bag/demo_ros2_converted.mcap", "-o", "ccny-map/",
         "--sensor-height", "0.3", "--body-height", "0.5"],
        ["plot", "map", "ccny-map/", "-o", "{images}/ccny-registered-map.png"],
    ],
    # docs/register.md: the MINES log registered from its wheel odometry (the default) ...
    "mines-registered-map": [
        ["map", "{data}/mines_paristech_urg/exp1.dat", "-o", "mines-map/",
         "--sensor-height", "0.3", "--body-height", "0.5"],
        ["plot", "map", "mines-map/", "-o", "{images}/mines-registered-map.png"],
    ],
    # ... and on that odometry as it is (`--no-register`).
    "mines-odometry-map": [
        ["map", "{data}/mines_paristech_urg/exp1.dat", "-o", "mines-odometry-map/",
         "--sensor-height", "0.3", "--body-height", "0.5", "--no-register"],
        ["plot", "map", "mines-odometry-map/", "-o", "{images}/mines-odometry-map.png"],
    ],
}

# Pictures under docs/images/ this script does not draw, and why (none at present: bench
# plots such as bench/*.png live beside the bench and are drawn by bench/run.py, and
# hand-made diagrams would be drawn by hand). A new one goes here or into PICTURES;
# tests/test_pictures.py fails on an image in neither.
NOT_OURS: dict[str, str] = {}


def expand(argv: list[str]) -> list[str]:
    """The command with its placeholders replaced by real paths."""
    return [arg.format(**{k: str(v) for k, v in PLACES.items()}) for arg in argv]


def show(argv: list[str]) -> str:
    """The command as one shell line, placeholders kept, to compare with the docs."""
    # Quote only what a shell would split; the {placeholders} stay readable.
    return "occtool " + " ".join(a if not set(a) & set(" '\"$;&|") else shlex.quote(a)
                                 for a in argv)


def redraw(name: str) -> float:
    """Run NAME's commands in a fresh temporary folder; the seconds they took."""
    env = dict(os.environ)
    # Run this tree's occtool whatever is installed, so a branch redraws its own outputs.
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix=f"pictures-{name}-") as tmp:
        for argv in PICTURES[name]:
            print(f"[{name}] {show(argv)}", flush=True)
            subprocess.run([sys.executable, "-m", "occtool", *expand(argv)],
                           cwd=tmp, env=env, check=True)
    return time.perf_counter() - start


def main(args: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", action="append", metavar="NAME", choices=sorted(PICTURES),
                        help="redraw this picture only (repeatable)")
    parser.add_argument("--data", type=Path, metavar="DIR",
                        help="the shared data sets (default: ../shared/data beside the repo)")
    parser.add_argument("--list", action="store_true",
                        help="print each picture and its commands; run nothing")
    opts = parser.parse_args(args)
    names = opts.only or list(PICTURES)
    if opts.data is not None:
        PLACES["data"] = opts.data.resolve()
    if opts.list:
        for name in names:
            print(f"{name}.png")
            for argv in PICTURES[name]:
                print(f"    {show(argv)}")
        for name, why in NOT_OURS.items():
            print(f"{name}: not drawn here: {why}")
        return 0
    missing = [n for n in names if any("{data}" in a for argv in PICTURES[n] for a in argv)
               and not PLACES["data"].is_dir()]
    if missing:
        parser.error(f"{PLACES['data']} not found, needed by: {', '.join(missing)}")
    for name in names:
        print(f"[{name}] done in {redraw(name):.1f} s -> docs/images/{name}.png", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
