"""What a fresh process pays on its first fit and comparison: no module is imported
inside a timed or fitted call that the process could have had already."""

from __future__ import annotations

import subprocess
import sys

ROOM = """
import numpy as np
from occtool.features import Features
rng = np.random.default_rng(0)
a, z = rng.uniform(-1.5, 1.5, 3000), rng.uniform(-0.9, 0.5, 3000)
r = np.where(np.abs(a) < 0.4, 1.2, 2.5)  # a box ahead of a wall
features = Features(np.column_stack([r * np.cos(a), r * np.sin(a), z]), np.ones(3000))
"""


def _run(code: str) -> str:
    return subprocess.run([sys.executable, "-c", ROOM + code], check=True, capture_output=True, text=True).stdout


def test_a_fit_imports_no_scipy():
    # scipy.spatial's import cost a fresh process more CPU than a fit of 10k features.
    out = _run("""
import sys
from occtool.fit import OccupancyRegressor
model = OccupancyRegressor(seed=0).fit(features)
assert model.guard_ is not None
print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))
""")
    assert out.strip() == "[]"


def test_a_fit_imports_nothing_a_second_fit_would_not():
    # The first fit's one-off costs were imports (scipy.spatial, numpy.ma, numpy.random).
    out = _run("""
import sys
from occtool.fit import OccupancyRegressor
before = set(sys.modules)
OccupancyRegressor(seed=0).fit(features)
print(sorted(set(sys.modules) - before))
""")
    assert out.strip() == "[]"


def test_no_compared_model_is_timed_importing_a_module():
    # The parametric model ran first and paid occtool.navigation's and numpy.ma's import
    # in its timed extraction; the grid found them loaded.
    out = _run("""
import sys
import occtool.compare._compare as compare
from occtool.fit import OccupancyRegressor
timed = compare._timed
imported = []
def watched(function, repeat):
    before = set(sys.modules)
    result = timed(function, repeat)
    imported.append(sorted(set(sys.modules) - before))
    return result
compare._timed = watched
compare.compare_grid(features, regressor=OccupancyRegressor(seed=0), navigation={}, file_sizes=False,
                     resolution=0.1)
print(len(imported), imported)
""")
    assert out.strip() == "4 [[], [], [], []]"  # fit, extract, grid build, grid extract

