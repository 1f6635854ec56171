"""Scoring a fused map on a real log: the Hilbert-maps held-out protocol.

:func:`evaluate_log` holds out 10 % of a log's scans in blocks of 40 consecutive scans
(Ramos and Ott's protocol for Hilbert maps, as used for BHM on the Intel lab), fuses
the local models of the remaining scans (:func:`occtool.fuse.fuse_log`), builds a dense
2D log-odds grid from the same training scans (OctoMap's hit/miss model, vectorised ray
traversal of :mod:`occtool.grid`) and scores both on the held-out beams: each beam's end
point is occupied; points drawn uniformly along the beam up to 0.1 m before its end are
free. ROC AUC (:func:`roc_auc`) with model bytes and build times.

Beside that grid, the textbook one (:func:`occtool.grid.textbook_grid`: each cell updated
once a scan, ``l_occ`` at the return, ``l_free`` before it, clamped after every scan) at
0.05 and 0.1 m, its settings tuned on an inner split of the training scans alone
(:func:`tune_textbook`), and with the textbook's fixed ones (:data:`TEXTBOOK_DEFAULTS`); and the counting-model
grid (:func:`occtool.grid.counting_grid`: per cell the share of the beams reaching it that
returned there), its prior tuned the same way (:func:`textbook_scores`).

The fused map's raster and the grid are also checked against their training scans
(:func:`nav2_agreement`): each return should fall on an occupied cell or one of its eight
neighbours, and the cells along each beam up to 0.1 m before its end should not be occupied.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError, MissingDependencyError
from occtool.features import Position
from occtool.fuse import COMBINATIONS, FREE, OCCUPIED, UNKNOWN, Raster
from occtool.grid import (
    OCTOMAP_DEFAULTS,
    TEXTBOOK_DEFAULTS,
    OccupancyGrid,
    WorldBeams,
    build_world_octomap,
    observation_log_odds,
    traverse,
)
from occtool.scoring._heldout import BLOCK, HOLDOUT, holdout_blocks, holdout_test_points, world_rays
from occtool.scoring._metrics import roc_auc
from occtool.scoring._nav2 import RAYS_PER_CHUNK, grid_raster, nav2_agreement
from occtool.scoring._tune import tune_grids

FloatArray = NDArray[np.float64]

def world_grid(scans: list[Position], resolution: float = 0.05) -> Any:
    """A dense 2D log-odds grid in the world frame from scans with poses (OctoMap's hit/miss
    model and clamping): an :class:`occtool.grid.OccupancyGrid` one cell thick, whose
    ``occupancy`` reads points at any z in the scans' plane."""
    starts, ends, returns, _ = world_rays(scans)
    flat_start = starts[:, :2]
    flat_end = ends[:, :2]
    lower = np.floor(np.minimum(flat_start.min(axis=0), flat_end.min(axis=0)) / resolution).astype(np.int64)
    upper = np.floor(np.maximum(flat_start.max(axis=0), flat_end.max(axis=0)) / resolution).astype(np.int64)
    shape = upper - lower + 1
    log_odds = np.zeros(int(shape[0] * shape[1]), dtype=np.float32)
    params = OCTOMAP_DEFAULTS
    lengths = np.hypot(*(flat_end - flat_start).T)
    for lo in range(0, lengths.size, RAYS_PER_CHUNK):
        hi = min(lengths.size, lo + RAYS_PER_CHUNK)
        start3 = np.column_stack([flat_start[lo:hi], np.full(hi - lo, 0.5 * resolution)])
        end3 = np.column_stack([flat_end[lo:hi], np.full(hi - lo, 0.5 * resolution)])
        seg = traverse(start3, end3, resolution)
        values = observation_log_odds(seg, lengths[lo:hi], returns[lo:hi].astype(np.float64),
                                      returns[lo:hi], None, params)
        index = (seg.cell[:, 0] - lower[0]) * shape[1] + (seg.cell[:, 1] - lower[1])
        np.add.at(log_odds, index, values.astype(np.float32))
    np.clip(log_odds, *params.clamp_log_odds, out=log_odds)
    return OccupancyGrid(log_odds.reshape(int(shape[0]), int(shape[1]), 1), float(resolution),
                         np.array([lower[0], lower[1], 0], dtype=np.int64), params=params)


@dataclass
class LogScore:
    """The figures of :func:`evaluate_log` (``as_dict`` for JSON)."""

    source: str
    scans: int
    held_out_scans: int
    training_positions: int
    #: The keyframes fitted and fused (``training_positions`` less those left out).
    fused_positions: int
    occupied_points: int
    free_points: int
    auc: dict[str, float]
    coverage: float
    fused_bytes: int
    grid_bytes: int
    fit_s: float
    raster_s: float
    grid_s: float
    nav2: dict[str, float]
    #: The same agreement for the dense grid of the training scans (read as Nav2 reads a map).
    nav2_grid: dict[str, float]
    #: OctoMap of the same training scans at ``resolution`` (``auc["octomap"]``): its
    #: ``memoryUsage()`` and build time, or ``None`` with the reason in ``octomap_note``
    #: (``pyoctomap`` not installed, or not asked for).
    octomap_bytes: int | None = None
    octomap_s: float | None = None
    octomap_note: str = ""
    #: The textbook grids (``auc["textbook_0.05m"]`` tuned, ``auc["textbook_fixed_0.05m"]`` the
    #: textbook's fixed setting, ``auc["counting_0.05m"]`` the counting model...): per name the chosen
    #: setting, its inner AUC, bytes at one byte a cell over the training box, and the
    #: candidates tried (:func:`textbook_scores`).
    textbook: dict[str, Any] | None = None
    #: Seconds to tune and build the textbook grids.
    textbook_s: float | None = None
    #: The world map (``auc["world"]``, :func:`occtool.fuse.build_world_map`): what
    #: ``world.occmap`` holds, in bytes, and its wall segments.
    world_bytes: int | None = None
    world_segments: int | None = None
    #: Where the test points fall on the Nav2 map (``auc["nav2_map"]``, the world map's
    #: raster read occupied 1, free 0, unknown 0.5): shares of the held-out returns on
    #: occupied, free and unknown cells, and of the free points on occupied and unknown ones.
    nav2_hits: dict[str, float] | None = None

    def as_dict(self) -> dict[str, Any]:
        from dataclasses import asdict

        return asdict(self)


def evaluate_log(path: str, template: Any, *, holdout: float = HOLDOUT, block: int = BLOCK, seed: int = 0,
                 resolution: float = 0.05, no_return_range: float | None = 5.0, threshold: float = 0.6,
                 read_options: dict[str, Any] | None = None, grid_resolutions: tuple[float, ...] = (),
                 keyframe_share: float | None = None, octomap: bool = True) -> LogScore:
    """Score the fused map of ``path``'s training scans against a dense 2D grid on held-out blocks.

    Parameters
    ----------
    path
        A range log with poses (a CARMEN log, say).
    template
        An unfitted :class:`occtool.fit.OccupancyRegressor` (robot, sensor, fit settings).
    holdout, block, seed
        The share of scans held out, in blocks of ``block`` consecutive scans, picked with ``seed``.
    resolution
        Cell size of the grid and of the fused map's raster (for the Nav2 agreement), metres.
    no_return_range
        Beams without a return become free rays this long (training only; only returns are tested).
    grid_resolutions
        Further grid cell sizes to score (``auc["grid_0.1m"]`` ...); ``auc["grid"]`` is at ``resolution``.
    keyframe_share
        :func:`occtool.fuse.fuse_log`'s keyframe selection (``None``: its default; 0: every
        training position is fitted). The test points and the grid do not depend on it.
    octomap
        Also build an OctoMap of the training scans at ``resolution``
        (:func:`occtool.grid.build_world_octomap`) and score it as ``auc["octomap"]``.
        Without ``pyoctomap`` (the ``octomap`` extra) the score says so in
        :attr:`LogScore.octomap_note` and has no OctoMap figures.

    The textbook grids at 0.05 and 0.1 m are always scored (:func:`textbook_scores`): tuned on
    an inner split of the training scans with the same ``holdout``, ``block`` and ``seed``,
    and with the textbook's fixed setting, and the counting-model grids (prior tuned the same
    way); :attr:`LogScore.textbook` holds their settings.
    """
    from occtool.fuse import fuse_log
    from occtool.io import read_log
    from occtool.io.positions import DEFAULT_POSITION_TOLERANCE, Scan, build_log

    options = dict(read_options or {})
    tolerance = options.pop("position_tolerance", DEFAULT_POSITION_TOLERANCE)
    options.pop("group_by", None)
    scan_log = read_log(path, group_by="message", no_return_range=no_return_range, **options)
    scans = scan_log.positions
    if any(s.pose is None for s in scans):
        raise InputError(f"{path}: scans without poses cannot be placed in a world map")
    held = holdout_blocks(len(scans), holdout, block, seed)
    train = [s for s, out in zip(scans, held) if not out]
    test = [s for s, out in zip(scans, held) if out]
    train_log = build_log([Scan(s.features.points, s.features.evidence, s.pose, s.stamp, s.source) for s in train],
                          source=str(path), tolerance=tolerance)
    from occtool.fuse import KEYFRAME_NEW_SHARE

    share = KEYFRAME_NEW_SHARE if keyframe_share is None else keyframe_share
    fused, _, report = fuse_log(train_log, template, threshold=threshold, keyframe_share=share)
    started = time.perf_counter()
    grid = world_grid(train, resolution)
    grid_s = time.perf_counter() - started
    occupied, free = holdout_test_points(test, seed=seed)
    points = np.concatenate([occupied, free])
    # One pass over the models gives every combination's figures.
    sums = fused._sums(points)
    auc = {}
    for combination in COMBINATIONS:
        p = sums.evidence(combination).probability
        auc[f"fused_{combination}"] = roc_auc(p[:len(occupied)], p[len(occupied):])
    observed = sums.count > 0
    grid_p = grid.occupancy(np.column_stack([points[:, :2], np.full(len(points), 0.5 * resolution)]))
    auc["grid"] = roc_auc(grid_p[:len(occupied)], grid_p[len(occupied):])
    # Coarser grids blur walls into the free points near them but fill gaps between beams:
    # the grid is scored at each, so the comparison is with its best.
    for size in grid_resolutions:
        other = world_grid(train, size)
        other_p = other.occupancy(np.column_stack([points[:, :2], np.full(len(points), 0.5 * size)]))
        auc[f"grid_{size:g}m"] = roc_auc(other_p[:len(occupied)], other_p[len(occupied):])
    started = time.perf_counter()
    textbook_auc, textbook = textbook_scores(train, points, len(occupied), holdout=holdout, block=block, seed=seed)
    textbook_s = time.perf_counter() - started
    auc.update(textbook_auc)
    octomap_figures: dict[str, Any] = (_octomap_scores(train, points, len(occupied), resolution) if octomap
                                       else {"octomap_note": "not asked for"})
    octomap_auc: dict[str, float] = octomap_figures.pop("auc", {})
    auc.update(octomap_auc)
    from occtool.fuse import build_world_map

    started = time.perf_counter()
    world = build_world_map(fused, sightings=report.sightings)
    world_p = world.predict(points)
    auc["world"] = roc_auc(world_p[:len(occupied)], world_p[len(occupied):])
    raster = world.rasterise(resolution)
    raster_s = time.perf_counter() - started
    nav2_p, nav2_hits = _trinary(raster, points, len(occupied))
    auc["nav2_map"] = roc_auc(nav2_p[:len(occupied)], nav2_p[len(occupied):])
    return LogScore(
        source=str(path), scans=len(scans), held_out_scans=int(held.sum()),
        training_positions=len(fused) + len(report.not_keyframes) + len(report.skipped), fused_positions=len(fused),
        occupied_points=len(occupied), free_points=len(free), auc=auc, coverage=float(observed.mean()),
        fused_bytes=fused.nbytes, grid_bytes=int(grid.nbytes), fit_s=report.fit_seconds, raster_s=raster_s,
        grid_s=grid_s, nav2=nav2_agreement(raster, train), nav2_grid=nav2_agreement(grid_raster(grid), train),
        textbook=textbook, textbook_s=textbook_s, world_bytes=world.nbytes, world_segments=len(world),
        nav2_hits=nav2_hits, **octomap_figures,
    )


def _trinary(raster: Raster, points: FloatArray, n_occupied: int) -> tuple[FloatArray, dict[str, float]]:
    """A Nav2 raster read as map_server's trinary map at ``points`` (occupied 1, free 0,
    unknown 0.5, outside unknown) and where the first ``n_occupied`` (returns) and the
    rest (free points) fall."""
    row, col, inside = raster.cell_of(points[:, :2])
    cells = np.where(inside, raster.cells[row, col], UNKNOWN)
    p = np.where(cells == OCCUPIED, 1.0, np.where(cells == FREE, 0.0, 0.5))
    returns, free = cells[:n_occupied], cells[n_occupied:]
    hits = {"returns_on_occupied": float(np.mean(returns == OCCUPIED)),
            "returns_on_free": float(np.mean(returns == FREE)),
            "returns_on_unknown": float(np.mean(returns == UNKNOWN)),
            "free_on_occupied": float(np.mean(free == OCCUPIED)),
            "free_on_unknown": float(np.mean(free == UNKNOWN))}
    return p, hits


def _beams(scans: list[Position]) -> WorldBeams:
    """The scans' beams in the world plane."""
    starts, ends, returns, owner = world_rays(scans)
    return WorldBeams(starts[:, :2], ends[:, :2], returns, owner)


def textbook_scores(train: list[Position], points: FloatArray, n_occupied: int, *, holdout: float = HOLDOUT,
                    block: int = BLOCK, seed: int = 0,
                    resolutions: tuple[float, ...] = (0.05, 0.1)) -> tuple[dict[str, float], dict[str, Any]]:
    """AUC of the textbook grids of ``train`` on the test ``points`` (the first ``n_occupied`` occupied).

    The settings are tuned by :func:`tune_grids` on ``train`` alone (an inner
    split ``holdout`` / ``block`` / ``seed`` of those scans); ``points`` are read only by
    the grids it returns. Returns ``auc`` (``textbook_0.05m``: the log-odds grid tuned,
    ``textbook_fixed_0.05m``: l_occ 0.85, l_free -0.4, clamp [-2, 3.5], ``counting_0.05m``:
    the counting-model grid, its prior tuned; and so on per resolution) and per name the
    setting, inner AUC and bytes at one byte a cell.
    """
    tuned, counting = tune_grids(_beams(train), resolutions=resolutions, holdout=holdout, block=block, seed=seed)
    auc: dict[str, float] = {}
    settings: dict[str, Any] = {}
    for resolution, result in tuned.items():
        for name, grid in ((f"textbook_{resolution:g}m", result.grid),
                           (f"textbook_fixed_{resolution:g}m", result.default_grid),
                           (f"counting_{resolution:g}m", counting[resolution].grid)):
            p = grid.occupancy(points)
            auc[name] = roc_auc(p[:n_occupied], p[n_occupied:])
        settings[f"textbook_{resolution:g}m"] = result.as_dict()
        settings[f"textbook_fixed_{resolution:g}m"] = {**TEXTBOOK_DEFAULTS.as_dict(), "resolution": resolution,
                                                        "bytes": result.default_grid.byte_size}
        settings[f"counting_{resolution:g}m"] = counting[resolution].as_dict()
    return auc, settings


def _octomap_scores(train: list[Position], points: FloatArray, n_occupied: int, resolution: float) -> dict[str, Any]:
    """OctoMap's AUC on the test points, its bytes and build time; a note instead without pyoctomap."""
    scans = []
    for scan in train:
        pose = scan.pose
        assert pose is not None, "scored scans have poses"
        scans.append((pose.translation, scan.features.points @ pose.rotation.T + pose.translation,
                      scan.features.evidence))
    started = time.perf_counter()
    try:
        model = build_world_octomap(scans, resolution=resolution)
    except MissingDependencyError as exc:
        return {"octomap_note": str(exc)}
    seconds = time.perf_counter() - started
    p = model.occupancy(points)
    return {"auc": {"octomap": roc_auc(p[:n_occupied], p[n_occupied:])}, "octomap_bytes": model.memory_bytes,
            "octomap_s": seconds}


__all__ = ["LogScore", "evaluate_log", "textbook_scores", "world_grid"]
