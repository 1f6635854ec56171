"""The map of a run written where robots and people look: the world map (``world.occmap``),
a Nav2 map (:mod:`occtool.formats.nav2`), an MCAP that Foxglove draws with its standard
schemas (:mod:`occtool.formats.foxglove`), GeoJSON layers with one geometry type each, and
a JSON summary (:func:`write_run_map`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool._files import atomic_write
from occtool.errors import InputError
from occtool.fuse._run import RunMap

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
    if not overwrite:
        for path in output_paths(folder, nav2_mode):
            if path.exists():
                raise FileExistsError(f"{path} exists already (pass overwrite=True to replace it)")


def write_run_map(run: RunMap, folder: str | os.PathLike[str], *, overwrite: bool = True,
                  simplify: float | None = None, precision: int | None = None, mcap: bool = True,
                  georeference: Any | None = None, extra_summary: dict[str, Any] | None = None,
                  nav2_mode: str = "trinary") -> list[Path]:
    """Write the world map (``world.occmap``), the Nav2 map, the Foxglove MCAP, the GeoJSON
    layers and ``summary.json`` into ``folder`` (created if missing). Every file is written
    completely or not at all, and everything is computed before the first file is written.

    ``nav2_mode``: ``"trinary"`` writes ``map.pgm`` (free / occupied / unknown), ``"scale"``
    ``map.png`` with the fused occupancy graded (needs Pillow)."""
    return _write_run_map(run, folder, overwrite=overwrite, simplify=simplify, precision=precision, mcap=mcap,
                          georeference=georeference, extra_summary=extra_summary, nav2_mode=nav2_mode)[0]


def _write_run_map(run: RunMap, folder: str | os.PathLike[str], *, overwrite: bool, simplify: float | None,
                   precision: int | None, mcap: bool, georeference: Any | None,
                   extra_summary: dict[str, Any] | None, nav2_mode: str) -> tuple[list[Path], dict[str, Any]]:
    """:func:`write_run_map`, and the summary it wrote (``summary.json``)."""
    from occtool.formats.geojson import run_map_layers
    from occtool.formats.nav2 import write_nav2, write_nav2_scale
    from occtool.formats.occmap import encode

    check_outputs(folder, nav2_mode=nav2_mode, overwrite=overwrite)  # before any file is written
    folder = Path(folder)
    layers = run_map_layers(run.navigation, run.obstacles, run.frontiers, simplify=simplify, precision=precision,
                            georeference=georeference)
    world_bytes = encode(run.world)
    summary = {**run.summary(), **(extra_summary or {})}
    summary["world_map"]["file_bytes"] = len(world_bytes)
    mcap_bytes = None
    if mcap:
        from occtool.formats.foxglove import run_map_mcap_bytes

        mcap_bytes = run_map_mcap_bytes(run)
    folder.mkdir(parents=True, exist_ok=True)
    with atomic_write(folder / "world.occmap", "wb", overwrite=overwrite) as handle:
        handle.write(world_bytes)
    written = [folder / "world.occmap"]
    if nav2_mode == "scale":
        written += list(write_nav2_scale(run.raster.graded(), run.raster.resolution, run.raster.origin,
                                         folder / "map.yaml", overwrite=overwrite))
    else:
        written += list(write_nav2(run.raster.cells, run.raster.resolution, run.raster.origin, folder / "map.yaml",
                                  overwrite=overwrite))
    if mcap_bytes is not None:
        with atomic_write(folder / "map.mcap", "wb", overwrite=overwrite) as handle:
            handle.write(mcap_bytes)
        written.append(folder / "map.mcap")
    for name, collection in layers.items():
        with atomic_write(folder / f"{name}.geojson", "w", overwrite=overwrite) as handle:
            json.dump(collection, handle, separators=(",", ":"))
            handle.write("\n")
        written.append(folder / f"{name}.geojson")
    with atomic_write(folder / "summary.json", "w", overwrite=overwrite) as handle:
        json.dump(summary, handle, indent=1)
        handle.write("\n")
    written.append(folder / "summary.json")
    return written, summary


__all__ = ["NAV2_MODES", "check_outputs", "output_paths", "write_run_map"]
