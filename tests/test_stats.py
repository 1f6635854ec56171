"""occtool._stats.median: np.median's answer without importing numpy.ma."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool._stats import median


@pytest.mark.parametrize(("values", "expected"), [
    ([3.0, 1.0, 2.0], 2.0),  # odd: the middle value
    ([4.0, 1.0, 3.0, 2.0], 2.5),  # even: the mean of the middle two
    ([5.0], 5.0),
    ([-1.0, 7.0], 3.0),
    ([2, 2, 2, 9], 2.0),  # ties; integers are read as floats
    ([[1.0, 9.0], [3.0, 4.0]], 3.5),  # any shape is flattened
])
def test_known_answers(values, expected):
    result = median(values)
    assert type(result) is float and result == expected


def test_nothing_or_a_nan_is_nan():
    assert math.isnan(median([]))
    assert math.isnan(median([1.0, float("nan"), 3.0]))


@given(st.lists(st.floats(-1e300, 1e300), min_size=1, max_size=40))
def test_it_is_np_median_to_the_bit(values):
    assert median(values) == float(np.median(np.array(values)))


def test_it_leaves_its_argument_unsorted():
    values = np.array([3.0, 1.0, 2.0, 0.0])
    median(values)
    np.testing.assert_array_equal(values, [3.0, 1.0, 2.0, 0.0])
