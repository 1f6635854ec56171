"""Map coordinates to WGS84 through pyproj: known answers, round trips, bad origins."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.formats.wgs84 import Georeference, parse_origin

pytest.importorskip("pyproj")


def test_east_at_the_equator_is_a_known_longitude():
    lonlat = Georeference(0.0, 0.0).to_lonlat([[1000.0, 0.0]])
    # WGS84: one degree of longitude at the equator is 111,319.49 m.
    assert lonlat[0, 0] == pytest.approx(1000.0 / 111_319.4908, rel=1e-6)
    assert lonlat[0, 1] == pytest.approx(0.0, abs=1e-9)


def test_heading_turns_the_map():
    north = Georeference(47.0, 8.0, heading=0.0).to_lonlat([[100.0, 0.0]])[0]
    assert north[0] == pytest.approx(8.0, abs=1e-9) and north[1] > 47.0
    # y is 90 degrees counter-clockwise of x: with x north, y points west.
    west = Georeference(47.0, 8.0, heading=0.0).to_lonlat([[0.0, 100.0]])[0]
    assert west[0] < 8.0 and west[1] == pytest.approx(47.0, abs=1e-6)


@given(st.floats(-80, 80), st.floats(-179, 179), st.floats(0, 360),
       st.lists(st.tuples(st.floats(-2000, 2000), st.floats(-2000, 2000)), min_size=1, max_size=5))
def test_round_trip_within_a_centimetre(lat, lon, heading, points):
    reference = Georeference(lat, lon, heading)
    xy = np.array(points)
    back = reference.from_lonlat(reference.to_lonlat(xy))
    assert np.abs(back - xy).max() < 0.01


@pytest.mark.parametrize("text", ["", "1", "1,2,3,4", "a,b", "95,0", "0,200", "nan,0"])
def test_bad_origins_are_input_errors(text):
    with pytest.raises(InputError):
        parse_origin(text)


def test_heading_defaults_to_east():
    assert parse_origin("47.5, 8.25") == (47.5, 8.25, 90.0)
