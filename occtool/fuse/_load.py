"""Reading a saved world map of either kind: ``world.occmap`` of any version.

Versions 1-4 hold the 2D map (:class:`occtool.fuse.WorldMap`), versions 5 and 6 the 3D one
(:class:`occtool.fuse.WorldMap3D`); :func:`load_map` reads the header's version and hands
the bytes to that version's decoder, so a user loads any map with one call.
"""

from __future__ import annotations

import os

from occtool.formats.occmap import header_version, read_map_bytes
from occtool.formats.occmap3d import VERSIONS as VERSIONS_3D
from occtool.fuse._world import WorldMap, decode_map
from occtool.fuse._world3d import WorldMap3D, from_arrays


def load_map(path: str | os.PathLike[str]) -> WorldMap | WorldMap3D:
    """Read a ``.occmap`` file written by ``occtool map`` (``DIR/world.occmap``) or by a
    map's ``save``: a :class:`WorldMap` (versions 1-4) or a :class:`WorldMap3D` (versions 5-6,
    answering ``predict`` at x, y, z in the frame of the log's poses). A file that cannot be
    read or is damaged is one :class:`~occtool.errors.InputError`."""
    data = read_map_bytes(path)
    if header_version(data) in VERSIONS_3D:
        from occtool.formats.occmap3d import decode

        return from_arrays(decode(bytes(data), str(path)))
    return decode_map(bytes(data), str(path))


__all__ = ["load_map"]
