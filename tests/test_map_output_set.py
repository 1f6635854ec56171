"""`occtool map` writes its outputs as one set: an interrupted run leaves the previous
complete set or the new one, never a mix, and no temporary folder."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from _room_log import write_room_log

from occtool.fit import OccupancyRegressor
from occtool.fuse import map_log, write_run_map
from occtool.fuse._outputs import STAGING_PREFIX
from occtool.robot import Robot

ROOT = Path(__file__).resolve().parents[1]
ROBOT = Robot(radius=0.25, sensor_height=0.3, body_height=0.5)
SET = ["frontiers.geojson", "map.mcap", "map.pgm", "map.yaml", "navigation.geojson", "obstacles.geojson",
       "summary.json", "world.occmap"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two different maps' runs of the room log (40 and 30 scans) and the log."""
    folder = tmp_path_factory.mktemp("room")
    write_room_log(folder / "a.log", scans=40)
    write_room_log(folder / "b.log", scans=30)
    first = map_log(folder / "a.log", folder / "first", estimator=OccupancyRegressor(robot=ROBOT)).run
    second = map_log(folder / "b.log", folder / "second", estimator=OccupancyRegressor(robot=ROBOT)).run
    return first, second, folder / "a.log"


def contents(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def leftovers(folder: Path) -> list[str]:
    return [p.name for p in folder.parent.iterdir() if p.name.startswith(STAGING_PREFIX)] + \
        ([p.name for p in folder.iterdir() if p.name.startswith(STAGING_PREFIX)] if folder.is_dir() else [])


def interrupt_after(monkeypatch, count: int, error: type[BaseException] = KeyboardInterrupt) -> None:
    """Make the GeoJSON writer raise ``error`` after ``count`` files of the set are written."""
    import occtool.fuse._outputs as outputs

    real = outputs.atomic_write
    seen = []

    def failing(path, *args, **kwargs):
        seen.append(path)
        if len(seen) > count:
            raise error()
        return real(path, *args, **kwargs)

    monkeypatch.setattr(outputs, "atomic_write", failing)


@pytest.mark.parametrize("count", [1, 3])
@pytest.mark.parametrize("error", [KeyboardInterrupt, OSError])
def test_an_interrupted_run_leaves_the_previous_set_whole(runs, tmp_path, monkeypatch, count, error):
    first, second, _ = runs
    folder = tmp_path / "out"
    write_run_map(first, folder)
    (folder / "notes.txt").write_text("mine")  # a user's file beside the outputs
    before = contents(folder)
    interrupt_after(monkeypatch, count, error)
    with pytest.raises(error):
        write_run_map(second, folder)
    assert contents(folder) == before
    assert not leftovers(folder)


def test_an_interrupted_run_into_a_new_folder_leaves_nothing(runs, tmp_path, monkeypatch):
    first, _, _ = runs
    interrupt_after(monkeypatch, 2)
    with pytest.raises(KeyboardInterrupt):
        write_run_map(first, tmp_path / "new")
    assert not (tmp_path / "new").exists() and not leftovers(tmp_path / "new")


def test_a_failure_while_moving_into_place_moves_the_previous_set_back(runs, tmp_path, monkeypatch):
    first, second, _ = runs
    folder = tmp_path / "out"
    write_run_map(first, folder)
    before = contents(folder)
    real = os.rename
    moved = []

    def rename(source, target):
        # The third new file into the folder fails (a full directory, a disk gone away).
        if Path(target).parent == folder and STAGING_PREFIX in str(source):
            moved.append(target)
            if len(moved) == 3:
                raise OSError(28, "No space left on device")
        return real(source, target)

    monkeypatch.setattr(os, "rename", rename)
    with pytest.raises(OSError):
        write_run_map(second, folder)
    assert contents(folder) == before and not leftovers(folder)


def test_a_complete_run_replaces_the_whole_set_and_removes_stale_outputs(runs, tmp_path):
    first, second, _ = runs
    folder = tmp_path / "out"
    write_run_map(first, folder, nav2_mode="scale")
    (folder / "poses.csv").write_text("stale\n")
    (folder / "notes.txt").write_text("mine")
    written = write_run_map(second, folder, mcap=False)
    # map.png of the scale run, map.mcap and poses.csv described the previous map.
    assert sorted(p.name for p in folder.iterdir()) == sorted([n for n in SET if n != "map.mcap"] + ["notes.txt"])
    assert (folder / "notes.txt").read_text() == "mine" and not leftovers(folder)
    assert [p.parent for p in written] == [folder] * len(written) and written[0].name == "world.occmap"
    fresh = tmp_path / "fresh"
    write_run_map(second, fresh, mcap=False)
    assert {k: v for k, v in contents(fresh).items()} == {k: v for k, v in contents(folder).items()
                                                          if k != "notes.txt"}


def test_a_new_folder_gets_the_mode_mkdir_gives(runs, tmp_path):
    first, _, _ = runs
    write_run_map(first, tmp_path / "a" / "b")
    (tmp_path / "plain").mkdir()
    assert (tmp_path / "a" / "b").stat().st_mode == (tmp_path / "plain").stat().st_mode
    assert sorted(p.name for p in (tmp_path / "a" / "b").iterdir()) == SET


def test_without_overwrite_an_existing_output_is_refused_before_any_work(runs, tmp_path):
    first, second, _ = runs
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "map.png").write_text("another run's")  # not an output of a trinary run: kept
    write_run_map(first, folder, overwrite=False)
    assert (folder / "map.png").read_text() == "another run's"
    before = contents(folder)
    with pytest.raises(FileExistsError, match="exists already"):
        write_run_map(second, folder, overwrite=False)
    assert contents(folder) == before and not leftovers(folder)


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="SIGTERM")
def test_sigterm_during_occtool_map_leaves_the_previous_set(runs, tmp_path):
    """A real process terminated while it fits: the folder holds the previous set, whole."""
    _, _, log = runs
    folder = tmp_path / "out"

    def command(source: Path, out: Path = folder) -> list[str]:
        return [sys.executable, "-m", "occtool", "-q", "map", str(source), "-o", str(out), "--sensor-height",
                "0.3", "--body-height", "0.5"]

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    other = log.parent / "c.log"
    write_room_log(other, scans=30)
    subprocess.run(command(other), env=env, check=True, capture_output=True)
    subprocess.run(command(log, tmp_path / "reference"), env=env, check=True, capture_output=True)
    reference = contents(tmp_path / "reference")
    before = contents(folder)
    process = subprocess.Popen(command(log), env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    time.sleep(1.5)
    process.send_signal(signal.SIGTERM)
    process.communicate(timeout=120)
    after = contents(folder)
    assert set(after) == set(before) and not leftovers(folder)
    # The previous map's set whole, or (had the run finished) the new one's: never some of each.
    kept = {name for name in after if after[name] == before[name]}
    new = {name for name in after if after[name] == reference[name]}
    assert kept == set(after) or new | {"summary.json"} == set(after), (kept, new)


def test_a_killed_runs_hidden_folder_is_removed_by_the_next_run_and_a_live_ones_kept(runs, tmp_path):
    # SIGKILL leaves nothing to clean up: the next run into the folder removes what a dead process left.
    first, _, _ = runs
    folder = tmp_path / "out"
    write_run_map(first, folder)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True).stdout.strip()
    orphans = [folder / f"{STAGING_PREFIX}{dead}-0123abcd", tmp_path / f"{STAGING_PREFIX}{dead}-89abcdef"]
    for orphan in orphans:
        (orphan / f"{STAGING_PREFIX}previous").mkdir(parents=True)
        (orphan / f"{STAGING_PREFIX}previous" / "map.pgm").write_bytes(b"P5 old")
    alive = folder / f"{STAGING_PREFIX}{os.getppid()}-0123abcd"  # the process that started pytest
    other = folder / f"{STAGING_PREFIX}notes"  # not a name a run makes
    for kept in (alive, other):
        kept.mkdir()
    write_run_map(first, folder)
    assert not orphans[0].exists() and alive.is_dir() and other.is_dir()
    write_run_map(first, tmp_path / "new")  # a new folder: its parent is searched
    assert not orphans[1].exists()
    assert sorted(p.name for p in folder.iterdir() if not p.name.startswith(".")) == SET
