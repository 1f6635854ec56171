"""The map of a run written where robots and people look: the world map (``world.occmap``),
a Nav2 map (:mod:`occtool.formats.nav2`), an MCAP that Foxglove draws with its standard
schemas (:mod:`occtool.formats.foxglove`), GeoJSON layers with one geometry type each, and
a JSON summary (:func:`write_run_map`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool._files import atomic_write, signals_held
from occtool.errors import InputError
from occtool.fuse._run import RunMap
from occtool.fuse._world import WorldMap

FloatArray = NDArray[np.float64]


#: The Nav2 map's modes (map_server's): three values, or the fused occupancy graded.
NAV2_MODES = ("trinary", "scale")


def output_paths(folder: str | os.PathLike[str], nav2_mode: str = "trinary") -> list[Path]:
    folder = Path(folder)
    image = "map.png" if nav2_mode == "scale" else "map.pgm"
    return [folder / name for name in ("world.occmap", "map.yaml", image, "map.mcap", "navigation.geojson",
                                       "obstacles.geojson", "frontiers.geojson", "summary.json")]


def _require_pillow(purpose: str) -> None:
    """An :class:`InputError` now if Pillow is missing, rather than after the first file is written."""
    try:
        import PIL  # noqa: F401
    except ImportError:
        raise InputError(f"{purpose} needs Pillow: pip install 'occtool[png]'") from None


def check_outputs(folder: str | os.PathLike[str], *, nav2_mode: str = "trinary", overwrite: bool = True) -> None:
    """Raise now what :func:`write_run_map` would raise before writing: an unknown
    ``nav2_mode``, a missing Pillow for ``"scale"``, ``folder`` a file, or (``overwrite``
    off) an output that exists already (:class:`FileExistsError`)."""
    if nav2_mode not in NAV2_MODES:
        raise InputError(f"nav2_mode must be one of {', '.join(NAV2_MODES)}, got {nav2_mode!r}")
    if nav2_mode == "scale":
        _require_pillow("nav2_mode='scale' (a PNG map)")
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder} exists and is not a folder")
    for path in output_paths(folder, nav2_mode):
        if path.is_dir():
            raise InputError(f"{path} is a folder, not an output this run may replace")
    if not overwrite:
        for path in output_paths(folder, nav2_mode):
            if path.exists():
                raise FileExistsError(f"{path} exists already (pass overwrite=True to replace it)")


#: Every file a run's map may hold (:func:`write_run_map` and ``poses.csv`` of
#: :func:`occtool.fuse.map_log`): a run replacing a map removes those of them it does not write.
OUTPUT_NAMES = ("world.occmap", "map.yaml", "map.pgm", "map.png", "map.mcap", "navigation.geojson",
                "obstacles.geojson", "frontiers.geojson", "summary.json", "poses.csv")
#: Hidden folders a run's outputs are written into before they are moved into place.
STAGING_PREFIX = ".occtool-map-"


def write_run_map(run: RunMap, folder: str | os.PathLike[str], *, overwrite: bool = True,
                  simplify: float | None = None, precision: int | None = None, mcap: bool = True,
                  georeference: Any | None = None, extra_summary: dict[str, Any] | None = None,
                  nav2_mode: str = "trinary") -> list[Path]:
    """Write the world map (``world.occmap``), the Nav2 map, the Foxglove MCAP, the GeoJSON
    layers and ``summary.json`` into ``folder`` (created if missing), as one set.

    Everything is computed before the first file is written, and every file is written
    into a hidden temporary folder first (:data:`STAGING_PREFIX`; beside ``folder`` when
    ``folder`` is new, inside it when it exists: the same file system either way), then
    moved into place: a run interrupted by an exception, Ctrl-C or SIGTERM leaves the
    previous complete set or the new complete set, never a mix, and no temporary folder.

    * A new ``folder`` is the temporary folder renamed: it appears whole or not at all
      (missing parent folders are created first and stay).
    * In an existing ``folder`` the previous outputs are moved aside, the new ones in and
      the previous ones deleted, with SIGINT and SIGTERM held back meanwhile (a signal
      arriving then is raised once the new set is whole); an error half way moves the
      previous ones back. Files of other names in ``folder`` are never touched.
    * Outputs of a previous run that this run does not write (:data:`OUTPUT_NAMES`:
      ``map.png`` of a ``"scale"`` run when this one writes ``map.pgm``, ``map.mcap``
      without ``mcap``, ``poses.csv`` of a registered run) would describe another map:
      with ``overwrite`` they are removed with the rest of the previous set; without it
      nothing is removed, and an output that exists (checked before any work, and again
      before anything is moved) is a :class:`FileExistsError`.
    * A run killed outright (SIGKILL, a power cut) cannot clean up: the next run into the
      same place removes the hidden folders of processes no longer running (POSIX).

    ``nav2_mode``: ``"trinary"`` writes ``map.pgm`` (free / occupied / unknown), ``"scale"``
    ``map.png`` with the fused occupancy graded (needs Pillow)."""
    return _write_run_map(run, folder, overwrite=overwrite, simplify=simplify, precision=precision, mcap=mcap,
                          georeference=georeference, extra_summary=extra_summary, nav2_mode=nav2_mode)[0]


def _write_run_map(run: RunMap, folder: str | os.PathLike[str], *, overwrite: bool, simplify: float | None,
                   precision: int | None, mcap: bool, georeference: Any | None,
                   extra_summary: dict[str, Any] | None, nav2_mode: str,
                   also: Callable[[Path], list[Path]] | None = None) -> tuple[list[Path], dict[str, Any]]:
    """:func:`write_run_map`, and the summary it wrote (``summary.json``); ``also`` writes
    more files of the set into the folder it is given (:func:`occtool.fuse.map_log`'s
    ``poses.csv``) and returns them."""
    from occtool.formats.geojson import run_map_layers
    from occtool.formats.occmap import encode

    check_outputs(folder, nav2_mode=nav2_mode, overwrite=overwrite)  # before any file is written
    folder = Path(folder)
    # The layers' features are made as they are written (a large run's would take hundreds
    # of megabytes as lists); their options are checked here, before any file.
    layers = run_map_layers(run.navigation, run.obstacles, run.frontiers, simplify=simplify, precision=precision,
                            georeference=georeference, lazy=True)
    world_bytes = encode(run.world) if isinstance(run.world, WorldMap) else run.world.to_bytes()  # 2D or 3D
    summary = {**run.summary(), **(extra_summary or {})}
    summary["world_map"]["file_bytes"] = len(world_bytes)
    with _output_set(folder, overwrite=overwrite) as staging:
        written = _write_files(run, staging, world_bytes, mcap, layers, summary, nav2_mode)
        if also is not None:
            written += also(staging)
    return [folder / path.name for path in written], summary


def _write_files(run: RunMap, staging: Path, world_bytes: bytes, mcap: bool,
                 layers: dict[str, Any], summary: dict[str, Any], nav2_mode: str) -> list[Path]:
    """The set's files, written into the (new, empty) folder ``staging``; the MCAP and the
    GeoJSON layers are written as they are made (:func:`occtool.formats.foxglove.write_run_map_mcap`,
    :func:`occtool.formats.geojson.dump_collection`), never held whole."""
    from occtool.formats.geojson import dump_collection
    from occtool.formats.nav2 import write_nav2, write_nav2_scale

    with atomic_write(staging / "world.occmap", "wb") as handle:
        handle.write(world_bytes)
    written = [staging / "world.occmap"]
    if nav2_mode == "scale":
        raster = run.raster
        if raster.probability is None and isinstance(run.world, WorldMap):
            # Drawn for a trinary map, without its occupancy: drawn again with it (the same cells).
            raster = run.world.rasterise(raster.resolution, occupancy=True)
        written += list(write_nav2_scale(raster.graded(), raster.resolution, raster.origin, staging / "map.yaml"))
    else:
        written += list(write_nav2(run.raster.cells, run.raster.resolution, run.raster.origin, staging / "map.yaml"))
    if mcap:
        from occtool.formats.foxglove import write_run_map_mcap

        with atomic_write(staging / "map.mcap", "wb") as handle:
            write_run_map_mcap(run, handle)
        written.append(staging / "map.mcap")
    for name, collection in layers.items():
        with atomic_write(staging / f"{name}.geojson", "w") as handle:
            dump_collection(collection, handle)
            handle.write("\n")
        written.append(staging / f"{name}.geojson")
    with atomic_write(staging / "summary.json", "w") as handle:
        json.dump(summary, handle, indent=1)
        handle.write("\n")
    written.append(staging / "summary.json")
    return written


@contextmanager
def _output_set(folder: Path, *, overwrite: bool) -> Iterator[Path]:
    """A new hidden folder to write a set into; moved into ``folder`` as one set when the
    block ends normally, removed in every case (:func:`write_run_map` says how)."""
    import shutil

    fresh = not folder.exists()
    if fresh:
        folder.parent.mkdir(parents=True, exist_ok=True)
    _remove_orphans(folder.parent if fresh else folder)
    staging = _new_folder(folder.parent if fresh else folder)
    try:
        yield staging
        with signals_held():
            try:
                if fresh and not folder.exists():
                    os.rename(staging, folder)
                else:
                    _swap_in(staging, folder, overwrite=overwrite)
            finally:
                shutil.rmtree(staging, ignore_errors=True)
    finally:
        if staging.exists():  # interrupted while writing
            with signals_held():
                shutil.rmtree(staging, ignore_errors=True)


def _new_folder(parent: Path) -> Path:
    """A new hidden folder in ``parent`` made as ``mkdir`` makes one (its mode from the
    umask, unlike ``tempfile.mkdtemp``'s 0700: a new output folder is this one renamed),
    named with this process's id so that a later run can tell an orphan (:func:`_remove_orphans`)."""
    import secrets

    for _ in range(100):
        candidate = parent / f"{STAGING_PREFIX}{os.getpid()}-{secrets.token_hex(4)}"
        try:
            candidate.mkdir()
        except FileExistsError:
            continue
        return candidate
    raise FileExistsError(f"no free name for a temporary folder in {parent}")


def _remove_orphans(parent: Path) -> None:
    """Remove the hidden folders in ``parent`` left by a run of this machine that was killed
    (SIGKILL, a power cut: nothing could clean up), each known by its process id no longer
    running. A folder of a live process, or of a name this run did not make, is left alone."""
    import re
    import shutil

    pattern = re.compile(re.escape(STAGING_PREFIX) + r"(\d{1,10})-[0-9a-f]{8}")
    try:
        names = [entry.name for entry in os.scandir(parent) if entry.is_dir(follow_symlinks=False)]
    except OSError:
        return
    for name in names:
        match = pattern.fullmatch(name)
        if match is None or int(match.group(1)) == os.getpid() or _running(int(match.group(1))):
            continue
        shutil.rmtree(parent / name, ignore_errors=True)


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists (one of another user's counts: its folder is not ours to judge)."""
    if os.name != "posix":  # Windows' os.kill terminates the process it names: assume it runs
        return True
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True
    return True


def _swap_in(staging: Path, folder: Path, *, overwrite: bool) -> None:
    """Move the files of ``staging`` into ``folder``, the previous outputs (and, with
    ``overwrite``, those of :data:`OUTPUT_NAMES` this set lacks) into ``staging`` to be
    deleted with it; an error half way moves everything back."""
    new = sorted(path.name for path in staging.iterdir())
    present = [name for name in dict.fromkeys(new + (list(OUTPUT_NAMES) if overwrite else []))
               if os.path.lexists(folder / name)]
    for name in present:
        if (folder / name).is_dir() and not (folder / name).is_symlink():
            raise InputError(f"{folder / name} is a folder, not an output this run may replace")
    if present and not overwrite:
        raise FileExistsError(f"{folder / present[0]} exists already (pass overwrite=True to replace it)")
    previous = staging / (STAGING_PREFIX + "previous")
    previous.mkdir()
    aside: list[str] = []
    placed: list[str] = []
    try:
        for name in present:
            os.rename(folder / name, previous / name)
            aside.append(name)
        for name in new:
            os.rename(staging / name, folder / name)
            placed.append(name)
    except BaseException:
        for name in placed:
            os.rename(folder / name, staging / name)
        for name in aside:
            os.rename(previous / name, folder / name)
        raise


__all__ = ["NAV2_MODES", "OUTPUT_NAMES", "check_outputs", "output_paths", "write_run_map"]
