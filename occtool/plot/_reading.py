"""Files the pictures are drawn from: navigation maps, comparison reports, benchmark sweeps.

Parsing lives in :mod:`occtool.io` (:func:`occtool.formats.geojson.read_navigation`,
:func:`occtool._json.read_json`); this module picks out what a picture needs.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from occtool.errors import InputError
from occtool.plot._canvas import MODEL_COLOURS, FloatArray

if TYPE_CHECKING:  # pragma: no cover
    from occtool.navigation import NavigationMap


def read_navigation(path: str | os.PathLike[str]) -> NavigationMap:
    """Read a navigation map GeoJSON written by ``occtool extract``.

    A thin alias of :func:`occtool.formats.geojson.read_navigation`, which raises
    :class:`~occtool.errors.InputError` naming the file for malformed input.
    """
    from occtool.formats.geojson import read_navigation as read

    return read(path)


def read_navigation_maps(path: str | os.PathLike[str]) -> list[tuple[int | None, NavigationMap]]:
    """Every map in a navigation GeoJSON file, with the robot position each belongs to.

    A thin alias of :func:`occtool.formats.geojson.read_navigation_maps`: ``[(None, map)]``
    for a file of one map, one ``(position, map)`` per position, in position order, for
    a model set's file.
    """
    from occtool.formats.geojson import read_navigation_maps as read

    return read(path)


def expand_navigation_paths(paths: Iterable[str | os.PathLike[str]]) -> list[Path]:
    """Navigation map files from files and folders (a folder gives its ``*.geojson``, sorted).

    Raises
    ------
    InputError
        If a folder holds no GeoJSON file.
    """
    found: list[Path] = []
    for item in map(Path, paths):
        if item.is_dir():
            inside = sorted(p for p in item.iterdir() if p.suffix.lower() == ".geojson" and p.is_file())
            if not inside:
                raise InputError(f"{item} holds no .geojson navigation map")
            found.extend(inside)
        else:
            found.append(item)
    return found


def report_polygons(report: Mapping[str, Any]) -> dict[str, Any]:
    """The navigation polygons per model in a comparison report, as shapely geometries.

    Looks in ``report["polygons"][model]`` and in ``report["models"][model]["polygon"]``;
    a value may be a GeoJSON geometry, a Feature or a FeatureCollection (whose
    ``kind: navigation`` feature is used).
    """
    from shapely.errors import ShapelyError
    from shapely.geometry import shape

    found: dict[str, Any] = {}
    candidates: dict[str, Any] = {}
    models = report.get("models")
    if isinstance(models, Mapping):
        for name, entry in models.items():
            if isinstance(entry, Mapping) and "polygon" in entry:
                candidates[name] = entry["polygon"]
    polygons = report.get("polygons")
    if isinstance(polygons, Mapping):
        candidates.update(polygons)
    for name, value in candidates.items():
        if isinstance(value, Mapping) and value.get("type") == "FeatureCollection":
            value = next((f for f in value.get("features") or [] if isinstance(f, Mapping)
                          and (f.get("properties") or {}).get("kind") == "navigation"), None)
        if isinstance(value, Mapping) and value.get("type") == "Feature":
            value = value.get("geometry")
        try:
            found[str(name)] = shape(value)
        except (TypeError, ValueError, KeyError, IndexError, AttributeError, ShapelyError):
            continue  # a section we cannot read is skipped, not fatal: the rest still draws
    return found


@dataclass(frozen=True)
class ScalingSeries:
    """One model's cost against one size variable, from the benchmark's sweep."""

    model: str
    variable: str
    x: FloatArray
    seconds: FloatArray
    memory_bytes: FloatArray


_TIME_KEYS = ("total_s", "build_s", "fit_s", "seconds", "time_s")


_MEMORY_KEYS = ("memory_bytes", "peak_memory_bytes", "bytes")




def scaling_series(bench: Any) -> list[ScalingSeries]:
    """Scaling curves from the benchmark's results: time and memory against size per model.

    Accepts a list of rows (or ``{"scaling": [...]}`` / ``{"sweep": [...]}``, as
    ``bench/results.json`` has it) where a row has a size (``scale`` and/or
    ``features``; ``"sweep"`` names the one it varies) and either per-model entries
    under ``"models"`` or a ``"model"`` name with ``build_s`` (plus ``extract_s``) and
    ``memory_bytes``. Rows missing a number are skipped.

    Returns
    -------
    list of ScalingSeries
        One per (model, size variable) with at least two points, sorted by size.
    """
    rows: Any = bench
    if isinstance(bench, Mapping):
        for key in ("scaling", "sweep", "rows", "results"):
            if isinstance(bench.get(key), list):
                rows = bench[key]
                break
        else:
            rows = []
    if not isinstance(rows, list):
        return []
    collected: dict[tuple[str, str], list[tuple[float, float, float]]] = {}

    def number(entry: Mapping[str, Any], keys: Iterable[str]) -> float | None:
        for key in keys:
            value = entry.get(key)
            if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
                return float(value)
        return None

    def seconds_of(entry: Mapping[str, Any]) -> float | None:
        if "build_s" in entry and "extract_s" in entry:
            build, extract = number(entry, ["build_s"]), number(entry, ["extract_s"])
            if build is not None and extract is not None:
                return build + extract
        return number(entry, _TIME_KEYS)

    for row in rows:
        if not isinstance(row, Mapping):
            continue
        entries: list[tuple[str, Mapping[str, Any]]] = []
        if isinstance(row.get("models"), Mapping):
            entries = [(str(n), e) for n, e in row["models"].items() if isinstance(e, Mapping)]
        elif isinstance(row.get("model"), str):
            entries = [(row["model"], row)]
        # A row of one sweep varies one size; the other is held fixed and not a curve.
        swept = (row["sweep"],) if row.get("sweep") in ("scale", "features") else ("scale", "features")
        for name, entry in entries:
            seconds, memory = seconds_of(entry), number(entry, _MEMORY_KEYS)
            if seconds is None and memory is None:
                continue
            for variable in swept:
                size = number(row, [variable] if variable == "scale" else ["features", "n_features"])
                if size is None:
                    continue
                collected.setdefault((name, variable), []).append(
                    (size, np.nan if seconds is None else seconds, np.nan if memory is None else memory))
    series = []
    known = list(MODEL_COLOURS)  # the parametric model first, then the baselines
    for (name, variable), values in sorted(collected.items(), key=lambda item: (
            known.index(item[0][0]) if item[0][0] in known else len(known), item[0])):
        if len(values) < 2:
            continue
        array = np.asarray(sorted(values), dtype=np.float64)
        series.append(ScalingSeries(name, variable, array[:, 0], array[:, 1], array[:, 2]))
    return series
