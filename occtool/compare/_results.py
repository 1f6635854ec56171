"""What a model cost and produced: :class:`ModelResult`, timings, memory and file sizes."""

from __future__ import annotations

import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely


@dataclass
class ModelResult:
    """What one model cost and produced."""

    name: str
    samples: int
    build_s: float
    extract_s: float
    memory_bytes: int
    file_bytes: int
    polygon: shapely.Geometry
    extra: dict[str, Any] = field(default_factory=dict)
    #: Why the navigation map is degenerate (an empty polygon: the robot in collision), if it is.
    warnings: list[str] = field(default_factory=list)
    #: A grid's polygon under each further reading of unobserved space (``also_unknown``).
    readings: dict[str, shapely.Geometry] = field(default_factory=dict)

    def figures(self) -> dict[str, Any]:
        return {
            "samples": int(self.samples),
            "build_s": float(self.build_s),
            "extract_s": float(self.extract_s),
            "memory_bytes": int(self.memory_bytes),
            "file_bytes": int(self.file_bytes),
            "polygon_area": float(self.polygon.area),
            **self.extra,
            "warnings": list(self.warnings),
        }


def _timed(function: Callable[[], Any], repeat: int) -> tuple[Any, float]:
    """Run ``function`` ``repeat`` times; its last result and the shortest time, seconds."""
    best = float("inf")
    result = None
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        result = function()
        best = min(best, time.perf_counter() - start)
    return result, best


def _file_size(write: Callable[[str], Any], suffix: str) -> int:
    fd, name = tempfile.mkstemp(suffix=suffix)
    os.close(fd)
    try:
        write(name)
        return os.path.getsize(name)
    finally:
        os.unlink(name)


def tree_bytes(tree: Any) -> int:
    """Memory of a min/max tree's parameters: the piece coefficients plus one 8-byte
    reference per node of the tree structure."""

    def nodes(node: Any) -> int:
        return 1 if isinstance(node, (int, np.integer)) else 1 + sum(nodes(c) for c in node.children)

    return int(tree.coefficients.nbytes + 8 * nodes(tree.root))


def _save_model_size(model: Any) -> int:
    from occtool.formats.model import save_model

    return _file_size(lambda name: save_model(model, name), ".json")
