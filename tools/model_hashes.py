"""sha256 of the model bytes of a fixed set of fits: a speed change must leave every one alone.

    python tools/model_hashes.py OUT.json            # fit every case, write {case: sha256}
    python tools/model_hashes.py OUT.json --check REF.json   # ... and compare with REF

The cases: the office, corridor, aisle and chairs scenes simulated at 1k, 10k and 100k
features and the office at 1M (the defaults, seed 0); a few variants at 10k (linear basis,
floor as obstacle, refit sweeps, no focus); a few positions of the CARMEN logs in
../shared/data fitted as ``occtool fit`` fits them (planar defaults,
:func:`occtool.modelset.estimator_for_log`), with and without free rays. Features are
cached under ``$TMPDIR/occtool-model-hashes`` (simulating and reading logs is not what is
timed here). The model bytes are :func:`occtool.formats.model.model_text` without a run object.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from occtool.features import Features
from occtool.fit import OccupancyRegressor
from occtool.formats.model import model_text
from occtool.sensor import SensorModel

CACHE = Path(tempfile.gettempdir()) / "occtool-model-hashes"
DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SCENES = ("office", "corridor", "aisle", "chairs")
COUNTS = (1_000, 10_000, 100_000)
CARMEN = (("intel_lab/intel-corrected.log.gz", (0, 150, 600)),
          ("fr079/freiburg-079-corrected.log.gz", (10, 300)))


def _cached(name: str, make):  # type: ignore[no-untyped-def]
    CACHE.mkdir(exist_ok=True)
    path = CACHE / f"{name}.npz"
    if not path.exists():
        features = make()
        np.savez(path, points=features.points, evidence=features.evidence)
    data = np.load(path)
    return Features(data["points"], data["evidence"])


def _simulated(scene: str, n: int) -> Features:
    from occtool.simulate import simulate_scene

    return _cached(f"{scene}_{n}", lambda: simulate_scene(scene, n_features=n, seed=0)[0])


def _carmen_cases() -> list[tuple[str, Features, OccupancyRegressor]]:
    from occtool.io import read_log
    from occtool.modelset import estimator_for_log

    cases = []
    for relative, indices in CARMEN:
        path = DATA / relative
        if not path.exists():
            print(f"skipped {relative}: not found", file=sys.stderr)
            continue
        for free in (None, 5.0):
            tag = f"{path.parent.name}{'_free' if free else ''}"
            log = None
            for index in indices:
                file = CACHE / f"{tag}_{index}.npz"
                if not file.exists():
                    log = log or read_log(str(path), no_return_range=free)
                    position = log.single(index)
                    CACHE.mkdir(exist_ok=True)
                    np.savez(file, points=position.features.points, evidence=position.features.evidence)
                data = np.load(file)
                features = Features(data["points"], data["evidence"])

                class _Position:  # what estimator_for_log reads of a position
                    pass

                item = _Position()
                item.features, item.index = features, index  # type: ignore[attr-defined]
                estimator = estimator_for_log(OccupancyRegressor(seed=0), [item], planar_defaults=True)
                cases.append((f"{tag}_{index}", features, estimator))
    return cases


def cases() -> list[tuple[str, Features, OccupancyRegressor]]:
    out = []
    for scene in SCENES:
        for n in COUNTS:
            out.append((f"{scene}_{n}", _simulated(scene, n), OccupancyRegressor(seed=0)))
    office = _simulated("office", 10_000)
    out += [("office_10000_linear", office, OccupancyRegressor(seed=0, basis="linear")),
            ("office_10000_floor", office, OccupancyRegressor(seed=0, sensor=SensorModel(floor="obstacle"))),
            ("office_10000_sweeps", office, OccupancyRegressor(seed=0, max_sweeps=2)),
            ("office_10000_nofocus", office, OccupancyRegressor(seed=0, focus=False)),
            ("chairs_1000_seed3", _simulated("chairs", 1_000), OccupancyRegressor(seed=3, pieces=16))]
    out += _carmen_cases()
    out.append(("office_1000000", _simulated("office", 1_000_000), OccupancyRegressor(seed=0)))
    return out


def main() -> None:
    target = Path(sys.argv[1])
    reference = json.loads(Path(sys.argv[3]).read_text()) if "--check" in sys.argv else None
    hashes: dict[str, str] = {}
    seconds: dict[str, float] = {}
    for name, features, estimator in cases():
        started = time.process_time()
        estimator.fit(features)
        seconds[name] = time.process_time() - started
        hashes[name] = hashlib.sha256(model_text(estimator).encode()).hexdigest()
        mark = ""
        if reference is not None:
            mark = "same" if reference.get(name) == hashes[name] else "DIFFERENT"
        print(f"{name:32s} {seconds[name]:7.3f} s  {hashes[name][:16]}  {mark}", flush=True)
    target.write_text(json.dumps(hashes, indent=1) + "\n")
    if reference is not None:
        differ = sorted(k for k in set(reference) | set(hashes) if reference.get(k) != hashes.get(k))
        print(f"{len(hashes) - len(differ)} same, {len(differ)} different: {', '.join(differ)}")
        sys.exit(1 if differ else 0)


if __name__ == "__main__":
    os.environ.setdefault("PYTHONHASHSEED", "0")
    main()
