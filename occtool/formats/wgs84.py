"""Map coordinates to WGS84 longitude/latitude (and back) through pyproj.

A map is anchored at its origin's latitude and longitude, with the compass bearing of its
+x axis (degrees clockwise from north; 90, the default, puts x east and y north, as ENU).
Metric map coordinates are rotated into east/north and projected by an azimuthal
equidistant projection centred at the anchor on the WGS84 ellipsoid, which keeps
distances from the anchor exact (a map of a building or a campus is well within its
centimetre-accurate range). Needs the ``geo`` extra (pyproj).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError, MissingDependencyError

FloatArray = NDArray[np.float64]


def parse_origin(text: str) -> tuple[float, float, float]:
    """``"LAT,LON[,HEADING]"`` (degrees) -> ``(lat, lon, heading)``; heading 90 if absent."""
    try:
        values = [float(v) for v in str(text).replace(" ", "").split(",") if v != ""]
    except ValueError:
        raise InputError(f"origin must be LAT,LON[,HEADING] in degrees, got {text!r}") from None
    if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
        raise InputError(f"origin must be LAT,LON[,HEADING] in degrees, got {text!r}")
    lat, lon = values[0], values[1]
    heading = values[2] if len(values) == 3 else 90.0
    if not (-90.0 < lat < 90.0 and -180.0 <= lon <= 180.0):
        raise InputError(f"origin latitude must lie in (-90, 90) and longitude in [-180, 180], got {lat}, {lon}")
    return lat, lon, heading


@dataclass(frozen=True)
class Georeference:
    """Where the map frame's origin lies on Earth and where its +x axis points."""

    lat: float
    lon: float
    heading: float = 90.0

    def _transformer(self, inverse: bool) -> Any:
        try:
            from pyproj import CRS, Transformer
        except ImportError as exc:
            raise MissingDependencyError("pyproj", "geo", "writing WGS84 coordinates") from exc
        local = CRS.from_proj4(f"+proj=aeqd +lat_0={self.lat!r} +lon_0={self.lon!r} +datum=WGS84 +units=m")
        source, target = (local, CRS.from_epsg(4326)) if not inverse else (CRS.from_epsg(4326), local)
        return Transformer.from_crs(source, target, always_xy=True)

    def to_lonlat(self, xy: ArrayLike) -> FloatArray:
        """``(K, 2)`` map x, y metres -> ``(K, 2)`` longitude, latitude degrees."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        theta = math.radians(self.heading)
        east = xy[:, 0] * math.sin(theta) - xy[:, 1] * math.cos(theta)
        north = xy[:, 0] * math.cos(theta) + xy[:, 1] * math.sin(theta)
        lon, lat = self._transformer(False).transform(east, north)
        return np.column_stack([lon, lat])

    def from_lonlat(self, lonlat: ArrayLike) -> FloatArray:
        """``(K, 2)`` longitude, latitude degrees -> ``(K, 2)`` map x, y metres."""
        lonlat = np.asarray(lonlat, dtype=np.float64).reshape(-1, 2)
        east, north = self._transformer(True).transform(lonlat[:, 0], lonlat[:, 1])
        theta = math.radians(self.heading)
        x = np.asarray(east) * math.sin(theta) + np.asarray(north) * math.cos(theta)
        y = -np.asarray(east) * math.cos(theta) + np.asarray(north) * math.sin(theta)
        return np.column_stack([x, y])


__all__ = ["Georeference", "parse_origin"]
