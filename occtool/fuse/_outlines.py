"""A large run's navigation outlines kept in a file until its files are written.

A run keeps each keyframe's navigation polygon, placed in the world, from its navigation
maps to its last file (``map.mcap`` draws every one; the navigation region is their union):
about 7 KB a campus keyframe, 100 MB for campus x10's 15,710, held through the world map
and the raster. A lean run (:func:`occtool.fuse.map_log`) keeps them in an unnamed temporary
file instead (:class:`SpilledOutlines`) and each map without its polygon
(:class:`SpilledNavigation`), which reads it back when asked: the same polygons, to the bit.
"""

from __future__ import annotations

import os
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool._files import read_at


class SpilledOutlines:
    """Polygons kept as WKB (exact float64 coordinates) in an unnamed temporary file in
    ``folder``, with their bounding boxes in memory.

    ``append(polygon)`` gives its index; ``outlines[k]`` reads polygon ``k`` back,
    ``outlines[index_array]`` an object array of them; :attr:`bounds` is ``(N, 4)``
    (``shapely.bounds``: NaN for an empty polygon). The file has no name
    (``tempfile.TemporaryFile``), so it goes with the object or the process, however the
    process ends; it is read with ``os.preadv``, never mapped.
    """

    def __init__(self, folder: str | os.PathLike[str] | None = None) -> None:
        import tempfile

        self._file = tempfile.TemporaryFile(dir=folder)
        self._offsets = [0]
        self._bounds: list[NDArray[np.float64]] = []

    def __len__(self) -> int:
        return len(self._bounds)

    def append(self, polygon: Any) -> int:
        import shapely

        data = shapely.to_wkb(polygon)
        end = self._offsets[-1]
        written = 0
        while written < len(data):
            written += os.pwrite(self._file.fileno(), data[written:], end + written)
        self._offsets.append(end + len(data))
        self._bounds.append(np.asarray(shapely.bounds(polygon), dtype=np.float64))
        return len(self._bounds) - 1

    @property
    def bounds(self) -> NDArray[np.float64]:
        return np.stack(self._bounds) if self._bounds else np.zeros((0, 4))

    def _read(self, index: int) -> bytes:
        low, high = self._offsets[index], self._offsets[index + 1]
        return bytes(read_at(self._file.fileno(), bytearray(high - low), low, "the outlines' temporary file"))

    def __getitem__(self, index: Any) -> Any:
        import shapely

        if isinstance(index, (int, np.integer)):
            if not -len(self) <= index < len(self):
                raise IndexError(f"outline {index} out of range for {len(self)}")
            return shapely.from_wkb(self._read(int(index) % len(self)))
        indices = np.arange(len(self))[index]
        return shapely.from_wkb(np.array([self._read(int(k)) for k in indices], dtype=object))


class SpilledNavigation:
    """A placed navigation map (:class:`occtool.navigation.NavigationMap`) whose polygon waits
    in a :class:`SpilledOutlines`: every other field is the map's own, and ``polygon`` is read
    back from the file each time it is asked for. It pickles as the map it stands for."""

    __slots__ = ("_map", "_outlines", "_index")

    def __init__(self, nav: Any, outlines: SpilledOutlines) -> None:
        import shapely

        self._index = outlines.append(nav.polygon)
        self._outlines = outlines
        self._map = replace(nav, polygon=shapely.Polygon())

    @property
    def polygon(self) -> Any:
        return self._outlines[self._index]

    @property
    def outline_index(self) -> tuple[SpilledOutlines, int]:
        """The file its polygon is in and its index there."""
        return self._outlines, self._index

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self._map, name)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        return _with_polygon, (self._map, self.polygon)


def _with_polygon(nav: Any, polygon: Any) -> Any:
    return replace(nav, polygon=polygon)


def placed_outlines(navs: list[Any]) -> tuple[Any, NDArray[np.float64] | None]:
    """The polygons of ``navs`` (navigation maps, in order), as :func:`union_in_groups` takes
    them: their :class:`SpilledOutlines` and bounding boxes when every one waits, in order,
    in one such file (read back a group at a time), else an object array of them (``None``)."""
    if navs and all(isinstance(nav, SpilledNavigation) for nav in navs):
        outlines = navs[0].outline_index[0]
        if len(outlines) == len(navs) and all(nav.outline_index == (outlines, k) for k, nav in enumerate(navs)):
            return outlines, outlines.bounds
    return np.array([nav.polygon for nav in navs], dtype=object), None


__all__ = ["SpilledNavigation", "SpilledOutlines", "placed_outlines"]
