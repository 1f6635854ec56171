"""Model sets: fitting and extracting many positions and logs, in parallel, resumable."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.fit import OccupancyRegressor
from occtool.formats.model import (
    RUN_PLACEHOLDER,
    load_model,
    model_text,
    with_run,
)
from occtool.modelset import (
    extract_model_set,
    find_model_sets,
    fit_model_set,
    log_set_name,
    read_model_set,
)

ROOT = Path(__file__).resolve().parent.parent


def write_log(path: Path, positions: int, *, floor_only: tuple[int, ...] = (), seed: int = 0, n: int = 300) -> Path:
    """A CSV log of ``positions`` robot positions in a round room 1.5 m across."""
    rng = np.random.default_rng(seed)
    lines = ["x,y,z,m,position,pose_x,pose_y,pose_yaw"]
    for position in range(positions):
        a = rng.uniform(-np.pi, np.pi, n)
        radius = 1.2 + 0.1 * position
        z = np.full(n, -0.99) if position in floor_only else rng.uniform(-0.9, 0.3, n)
        for ai, zi in zip(a, z):
            lines.append(f"{float(radius * np.cos(ai))!r},{float(radius * np.sin(ai))!r},{float(zi)!r},0.9,"
                         f"{position},{position * 0.5},0.0,0.0")
    path.write_text("\n".join(lines) + "\n")
    return path


def models_without_run(folder: Path) -> dict[str, dict]:
    out = {}
    for path in sorted(folder.rglob("model_*.json")):
        data = json.loads(path.read_text())
        data.pop("run")
        out[str(path.relative_to(folder))] = data
    return out


def no_temp_files(folder: Path) -> bool:
    return not [p for p in folder.rglob("*") if p.name.startswith(".") and p.name.endswith(".tmp")]


def run(*args: str, input: bytes | None = None):
    return CliRunner().invoke(cli, list(args), input=input)


ESTIMATOR = OccupancyRegressor(pieces=8, seed=1)


def test_jobs_1_and_2_give_the_same_models_and_a_complete_index(tmp_path):
    log = write_log(tmp_path / "room.csv", 4)
    one = fit_model_set(log, tmp_path / "one", estimator=ESTIMATOR, jobs=1)
    two = fit_model_set(log, tmp_path / "two", estimator=ESTIMATOR, jobs=2)
    assert one.done == two.done == 4 and not one.failures
    models = models_without_run(tmp_path / "one")
    assert len(models) == 4 and models == models_without_run(tmp_path / "two")
    index = json.loads((tmp_path / "two" / "index.json").read_text())
    assert index["complete"] is True and index["failed"] == []
    assert [m["position"] for m in index["models"]] == [0, 1, 2, 3]
    assert all(len(m["features_sha256"]) == 64 for m in index["models"])


def test_progress_counts_every_position_of_every_log(tmp_path):
    logs = [write_log(tmp_path / "a.csv", 2), write_log(tmp_path / "b.csv", 3, seed=2)]
    events = []
    summary = fit_model_set(logs, tmp_path / "sets", estimator=ESTIMATOR, jobs=2, progress=events.append)
    assert summary.positions == 5 and summary.done == 5
    assert [e.status for e in events].count("read") == 2 and [e.status for e in events].count("fitted") == 5
    assert events[-1].done == events[-1].total == 5 and events[-1].logs_read == 2
    assert all(later.done >= earlier.done for earlier, later in itertools.pairwise(events))
    assert run("fit", str(logs[0]), "-o", f"{tmp_path}/x/", "-j", "0").exit_code == 2


def test_a_dask_local_cluster_gives_the_same_models(tmp_path):
    distributed = pytest.importorskip("distributed")
    import dask

    from occtool.executor import DASK_CLUSTER_CONFIG

    log = write_log(tmp_path / "room.csv", 3)
    fit_model_set(log, tmp_path / "local", estimator=ESTIMATOR, jobs=1)
    with dask.config.set(DASK_CLUSTER_CONFIG):  # as documented for occtool's clusters
        cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                           dashboard_address=None)
        with cluster, distributed.Client(cluster) as client:
            summary = fit_model_set(log, tmp_path / "dask", estimator=ESTIMATOR, scheduler=client)
    assert summary.done == 3 and "Dask" in summary.executor
    assert models_without_run(tmp_path / "local") == models_without_run(tmp_path / "dask")
    run_block = json.loads((tmp_path / "dask" / "model_0000.json").read_text())["run"]
    assert "Dask" in run_block["executor"]


def test_the_recommended_dask_settings_are_dask_settings():
    # dask.config.set takes any key: a misspelt one would leave Dask's default in force unseen.
    dask = pytest.importorskip("dask")
    pytest.importorskip("distributed")
    from occtool.executor import DASK_CLUSTER_CONFIG

    missing = object()
    for key, value in DASK_CLUSTER_CONFIG.items():
        default = dask.config.get(key, default=missing)
        assert default is not missing, key
        assert type(default) is type(value) and default != value, key


def test_the_run_object_is_filled_in_to_the_same_bytes_save_model_writes(tmp_path):
    log = write_log(tmp_path / "room.csv", 1)
    from occtool.io import read_log

    model = OccupancyRegressor(pieces=4).fit(read_log(log).single().features)
    run_block = {"seconds": 0.1, "host": "h", "nested": {"a": [1, 2]}}
    assert with_run(model_text(model, run=RUN_PLACEHOLDER), run_block) == model_text(model, run=run_block)


def test_a_failing_position_is_reported_and_the_others_written(tmp_path):
    log = write_log(tmp_path / "room.csv", 3, floor_only=(1,))
    result = run("fit", str(log), "-o", f"{tmp_path}/set/", "--pieces", "8", "-j", "1", "--floor", "drop")
    assert result.exit_code == 1
    assert "1 of 3 position(s) failed" in result.output and "floor" in result.output
    index = json.loads((tmp_path / "set" / "index.json").read_text())
    assert index["complete"] is True
    assert [m["position"] for m in index["models"]] == [0, 2]
    assert index["failed"][0]["position"] == 1 and "floor" in index["failed"][0]["reason"]
    assert not (tmp_path / "set" / "model_0001.json").exists()


def test_skip_existing_reuses_only_models_of_the_same_input_and_settings(tmp_path):
    log = write_log(tmp_path / "room.csv", 3)
    fit_model_set(log, tmp_path / "set", estimator=ESTIMATOR, jobs=1)
    before = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "set").glob("model_*.json")}
    again = fit_model_set(log, tmp_path / "set", estimator=ESTIMATOR, jobs=1, skip_existing=True)
    assert again.reused == 3 and again.done == 0
    assert before == {p.name: p.stat().st_mtime_ns for p in (tmp_path / "set").glob("model_*.json")}
    other = fit_model_set(log, tmp_path / "set", estimator=OccupancyRegressor(pieces=4, seed=1), jobs=1,
                          skip_existing=True)
    assert other.reused == 0 and other.done == 3
    write_log(log, 3, seed=5)  # new features, same settings
    changed = fit_model_set(log, tmp_path / "set", estimator=OccupancyRegressor(pieces=4, seed=1), jobs=1,
                            skip_existing=True)
    assert changed.reused == 0 and changed.done == 3


def test_an_interrupted_run_leaves_a_partial_index_that_resumes(tmp_path):
    log = write_log(tmp_path / "room.csv", 5)

    def stop_after_two(event):
        if event.status == "fitted" and event.done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        fit_model_set(log, tmp_path / "set", estimator=ESTIMATOR, jobs=1, progress=stop_after_two)
    index = json.loads((tmp_path / "set" / "index.json").read_text())
    assert index["complete"] is False and len(index["models"]) == 2
    assert no_temp_files(tmp_path)
    resumed = fit_model_set(log, tmp_path / "set", estimator=ESTIMATOR, jobs=1, skip_existing=True)
    assert resumed.reused == 2 and resumed.done == 3
    assert json.loads((tmp_path / "set" / "index.json").read_text())["complete"] is True
    fit_model_set(log, tmp_path / "whole", estimator=ESTIMATOR, jobs=1)
    assert models_without_run(tmp_path / "set") == models_without_run(tmp_path / "whole")


@pytest.mark.slow
def test_sigterm_leaves_a_valid_partial_index_and_no_temp_files(tmp_path):
    log = write_log(tmp_path / "room.csv", 60, n=2000)
    out = tmp_path / "set"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen([sys.executable, "-m", "occtool", "fit", str(log), "-o", f"{out}/", "-j", "2"],
                               env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        for _ in range(1200):
            if (out / "index.json").exists() or process.poll() is not None:
                break
            time.sleep(0.05)
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    index = json.loads((out / "index.json").read_text())
    if process.returncode == 0:
        pytest.skip("the fit finished before SIGTERM arrived")
    assert index["complete"] is False and 0 < len(index["models"]) < 60
    assert b"Traceback" not in stderr
    assert no_temp_files(tmp_path)
    for entry in index["models"]:
        load_model(out / entry["file"])


@pytest.mark.slow
def test_several_logs_give_one_sub_folder_each_and_extract_takes_them_all(tmp_path):
    first = write_log(tmp_path / "a.csv", 2)
    second = write_log(tmp_path / "b.csv.gz".replace(".gz", ""), 2, seed=3)
    result = run("fit", str(tmp_path / "*.csv"), "-o", f"{tmp_path}/sets/new/", "--pieces", "8")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (tmp_path / "sets" / "new").iterdir()) == ["a", "b"]
    assert find_model_sets(tmp_path / "sets" / "new") == [tmp_path / "sets" / "new" / "a",
                                                          tmp_path / "sets" / "new" / "b"]
    result = run("extract", str(tmp_path / "sets" / "new"), "-o", f"{tmp_path}/navs/", "--heights=-0.5",
                 "--world", "-j", "2")
    assert result.exit_code == 0, result.output
    navs = sorted(str(p.relative_to(tmp_path / "navs")) for p in (tmp_path / "navs").rglob("*.geojson"))
    assert navs == ["a/nav_0000.geojson", "a/nav_0001.geojson", "b/nav_0000.geojson", "b/nav_0001.geojson"]
    assert first.exists() and second.exists()
    result = run("fit", str(first), str(tmp_path / "a.csv"), "-o", f"{tmp_path}/dup/")
    assert result.exit_code != 0 and "share the sub-folder" in result.output


def test_extract_model_set_in_the_library_matches_the_cli(tmp_path):
    log = write_log(tmp_path / "room.csv", 2)
    fit_model_set(log, tmp_path / "set", estimator=ESTIMATOR, jobs=1)
    summary = extract_model_set(tmp_path / "set", tmp_path / "lib.geojson", jobs=2, heights=(-0.5,))
    assert summary.done == 2 and not summary.failures
    result = run("extract", str(tmp_path / "set"), "-o", str(tmp_path / "cli.geojson"), "--heights=-0.5")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "lib.geojson").read_bytes() == (tmp_path / "cli.geojson").read_bytes()


def test_a_log_on_standard_input_and_a_missing_output_folder(tmp_path):
    log = write_log(tmp_path / "room.csv", 1)
    result = run("fit", "-", "-o", str(tmp_path / "new" / "deeper" / "m.json"), "--pieces", "4",
                 input=log.read_bytes())
    assert result.exit_code == 1 and "does not exist" in result.output  # a model file's folder is not made
    result = run("fit", "-", "-o", f"{tmp_path}/new/deeper/", "--pieces", "4", input=log.read_bytes())
    assert result.exit_code == 0, result.output
    index = json.loads((tmp_path / "new" / "deeper" / "index.json").read_text())
    assert index["source"] == "-" and len(index["models"]) == 1
    result = run("fit", "-", "-o", str(tmp_path / "m.json"), "--pieces", "4", input=b"")
    assert result.exit_code == 1 and "standard input is empty" in result.output


def test_log_set_names_drop_format_and_compression_suffixes():
    assert log_set_name("/d/intel-corrected.log.gz") == "intel-corrected"
    assert log_set_name("run.2024-01-01.bag") == "run.2024-01-01"
    assert log_set_name("scan.dat.bz2") == "scan"


# --- the index: entries stay inside the set's folder ----------------------------------------

@pytest.fixture
def small_set(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("set")
    fit_model_set(write_log(folder / "room.csv", 2), folder / "set", estimator=ESTIMATOR, jobs=1)
    return folder / "set"


def with_entries(folder: Path, entries: list[dict]) -> Path:
    index = json.loads((folder / "index.json").read_text())
    index["models"] = entries
    (folder / "index.json").write_text(json.dumps(index))
    return folder


@pytest.mark.parametrize("name, message", [
    ("../x.json", "inside the set's folder"),
    ("/etc/passwd", "inside the set's folder"),
    ("missing.json", "does not exist"),
    ("fifo.json", "not a regular file"),
    ("link.json", "out of the set's folder"),
])
def test_index_entries_outside_the_folder_or_not_regular_files_are_refused(small_set, tmp_path, name, message):
    folder = tmp_path / "copy"
    folder.mkdir()
    for path in small_set.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())
    os.mkfifo(folder / "fifo.json")
    (tmp_path / "outside.json").write_bytes((small_set / "model_0000.json").read_bytes())
    (folder / "link.json").symlink_to(tmp_path / "outside.json")
    with_entries(folder, [{"position": 0, "file": name, "pose": None}])
    with pytest.raises(InputError, match=message):
        read_model_set(folder)
    result = run("extract", str(folder), "-o", str(tmp_path / "out.geojson"))
    assert result.exit_code == 1 and message in result.output and "Traceback" not in result.output
    assert not (tmp_path / "out.geojson").exists()


def test_duplicate_positions_are_refused(small_set, tmp_path):
    index = json.loads((small_set / "index.json").read_text())
    folder = tmp_path / "copy"
    folder.mkdir()
    for path in small_set.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())
    with_entries(folder, [index["models"][0], {**index["models"][1], "position": 0}])
    with pytest.raises(InputError, match="position 0 is listed twice"):
        read_model_set(folder)


@given(st.text(min_size=0, max_size=40), st.integers(-3, 3))
def test_any_index_entry_is_read_inside_the_folder_or_refused(small_set_path, name, position):
    folder = small_set_path
    index = json.loads((folder / "index.json").read_text())
    index["models"] = [{"position": position, "file": name, "pose": None}]
    text = json.dumps(index)
    probe = folder.parent / "probe"
    probe.mkdir(exist_ok=True)
    for path in folder.iterdir():
        if path.is_file() and not (probe / path.name).exists():
            (probe / path.name).write_bytes(path.read_bytes())
    (probe / "index.json").write_text(text)
    try:
        found, entries = read_model_set(probe)
    except InputError:
        return
    target = (found / entries[0]["file"]).resolve()
    assert target.is_relative_to(probe.resolve()) and target.is_file()


@pytest.fixture(scope="module")
def small_set_path(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("fuzzset")
    fit_model_set(write_log(folder / "room.csv", 1), folder / "set", estimator=ESTIMATOR, jobs=1)
    return folder / "set"


def test_extract_reports_a_broken_model_and_writes_the_others(tmp_path):
    log = write_log(tmp_path / "room.csv", 3)
    fit_model_set(log, tmp_path / "set", estimator=ESTIMATOR, jobs=1)
    (tmp_path / "set" / "model_0001.json").write_text('{"format": "occtool-model", "format_version": 1}')
    result = run("extract", str(tmp_path / "set"), "-o", f"{tmp_path}/navs/", "--heights=-0.5", "-j", "2")
    assert result.exit_code == 1 and "1 of 3 position(s) failed" in result.output
    assert sorted(p.name for p in (tmp_path / "navs").iterdir()) == ["nav_0000.geojson", "nav_0002.geojson"]
    assert no_temp_files(tmp_path)


def test_tasks_of_fits_hold_a_task_of_positions_or_features_and_a_large_position_alone():
    from occtool.executor import CHUNK_FEATURES, CHUNK_POSITIONS, tasks_of_fits

    small = [10] * (CHUNK_POSITIONS + 3)
    assert [len(t) for t in tasks_of_fits(small, lambda n: n)] == [CHUNK_POSITIONS, 3]
    mixed = [CHUNK_FEATURES // 4] * 3 + [CHUNK_FEATURES * 2] + [1, 1]
    tasks = list(tasks_of_fits(mixed, lambda n: n))
    assert tasks == [[CHUNK_FEATURES // 4] * 3, [CHUNK_FEATURES * 2], [1, 1]]
    # Lazy: a stream of positions is grouped as it is read, in order, each item once.
    assert [x for t in tasks_of_fits(iter(range(100)), lambda n: 1000) for x in t] == list(range(100))
