"""Navigation maps as GeoJSON (a FeatureCollection or a newline-delimited feature sequence),
and the layers of a run's map (:func:`run_map_layers`): occtool's one GeoJSON writer.

One Polygon feature ``{"kind": "navigation"}``, Point features ``{"kind": "obstacle",
"reinforcement": -1}`` and ``{"kind": "exploration", "reinforcement": 1}``, and optionally
one Polygon per height ``{"kind": "slice", "height": h}``. Polygons follow RFC 7946 ring
orientation (outer rings counter-clockwise).

Coordinates are metric x, y in the robot frame (``base_link``, REP-103) or, with a pose,
in a world frame, *not* longitude/latitude as RFC 7946 readers assume: the collection's
``properties`` say so (``frame_id``, ``units``, ``crs_note``) with the extraction
parameters. A sequence (RFC 8142 style, as rasterio's ``--sequence``) has no collection,
so there the navigation feature's properties carry those parameters.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from shapely.geometry import Polygon, shape
from shapely.geometry.base import BaseGeometry
from shapely.geometry.polygon import orient

from occtool import _json as safe_json
from occtool._files import atomic_write
from occtool._json import read_text
from occtool.errors import InputError
from occtool.features import Pose
from occtool.limits import collector_paused
from occtool.navigation import NavigationMap, Slice

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from occtool.formats.wgs84 import Georeference

CRS_NOTE = (
    "coordinates are metric x, y (metres) in frame_id, x forward and y left (REP-103), "
    "not longitude/latitude"
)
# Properties written for every map; read back into the NavigationMap fields of the same name.
_NUMBER_FIELDS = (
    "threshold", "effective_threshold", "robot_radius", "max_range", "point_spacing",
    "sensor_height", "body_height", "ground_clearance", "margin", "return_snap",
)
_RECORD_SEPARATOR = "\x1e"


def map_properties(nav: NavigationMap) -> dict[str, Any]:
    """The metadata of a navigation map, as written in the collection's ``properties``.

    Parameters
    ----------
    nav
        The map.

    Returns
    -------
    dict
        ``frame_id``, ``units``, ``crs_note``, the thresholds, heights, robot geometry,
        max range, angles, point spacing, and ``pose`` for a map in a world frame.
    """
    properties: dict[str, Any] = {
        "frame_id": nav.frame_id,
        "units": "m",
        "crs_note": CRS_NOTE,
        # Heights are computed (midpoints, added cuts): a nanometre is precise enough.
        "heights": [round(float(h), 9) for h in nav.heights],
        "slice_heights": [round(float(h), 9) for h in nav.slice_heights],
        "n_angles": int(nav.n_angles),
        "straight_line": bool(nav.straight_line),
    }
    for name in _NUMBER_FIELDS:
        value = float(getattr(nav, name))
        properties[name] = value if math.isfinite(value) else None
    if nav.pose is not None:
        properties["pose"] = nav.pose.to_dict()
    for key, extra in nav.extra.items():
        properties.setdefault(key, extra)
    return properties


def _rounded(coordinates: np.ndarray, precision: int | None) -> list:
    return (coordinates if precision is None else np.round(coordinates, precision)).tolist()


def _polygon_geometry(polygon: BaseGeometry, precision: int | None, *, orient_rings: bool = True) -> dict[str, Any]:
    """A Polygon's or MultiPolygon's geometry; ``orient_rings=False`` keeps the rings as
    they are (a run map orients its rings before the grid snap, which may turn them)."""
    if polygon.is_empty:
        return {"type": "Polygon", "coordinates": []}
    if polygon.geom_type == "MultiPolygon":
        return {
            "type": "MultiPolygon",
            "coordinates": [_polygon_geometry(part, precision, orient_rings=orient_rings)["coordinates"]
                            for part in polygon.geoms],
        }
    if orient_rings:
        polygon = orient(polygon, sign=1.0)  # RFC 7946: outer ring counter-clockwise, holes clockwise
    rings = [polygon.exterior, *polygon.interiors]
    return {"type": "Polygon", "coordinates": [_rounded(np.asarray(ring.coords)[:, :2], precision) for ring in rings]}


def _point_features(points: np.ndarray, kind: str, reinforcement: int, precision: int | None) -> Iterator[dict]:
    for xy in _rounded(np.asarray(points, dtype=np.float64).reshape(-1, 2), precision):
        yield {
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": xy},
            "properties": {"kind": kind, "reinforcement": reinforcement},
        }


def navigation_features(
    nav: NavigationMap,
    *,
    pose: Pose | None = None,
    precision: int | None = None,
    include_slices: bool = False,
    with_metadata: bool = False,
    position: int | None = None,
) -> Iterator[dict[str, Any]]:
    """The features of a navigation map, one GeoJSON Feature dict at a time.

    Parameters
    ----------
    nav
        The map.
    pose
        The robot's world pose: coordinates are moved into the ``map`` frame by it.
    precision
        Decimal places of the coordinates (default: full precision).
    include_slices
        Also yield one Polygon per requested height (``kind`` ``slice``, ``height``).
    with_metadata
        Put the map's parameters (:func:`map_properties`) into the navigation feature's
        properties too, for a feature sequence that has no collection to hold them.

    Yields
    ------
    dict
        The navigation polygon, obstacle points, exploration points, then slices.
    """
    if pose is not None:
        nav = nav.in_world(pose)
    tag = {} if position is None else {"position": int(position)}
    properties: dict[str, Any] = {"kind": "navigation", **tag}
    if with_metadata:
        properties.update(map_properties(nav))
    yield {"type": "Feature", "geometry": _polygon_geometry(nav.polygon, precision), "properties": properties}
    for feature in _point_features(nav.obstacle_points, "obstacle", -1, precision):
        feature["properties"].update(tag)
        yield feature
    for feature in _point_features(nav.exploration_points, "exploration", 1, precision):
        feature["properties"].update(tag)
        yield feature
    if include_slices:
        for item in nav.slices:
            yield {
                "type": "Feature",
                "geometry": _polygon_geometry(item.polygon, precision),
                "properties": {"kind": "slice", "height": float(item.height), **tag},
            }


def navigation_to_geojson(
    nav: NavigationMap, *, pose: Pose | None = None, precision: int | None = None, include_slices: bool = False
) -> dict[str, Any]:
    """A navigation map as a GeoJSON FeatureCollection.

    Parameters
    ----------
    nav
        The map.
    pose
        The robot's world pose: coordinates are moved into the ``map`` frame by it and
        the collection's ``frame_id`` says so.
    precision
        Decimal places of the coordinates (default: full precision).
    include_slices
        Also include one Polygon per requested height.

    Returns
    -------
    dict
        ``{"type": "FeatureCollection", "properties": {...}, "features": [...]}``.

    Examples
    --------
    >>> import numpy as np
    >>> from occtool.navigation import navigation_map
    >>> from occtool.robot import Robot
    >>> nav = navigation_map(lambda a, h, m: np.full(np.broadcast(a, h).shape, np.inf), robot=Robot())
    >>> collection = navigation_to_geojson(nav, precision=3)
    >>> collection["properties"]["frame_id"], collection["features"][0]["properties"]["kind"]
    ('base_link', 'navigation')
    """
    moved = nav if pose is None else nav.in_world(pose)
    return {
        "type": "FeatureCollection",
        "properties": map_properties(moved),
        "features": list(navigation_features(moved, precision=precision, include_slices=include_slices)),
    }


def write_navigation(
    nav: NavigationMap,
    path_or_dash: str | os.PathLike[str],
    *,
    sequence: bool = False,
    indent: int | None = None,
    pose: Pose | None = None,
    precision: int | None = None,
    include_slices: bool = False,
    overwrite: bool = True,
) -> None:
    """Write a navigation map as GeoJSON, completely or not at all.

    Parameters
    ----------
    nav
        The map.
    path_or_dash
        Output file, or ``"-"`` for standard output.
    sequence
        Write newline-delimited features (one compact Feature per line, as rasterio's
        ``--sequence``) instead of one FeatureCollection; the navigation feature then
        carries the map's parameters.
    indent
        JSON indentation of a collection (default: compact).
    pose, precision, include_slices
        As for :func:`navigation_to_geojson`.
    overwrite
        If false, refuse to replace an existing file.
    """
    with atomic_write(path_or_dash, "w", overwrite=overwrite) as handle:
        if sequence:
            for feature in navigation_features(
                nav, pose=pose, precision=precision, include_slices=include_slices, with_metadata=True
            ):
                handle.write(json.dumps(feature, allow_nan=False) + "\n")
        else:
            collection = navigation_to_geojson(nav, pose=pose, precision=precision, include_slices=include_slices)
            handle.write(json.dumps(collection, indent=indent, allow_nan=False) + "\n")


# Parameters that differ between the maps of a model set: listed per position.
_PER_POSITION = ("effective_threshold", "margin", "slice_heights", "pose", "frame_id")


def navigation_set_to_geojson(
    maps: Sequence[tuple[int, NavigationMap]], *, precision: int | None = None, include_slices: bool = False
) -> dict[str, Any]:
    """The maps of several robot positions as one FeatureCollection.

    Every feature's properties carry its ``position``; the collection's properties hold
    the parameters the maps share and, under ``positions``, what differs per position
    (pose, effective threshold, cuts).

    Parameters
    ----------
    maps
        ``(position, map)`` pairs, the maps already in the frame to write (see
        :meth:`~occtool.navigation.NavigationMap.in_world`).
    precision, include_slices
        As for :func:`navigation_to_geojson`.

    Returns
    -------
    dict
        A FeatureCollection; :func:`read_navigation` with ``position=`` reads one map back.
    """
    if not maps:
        raise InputError("no navigation maps to write")
    frames = {nav.frame_id for _, nav in maps}
    if len(frames) > 1:
        raise InputError(f"the maps are in different frames ({', '.join(sorted(frames))})")
    properties = {k: v for k, v in map_properties(maps[0][1]).items() if k not in _PER_POSITION}
    properties["frame_id"] = frames.pop()
    properties["positions"] = [
        {
            "position": int(position),
            **{k: v for k, v in map_properties(nav).items() if k in _PER_POSITION and k != "frame_id"},
        }
        for position, nav in maps
    ]
    features = [
        feature
        for position, nav in maps
        for feature in navigation_features(nav, precision=precision, include_slices=include_slices, position=position)
    ]
    return {"type": "FeatureCollection", "properties": properties, "features": features}


def write_navigation_set(
    maps: Sequence[tuple[int, NavigationMap]],
    path_or_dash: str | os.PathLike[str],
    *,
    sequence: bool = False,
    indent: int | None = None,
    precision: int | None = None,
    include_slices: bool = False,
    overwrite: bool = True,
) -> None:
    """Write the maps of several robot positions to one GeoJSON file (or sequence).

    Parameters are those of :func:`write_navigation`; each map's navigation feature in
    a sequence carries its own parameters and every feature its ``position``.
    """
    if not maps:
        raise InputError("no navigation maps to write")
    with atomic_write(path_or_dash, "w", overwrite=overwrite) as handle:
        if sequence:
            for position, nav in maps:
                for feature in navigation_features(
                    nav, precision=precision, include_slices=include_slices, with_metadata=True, position=position
                ):
                    handle.write(json.dumps(feature, allow_nan=False) + "\n")
        else:
            collection = navigation_set_to_geojson(maps, precision=precision, include_slices=include_slices)
            handle.write(json.dumps(collection, indent=indent, allow_nan=False) + "\n")


#: The GeoJSON layers of a run's map, ``occtool map``'s (file stem -> their features' ``kind``).
RUN_MAP_LAYERS = {"navigation": "navigation", "obstacles": "obstacle", "frontiers": "frontier"}


def run_map_layers(navigation: BaseGeometry | None, obstacles: ArrayLike, frontiers: ArrayLike, *,
                   simplify: float | None = None, precision: int | None = None,
                   georeference: Georeference | None = None, lazy: bool = False) -> dict[str, dict[str, Any]]:
    """The GeoJSON layers of a run's map, one geometry type each (``occtool map`` writes
    them as ``navigation.geojson``, ``obstacles.geojson`` and ``frontiers.geojson``).

    Parameters
    ----------
    navigation
        The navigation region in the ``map`` frame: one Polygon feature per part.
    obstacles, frontiers
        ``(K, 2)`` x, y in the ``map`` frame: one Point feature each.
    simplify
        Tolerance in metres of a topology-preserving simplification of the region.
    precision
        Decimal places: points are rounded, polygons snapped to a grid of
        ``10**-precision`` (whose rings then come out as GEOS builds them).
    georeference
        Write WGS84 longitude/latitude (RFC 7946) instead of metric map x, y.
    lazy
        Each collection's ``features`` an iterator that makes them one at a time, for
        :func:`dump_collection` to write as it goes (a large run's layers are never held
        whole as Python lists), instead of a list.

    Returns
    -------
    dict
        ``{"navigation": ..., "obstacles": ..., "frontiers": ...}``, FeatureCollections
        whose ``properties`` say the frame and units.
    """
    if simplify is not None:
        if not (math.isfinite(simplify) and simplify >= 0):
            raise InputError(f"simplify tolerance must be a number of metres >= 0, got {simplify}")
        navigation = shapely.simplify(navigation, simplify, preserve_topology=True)
    parts = [] if navigation is None or navigation.is_empty else (
        [navigation] if navigation.geom_type == "Polygon" else
        [g for g in getattr(navigation, "geoms", []) if g.geom_type == "Polygon" and not g.is_empty])
    properties: dict[str, Any] = {"frame": "map", "units": "m",
                                  "crs_note": "metric x, y in the map frame, not longitude/latitude"}
    if georeference is not None:
        obstacles, frontiers = georeference.to_lonlat(obstacles), georeference.to_lonlat(frontiers)
        properties = {"frame": "WGS84", "units": "degrees",
                      "origin": {"lat": georeference.lat, "lon": georeference.lon, "heading": georeference.heading}}

    def polygon(part: BaseGeometry) -> dict[str, Any]:
        part = orient(part, sign=1.0)
        if georeference is not None:
            # A rotation and an azimuthal projection: rings keep their orientation.
            part = shapely.transform(part, georeference.to_lonlat)
        if precision is not None:
            part = shapely.set_precision(part, 10.0 ** -precision)
        # Polygons are oriented before the transform and the snap, and written as those leave them.
        return _polygon_geometry(part, None, orient_rings=False)

    def points(values: ArrayLike) -> Iterator[dict[str, Any]]:
        xy = np.asarray(values, dtype=np.float64).reshape(-1, 2)
        for low in range(0, xy.shape[0], _POINTS_AT_ONCE):
            yield from ({"type": "Point", "coordinates": p} for p in _rounded(xy[low:low + _POINTS_AT_ONCE], precision))

    geometries = {"navigation": (polygon(part) for part in parts), "obstacles": points(obstacles),
                  "frontiers": points(frontiers)}

    def features(layer: str, kind: str) -> Iterator[dict[str, Any]]:
        return ({"type": "Feature", "properties": {"kind": kind}, "geometry": geometry}
                for geometry in geometries[layer])

    return {layer: {"type": "FeatureCollection", "properties": {**properties, "kind": kind},
                    "features": features(layer, kind) if lazy else list(features(layer, kind))}
            for layer, kind in RUN_MAP_LAYERS.items()}


#: The end of a collection's features (:func:`dump_collection`).
_END = object()

#: Points turned into Python lists at a time by a lazy layer (:func:`run_map_layers`).
_POINTS_AT_ONCE = 1 << 16


def dump_collection(collection: Mapping[str, Any], handle: Any) -> None:
    """Write ``collection`` (a GeoJSON object whose ``features`` may be any iterable, e.g. a
    lazy layer of :func:`run_map_layers`) to the text stream ``handle`` as compact JSON: the
    same text as ``json.dump(collection, handle, separators=(",", ":"))``, each feature
    encoded on its own (by the C encoder, which ``json.dump`` does not use)."""
    handle.write("{")
    for n, (key, value) in enumerate(collection.items()):
        handle.write(("," if n else "") + json.dumps(key) + ":")
        if key != "features":
            handle.write(json.dumps(value, separators=(",", ":")))
            continue
        handle.write("[")
        features, separator = iter(value), ""
        while True:
            # A feature made and encoded without the cyclic collector: its lists (one a
            # vertex) go with their reference counts (occtool.limits.collector_paused).
            with collector_paused():
                feature = next(features, _END)
                if feature is _END:
                    break
                text = json.dumps(feature, separators=(",", ":"))
                del feature
            handle.write(separator + text)
            separator = ","
        handle.write("]")
    handle.write("}")


# --- reading ------------------------------------------------------------------------------


def _parse(text: str, source: str) -> tuple[list[Any], dict[str, Any]]:
    """Features and collection properties of a collection, a single feature or a sequence."""
    stripped = text.lstrip(_RECORD_SEPARATOR + " \t\r\n")
    if not stripped:
        raise InputError(f"{source}: the file is empty")
    try:
        document = safe_json.loads(stripped)
        documents = [document]
    except json.JSONDecodeError as exc:
        # A sequence: one JSON text per line, each optionally after an RS (RFC 8142).
        documents = []
        for number, line in enumerate(text.splitlines(), start=1):
            line = line.strip().lstrip(_RECORD_SEPARATOR).strip()
            if not line:
                continue
            try:
                documents.append(safe_json.loads(line))
            except json.JSONDecodeError as line_error:
                first = exc if len(documents) == 0 and number == 1 else line_error
                raise InputError(f"{source}: not valid GeoJSON (line {number}: {first.msg})") from None
    if len(documents) == 1 and isinstance(documents[0], Mapping) and documents[0].get("type") == "FeatureCollection":
        collection = documents[0]
        features = collection.get("features")
        if not isinstance(features, list):
            raise InputError(f"{source}: the FeatureCollection has no 'features' list")
        properties = collection.get("properties") or {}
        if not isinstance(properties, Mapping):
            raise InputError(f"{source}: the collection's 'properties' is not an object")
        return features, dict(properties)
    for number, document in enumerate(documents, start=1):
        if not isinstance(document, Mapping) or document.get("type") != "Feature":
            raise InputError(
                f"{source}: item {number} is not a GeoJSON Feature (expected a FeatureCollection or a feature sequence)"
            )
    return documents, {}


def _geometry(feature: Mapping[str, Any], kinds: tuple[str, ...], source: str, what: str) -> BaseGeometry:
    data = feature.get("geometry")
    if not isinstance(data, Mapping) or data.get("type") not in kinds:
        raise InputError(f"{source}: the {what} geometry is not a {' or '.join(kinds)}")
    try:
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            # NaN coordinates are reported below, without shapely's RuntimeWarning.
            warnings.simplefilter("ignore", RuntimeWarning)
            geometry = shape(data)
    except (TypeError, ValueError, KeyError, IndexError, AttributeError, shapely.errors.ShapelyError) as exc:
        raise InputError(f"{source}: the {what} geometry is malformed ({exc})") from None
    coordinates = shapely.get_coordinates(geometry)
    if not np.isfinite(coordinates).all():
        raise InputError(f"{source}: the {what} geometry has a coordinate that is not a finite number")
    return geometry


def _number(properties: Mapping[str, Any], name: str, source: str, default: float = math.nan) -> float:
    value = properties.get(name)
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{source}: property {name!r} must be a number, got {value!r}")
    return float(value)


def _numbers(properties: Mapping[str, Any], name: str, source: str) -> tuple[float, ...]:
    value = properties.get(name, [])
    if not isinstance(value, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        raise InputError(f"{source}: property {name!r} must be a list of numbers, got {value!r}")
    return tuple(float(v) for v in value)


def read_navigation(path: str | os.PathLike[str], position: int | None = None) -> NavigationMap:
    """Read a navigation map written by :func:`write_navigation` (collection or sequence).

    Parameters
    ----------
    path
        The GeoJSON file.
    position
        For a file holding the maps of several positions (:func:`write_navigation_set`):
        the position whose map to read.

    Returns
    -------
    NavigationMap
        Polygon, points, slices and the parameters the file records (NaN where it
        records none, as in a hand-written file with just a navigation polygon).

    Raises
    ------
    InputError
        If the file is not JSON, not a FeatureCollection or feature sequence, has not
        exactly one ``navigation`` Polygon, or has a malformed geometry or property; the
        message names the file and what is wrong.
    """
    source = os.fspath(path)
    text = read_text(path, error=InputError)
    features, properties = _parse(text, source)
    if position is not None:
        features = [
            f for f in features
            if isinstance(f, Mapping) and isinstance(f.get("properties"), Mapping)
            and f["properties"].get("position") == position
        ]
        if not features:
            raise InputError(f"{source}: holds no map of position {position}")
        listed = properties.pop("positions", [])
        listed = listed if isinstance(listed, list) else []
        per_position = [p for p in listed if isinstance(p, Mapping) and p.get("position") == position]
        properties.update({k: v for p in per_position for k, v in p.items() if k != "position"})
    elif isinstance(properties.get("positions"), list):
        raise InputError(f"{source}: holds the maps of several positions; choose one (position=)")
    navigation: list[BaseGeometry] = []
    obstacles: list[tuple[float, float]] = []
    exploration: list[tuple[float, float]] = []
    slices: list[Slice] = []
    for number, feature in enumerate(features, start=1):
        if not isinstance(feature, Mapping) or feature.get("type") != "Feature":
            raise InputError(f"{source}: feature {number} is not a GeoJSON Feature")
        feature_properties = feature.get("properties") or {}
        if not isinstance(feature_properties, Mapping):
            raise InputError(f"{source}: feature {number}'s 'properties' is not an object")
        kind = feature_properties.get("kind")
        if kind == "navigation":
            navigation.append(_geometry(feature, ("Polygon",), source, "navigation"))
            # A sequence carries the map's parameters on its navigation feature.
            properties = {**{k: v for k, v in feature_properties.items() if k != "kind"}, **properties}
        elif kind in ("obstacle", "exploration"):
            point = _geometry(feature, ("Point",), source, f"{kind} point (feature {number})")
            if point.is_empty:
                raise InputError(f"{source}: the {kind} point (feature {number}) has no coordinates")
            (obstacles if kind == "obstacle" else exploration).append((point.x, point.y))
        elif kind == "slice":
            height = _number(feature_properties, "height", source)
            if not math.isfinite(height):
                raise InputError(f"{source}: slice feature {number} has no numeric 'height'")
            slices.append(Slice(height, _geometry(feature, ("Polygon",), source, f"slice (feature {number})")))
    if len(navigation) != 1:
        raise InputError(f"{source}: expected one feature of kind 'navigation', found {len(navigation)}")
    pose = properties.get("pose")
    if pose is not None:
        if not isinstance(pose, Mapping):
            raise InputError(f"{source}: property 'pose' must be an object with x, y, yaw")
        try:
            pose = Pose.from_dict(pose)
        except (TypeError, ValueError):
            raise InputError(f"{source}: property 'pose' must hold numbers x, y, z, yaw") from None
    known = {*_NUMBER_FIELDS, "frame_id", "units", "crs_note", "heights", "slice_heights", "n_angles", "pose",
             "kind", "position", "positions", "straight_line"}
    straight_line = properties.get("straight_line", True)
    if not isinstance(straight_line, bool):
        raise InputError(f"{source}: property 'straight_line' must be true or false, got {straight_line!r}")
    numbers = {name: _number(properties, name, source) for name in _NUMBER_FIELDS}
    for name in ("margin", "return_snap"):  # absent from older files: neither was applied
        numbers[name] = 0.0 if math.isnan(numbers[name]) else numbers[name]
    for name, default in (("sensor_height", 1.0), ("body_height", 1.0), ("ground_clearance", 0.05)):
        numbers[name] = default if math.isnan(numbers[name]) else numbers[name]
    n_angles = _number(properties, "n_angles", source, default=0.0)
    return NavigationMap(
        polygon=navigation[0] if isinstance(navigation[0], Polygon) else Polygon(),
        slices=sorted(slices, key=lambda item: item.height),
        obstacle_points=np.asarray(obstacles, dtype=np.float64).reshape(-1, 2),
        exploration_points=np.asarray(exploration, dtype=np.float64).reshape(-1, 2),
        heights=_numbers(properties, "heights", source),
        slice_heights=_numbers(properties, "slice_heights", source),
        n_angles=int(n_angles),
        frame_id=str(properties.get("frame_id", "base_link")),
        straight_line=straight_line,
        pose=pose,
        extra={k: v for k, v in properties.items() if k not in known},
        **numbers,
    )


def read_navigation_maps(path: str | os.PathLike[str]) -> list[tuple[int | None, NavigationMap]]:
    """Every map in a navigation GeoJSON file, with the robot position each belongs to.

    A file of one map (:func:`write_navigation`) gives ``[(None, map)]``; a file of a
    model set (:func:`write_navigation_set`: a collection or a sequence whose features
    carry ``position``) gives one ``(position, map)`` per position, in position order.

    Raises
    ------
    InputError
        If the file is not a navigation map (the message names the file).
    """
    source = os.fspath(path)
    text = read_text(path, error=InputError)
    features, _ = _parse(text, source)
    tags = {feature["properties"].get("position") for feature in features
            if isinstance(feature, Mapping) and isinstance(feature.get("properties"), Mapping)}
    positions = sorted(t for t in tags if isinstance(t, int) and not isinstance(t, bool))
    if not positions:
        return [(None, read_navigation(path))]
    return [(position, read_navigation(path, position=position)) for position in positions]


__all__ = [
    "CRS_NOTE",
    "RUN_MAP_LAYERS",
    "map_properties",
    "navigation_features",
    "navigation_set_to_geojson",
    "navigation_to_geojson",
    "read_navigation",
    "read_navigation_maps",
    "dump_collection",
    "run_map_layers",
    "write_navigation",
    "write_navigation_set",
]
