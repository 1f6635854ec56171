"""The fit's centre programmes through occtool.linear_program and through scipy's HiGHS.

Issue 21, item 2: on each room of bench/unseen_rooms.py (10k features, seed 0) the
programmes one fit solves are captured and solved again by both, best of 5 in process
CPU time, with the largest relative gap between their optimal objectives.

    python bench/lp_vs_highs.py

Not part of ``make bench``: it imports scipy.optimize, which the fit does not.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from unseen_rooms import SCENES, make_scene  # noqa: E402

import occtool.fit._construction as construction  # noqa: E402
from occtool.fit import OccupancyRegressor  # noqa: E402
from occtool.linear_program import solve_lp  # noqa: E402


def _programmes(features: Any) -> list[tuple[Any, ...]]:
    captured: list[tuple[Any, ...]] = []

    def recording(cost: Any, A_ub: Any, b_ub: Any, lower: Any, upper: Any, **options: Any) -> Any:
        result = solve_lp(cost, A_ub, b_ub, lower, upper, **options)
        captured.append((np.array(cost, float), np.array(A_ub, float), np.array(b_ub, float), lower, upper, result))
        return result

    construction.solve_lp = recording  # type: ignore[assignment]
    try:
        OccupancyRegressor(seed=0).fit(features)
    finally:
        construction.solve_lp = solve_lp
    return captured


def _best(function: Any, repeat: int = 5) -> float:
    best = float("inf")
    for _ in range(repeat):
        started = time.process_time()
        function()
        best = min(best, time.process_time() - started)
    return best


def main() -> None:
    started = time.process_time()
    from scipy.optimize import linprog

    print(f"scipy.optimize import: {1000 * (time.process_time() - started):.0f} ms CPU")
    for name in SCENES:
        features, _ = make_scene(name, 0)
        programmes = _programmes(features)

        def ours() -> None:
            for cost, A, b, lower, upper, _ in programmes:
                solve_lp(cost, A, b, lower, upper)

        def highs() -> list[Any]:
            out = []
            for cost, A, b, lower, upper, _ in programmes:
                low = np.broadcast_to(np.asarray(lower, float), cost.shape)
                high = np.broadcast_to(np.asarray(upper, float), cost.shape)
                bounds = [(lo if np.isfinite(lo) else None, hi if np.isfinite(hi) else None) for lo, hi in zip(low, high)]
                out.append(linprog(cost, A_ub=A if A.size else None, b_ub=b if A.size else None, bounds=bounds,
                                   method="highs"))
            return out

        gap = max((abs(float(c @ theirs.x) - float(c @ mine.x)) / max(1.0, abs(float(c @ theirs.x)))
                   for (c, *_, mine), theirs in zip(programmes, highs())
                   if theirs.status == 0 and mine.x is not None), default=0.0)
        rows = [A.shape[0] for _, A, *_ in programmes]
        print(f"{name}: {len(programmes)} programmes, {min(rows)}-{max(rows)} rows, {programmes[0][0].size} unknowns; "
              f"occtool {1000 * _best(ours):.1f} ms, HiGHS {1000 * _best(highs):.1f} ms CPU; "
              f"largest relative objective gap {gap:.1e}")


if __name__ == "__main__":
    main()
