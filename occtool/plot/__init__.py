"""Pictures of range data, occupancy models, navigation maps and comparison reports.

Every ``draw_*`` function draws onto a matplotlib :class:`~matplotlib.axes.Axes` the
caller owns; every ``*_figure`` function builds a complete
:class:`~matplotlib.figure.Figure` (the paper's Figure 5 a, b and c, and the grid
comparison); :func:`save_figure` writes one to PNG, SVG or PDF, chosen by the file's
extension, completely or not at all.

matplotlib is an optional extra (``pip install 'occtool[plot]'``). It is imported only
when a function here runs, and figures are built with :class:`matplotlib.figure.Figure`
and the Agg canvas directly, never through ``pyplot``, so rendering works headless and
a user's interactive backend is left alone.

The package keeps one concept per private module, behind this public one:
``_canvas`` (matplotlib, figure files, style), ``_reading`` (the files pictures are
drawn from, parsed by :mod:`occtool.io`), ``_probing`` (asking a model what to draw),
``_drawing`` (artists on an Axes), ``_figures`` (whole figures) and ``_map`` (a run's fused map).

Coordinates are metres in REP-103 frames (x forward, y left). Navigation maps and
features are drawn in the robot frame unless a pose places them in the world frame.
"""

from __future__ import annotations

from occtool._json import read_json
from occtool.plot._canvas import (
    DEFAULT_DPI,
    DEFAULT_SIZE,
    EXPLORATION_COLOUR,
    MODEL_COLOURS,
    NAVIGATION_COLOUR,
    OBSTACLE_COLOUR,
    ROBOT_COLOUR,
    SUPPORTED_FORMATS,
    TRUTH_COLOUR,
    new_figure,
    output_format,
    parse_size,
    require_matplotlib,
    save_figure,
)
from occtool.plot._drawing import (
    draw_active_pieces,
    draw_features,
    draw_heatmap,
    draw_navigation,
    draw_occupied_projection,
    draw_robot,
    draw_scaling,
    draw_truth,
    geometry_path,
    map_in_frame,
)
from occtool.plot._figures import compare_figure, features_figure, model_figure, navigation_figure
from occtool.plot._map import DEFAULT_MAP_SIZE, map_figure, read_map_folder
from occtool.plot._probing import (
    active_piece_function,
    evaluate_on_floor_grid,
    model_extent,
    model_piece_count,
    model_robot,
    occupied_projection,
)
from occtool.plot._reading import (
    ScalingSeries,
    expand_navigation_paths,
    read_navigation,
    read_navigation_maps,
    report_polygons,
    scaling_series,
)

__all__ = [
    "DEFAULT_DPI",
    "DEFAULT_MAP_SIZE",
    "DEFAULT_SIZE",
    "EXPLORATION_COLOUR",
    "MODEL_COLOURS",
    "NAVIGATION_COLOUR",
    "OBSTACLE_COLOUR",
    "ROBOT_COLOUR",
    "SUPPORTED_FORMATS",
    "TRUTH_COLOUR",
    "ScalingSeries",
    "active_piece_function",
    "compare_figure",
    "draw_active_pieces",
    "draw_features",
    "draw_heatmap",
    "draw_navigation",
    "draw_occupied_projection",
    "draw_robot",
    "draw_scaling",
    "draw_truth",
    "evaluate_on_floor_grid",
    "expand_navigation_paths",
    "features_figure",
    "geometry_path",
    "map_in_frame",
    "model_extent",
    "model_figure",
    "model_piece_count",
    "model_robot",
    "navigation_figure",
    "new_figure",
    "occupied_projection",
    "output_format",
    "parse_size",
    "read_json",
    "read_navigation",
    "read_navigation_maps",
    "map_figure",
    "read_map_folder",
    "report_polygons",
    "require_matplotlib",
    "save_figure",
    "scaling_series",
]
