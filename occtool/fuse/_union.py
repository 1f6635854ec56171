"""The union of a run's many polygons, a group of overlapping ones at a time.

A run's navigation region and observed region are unions of one polygon a position. GEOS's
``union_all`` of them all holds its overlay's working set for the whole result at once
(about 250 bytes a vertex of the result: 1.6-1.7 GB for campus x10's 15,710 navigation
polygons, docs/map.md); unioned a group at a time, the working set is one group's. Polygons
whose bounding boxes (grown by ``margin``) do not overlap, directly or through others,
cannot share a point, so each group's union is the union's parts that lie in it.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray


def connected_labels(near: NDArray[np.intp], other: NDArray[np.intp], count: int) -> tuple[int, NDArray[np.intp]]:
    """The groups of ``count`` items linked, directly or through others, by the pairs
    ``near[k]``-``other[k]`` (an STRtree query's answer): how many, and each item's group."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    groups, label = connected_components(
        coo_matrix((np.ones(near.size, dtype=bool), (near.astype(np.int32), other.astype(np.int32))),
                   shape=(count, count)), directed=False)
    return int(groups), label


def overlapping_groups(bounds: NDArray[np.float64], margin: float = 0.0) -> list[NDArray[np.intp]]:
    """Indices of geometries in groups, from their bounding boxes ``(N, 4)`` (``shapely.bounds``:
    NaN for an empty geometry): two whose boxes, grown by ``margin``, overlap are in one
    group, and so, transitively, are their groups. The groups come in the order of their
    first member, each member in the order given; empty geometries are in no group."""
    import shapely

    bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 4)
    present = np.flatnonzero(~np.isnan(bounds).any(axis=1))
    if not present.size:
        return []
    bounds = bounds[present]
    boxes = shapely.box(bounds[:, 0] - margin, bounds[:, 1] - margin, bounds[:, 2] + margin, bounds[:, 3] + margin)
    near, other = shapely.STRtree(boxes).query(boxes)
    count, label = connected_labels(near, other, present.size)
    del near, other
    # Groups by their first member: the order the geometries came in.
    first = np.full(count, present.size, dtype=np.intp)
    np.minimum.at(first, label, np.arange(present.size))
    rank = np.empty(count, dtype=np.intp)
    rank[np.argsort(first, kind="stable")] = np.arange(count)
    order = np.argsort(rank[label], kind="stable")
    return np.split(present[order], np.cumsum(np.bincount(rank[label], minlength=count))[:-1])


def union_in_groups(geometries: Any, *, bounds: NDArray[np.float64] | None = None, margin: float = 0.0,
                    then: Callable[[Any], Any] | None = None) -> Any:
    """``shapely.union_all(geometries)``, a group of
    :func:`overlapping_groups` at a time, each group's union passed through ``then`` (a
    simplification, say, which ``margin`` keeps from meeting another group's) before the next
    is made; its polygons come group by group, in the groups' order.

    One group: that union (passed through ``then``), as ``union_all`` makes it. Several: a
    MultiPolygon of their polygons, the same point set as one union of them all, as GEOS
    builds each group's union (which may differ from the whole's in the last bits of a
    vertex, and in the order of the polygons).

    ``geometries``: an object array, or, with their ``bounds`` given, anything an index array
    takes a group of them from (:class:`occtool.fuse._outlines.SpilledOutlines`, read back a
    group at a time)."""
    import shapely

    if bounds is None:
        geometries = np.asarray(geometries, dtype=object)
        bounds = shapely.bounds(geometries)
    groups = overlapping_groups(bounds, margin)
    if len(groups) == 1:  # the union of them all, as one union_all makes it
        union = shapely.union_all(geometries[groups[0]])
        return union if then is None else then(union)
    parts = []
    for members in groups:
        union = shapely.union_all(geometries[members])
        if then is not None:
            union = then(union)
        pieces = shapely.get_parts(union)
        parts.append(pieces[shapely.get_type_id(pieces) == 3])  # polygons; a union of areas has no others
        del union
    return shapely.multipolygons(np.concatenate(parts)) if parts else shapely.MultiPolygon()


__all__ = ["connected_labels", "overlapping_groups", "union_in_groups"]
