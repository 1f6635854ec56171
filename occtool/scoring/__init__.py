"""Scoring: held-out test points, the metrics, and the scores of navigation polygons and of maps of logs.

Every score occtool reports is computed here; the models and maps it scores are built
elsewhere (:mod:`occtool.fit`, :mod:`occtool.fuse`, the baselines of :mod:`occtool.grid`).

The parts, one concept a module (private; everything public is imported from here):

=============  ===========================================================================
``_heldout``   which scans or features are held out and the test points drawn from them:
               :func:`holdout_blocks` and :func:`beam_test_points` (the one generator, for
               the log scorer and the grid tuner alike), :func:`holdout_test_points`,
               :func:`split_holdout`, :func:`holdout_points` (``compare-grid``'s features)
``_metrics``   :func:`roc_auc`, :func:`grouped_auc` (the same figure from per-cell counts),
               :func:`polygon_iou`
``_rays``      the truth's own ray caster (numpy only), deliberately not the navigation
               maps' one: a bug there must not hide in the map and its judge alike
``_polygon``   a navigation polygon against a scene's truth: :func:`evaluate_navigation`
               (IoU, violation), :func:`reachable_region`, ... (``occtool evaluate``)
``_tune``      :func:`tune_grids`, :func:`tune_textbook`, :func:`tune_counting`: the textbook
               grids' settings picked by their score on an inner split of training scans
``_nav2``      :func:`nav2_agreement`: a map's raster against the scans it was built from
``_log``       :func:`evaluate_log`: a fused map of a log, the grids and OctoMap scored on
               held-out scans (``occtool evaluate-log``)
=============  ===========================================================================

Layers (each imports only those before it): :mod:`occtool.grid` (the baselines; imports
no scorer) -> ``_heldout``, ``_metrics`` (numpy, scipy and shapely only, so any scorer can
use them), ``_rays`` -> ``_polygon``, ``_tune``, ``_nav2`` -> ``_log`` -> :mod:`occtool.compare`
(which scores the parametric model against the baselines with these). The grid tuners
sit here rather than in :mod:`occtool.grid` because they choose a grid by its held-out
score: the grids stay free of scoring, and there is one generator of held-out points.

The names are imported on first use (PEP 562): ``compare-grid`` needs the metrics, not
the log scorer's fusion.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from occtool._lazy import lazy_attributes

_HELDOUT = ("BLOCK", "END_MARGIN", "FREE_FRACTIONS", "FREE_POINTS_PER_BEAM", "HOLDOUT", "beam_test_points",
            "holdout_blocks", "holdout_points", "holdout_test_points", "in_front_of_first_obstacle", "split_holdout",
            "world_rays")
_METRICS = ("grouped_auc", "polygon_iou", "roc_auc")
_POLYGON = ("Evaluation", "as_polygon", "blind_radius", "blocking_obstacles", "configuration_obstacles",
            "evaluate_navigation", "observable_footprints", "reachable_region", "returns_within_body",
            "robot_frame_points", "robot_frame_polygon", "true_reach", "violation_by_observability")
_TUNE = ("TunedCounting", "TunedGrid", "tune_counting", "tune_grids", "tune_textbook")
_NAV2 = ("grid_raster", "nav2_agreement")
_LOG = ("LogScore", "evaluate_log", "textbook_scores", "world_grid")

# public name -> module that defines it, imported on first use.
_LAZY: dict[str, str] = {
    name: f"occtool.scoring.{module}"
    for module, names in (("_heldout", _HELDOUT), ("_metrics", _METRICS), ("_polygon", _POLYGON),
                          ("_tune", _TUNE), ("_nav2", _NAV2), ("_log", _LOG))
    for name in names
}

__all__ = [
    "BLOCK", "END_MARGIN", "Evaluation", "FREE_FRACTIONS", "FREE_POINTS_PER_BEAM", "HOLDOUT", "LogScore",
    "TunedCounting", "TunedGrid", "as_polygon", "beam_test_points", "blind_radius", "blocking_obstacles",
    "configuration_obstacles", "evaluate_log", "evaluate_navigation", "grid_raster", "grouped_auc", "holdout_blocks",
    "holdout_points", "holdout_test_points", "in_front_of_first_obstacle", "nav2_agreement", "observable_footprints",
    "polygon_iou", "reachable_region", "returns_within_body", "robot_frame_points", "robot_frame_polygon", "roc_auc",
    "split_holdout", "textbook_scores", "true_reach", "tune_counting", "tune_grids", "tune_textbook",
    "violation_by_observability", "world_grid", "world_rays",
]

if TYPE_CHECKING:  # pragma: no cover - what the lazy names are, for type checkers and IDEs
    from occtool.scoring._heldout import (
        BLOCK,
        END_MARGIN,
        FREE_FRACTIONS,
        FREE_POINTS_PER_BEAM,
        HOLDOUT,
        beam_test_points,
        holdout_blocks,
        holdout_points,
        holdout_test_points,
        in_front_of_first_obstacle,
        split_holdout,
        world_rays,
    )
    from occtool.scoring._log import LogScore, evaluate_log, textbook_scores, world_grid
    from occtool.scoring._metrics import grouped_auc, polygon_iou, roc_auc
    from occtool.scoring._nav2 import grid_raster, nav2_agreement
    from occtool.scoring._polygon import (
        Evaluation,
        as_polygon,
        blind_radius,
        blocking_obstacles,
        configuration_obstacles,
        evaluate_navigation,
        observable_footprints,
        reachable_region,
        returns_within_body,
        robot_frame_points,
        robot_frame_polygon,
        true_reach,
        violation_by_observability,
    )
    from occtool.scoring._tune import TunedCounting, TunedGrid, tune_counting, tune_grids, tune_textbook


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
