"""The sensor model: five samples per feature, floor handling, footprint, ray profile."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.features import Features
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, SensorModel


def test_five_samples_per_feature_on_its_ray():
    sensor = SensorModel(depth_error=0.05, near_positions=(0.5, 0.75), near_values=(0.1, 0.3), footprint_samples=0)
    features = Features.from_xyz([2.0], [0.0], [0.0], 0.8)
    s = sensor.samples(features, Robot())
    assert len(s) == 5
    order = np.argsort(s.r)
    assert np.allclose(s.r[order], [0.0, 1.0, 1.5, 1.9, 2.1])
    assert np.allclose(s.m[order], [0.0, 0.08, 0.24, 0.8, 0.8])
    assert np.allclose(s.alpha, 0.0) and np.allclose(s.h, 0.0)


def test_samples_keep_pan_angle_and_scale_height():
    features = Features.from_xyz([0.0], [1.0], [-0.5], 1.0)
    s = SensorModel(footprint_samples=0).samples(features, Robot())
    assert np.allclose(s.alpha, np.pi / 2)
    moving = s.r > 0
    assert np.allclose(s.h[moving] / s.r[moving], -0.5 / np.hypot(1.0, 0.5))


def test_floor_features_give_only_free_samples():
    robot = Robot(sensor_height=1.0, ground_clearance=0.05)
    floor = Features.from_xyz([2.0], [0.0], [-1.0], 0.9)
    s = SensorModel(floor="free", footprint_samples=0).samples(floor, robot)
    assert s.count("hit") == 0 and s.count("floor") == 2 and s.count("robot") == 1
    assert (s.m < 0.9).all()
    assert len(SensorModel(floor="drop", footprint_samples=0).samples(floor, robot)) == 0
    assert SensorModel(floor="obstacle", footprint_samples=0).samples(floor, robot).count("hit") == 2
    pallet = Features.from_xyz([2.0], [0.0], [-0.9], 0.9)  # 10 cm above the floor: an obstacle
    assert SensorModel(footprint_samples=0).samples(pallet, robot).count("hit") == 2


def test_footprint_fills_the_body_with_zeros():
    robot = Robot(radius=0.3)
    s = SensorModel(footprint_samples=64).samples(Features.from_xyz([1.0], [0.0], [0.0], 1.0), robot)
    foot = s.kind == SAMPLE_KINDS["footprint"]
    assert foot.sum() == 64
    horizontal = np.sqrt(s.r[foot] ** 2 - s.h[foot] ** 2)
    assert (horizontal <= robot.radius + 1e-12).all() and (s.m[foot] == 0).all()
    assert s.h[foot].min() == pytest.approx(robot.body_band[0])


def test_background_samples_are_deterministic_and_light():
    sensor = SensorModel(background_samples=100, background_weight=0.05)
    features = Features.from_xyz([1.0], [0.0], [0.0], 1.0)
    a = sensor.samples(features, Robot(), np.random.default_rng(3))
    b = sensor.samples(features, Robot(), np.random.default_rng(3))
    bg = a.kind == SAMPLE_KINDS["background"]
    assert bg.sum() == 100 and np.allclose(a.weight[bg], 0.05) and (a.m[bg] == 0).all()
    assert np.array_equal(a.alpha, b.alpha)


@given(r=st.floats(0.2, 10.0), m=st.floats(0.0, 1.0), t=st.floats(0.0, 1.0))
def test_ray_profile_is_monotone_and_matches_samples(r, m, t):
    sensor = SensorModel()
    s = np.array([0.0, t * r, 0.8 * r, 0.9 * r, 0.97 * r])
    v = sensor.ray_profile(r, m, s)
    assert np.all(np.diff(v[np.argsort(s)]) >= -1e-12)
    assert np.allclose(v[2:], [0.2 * m, 0.4 * m, m])
    assert np.isnan(sensor.ray_profile(r, m, 1.1 * r))


@pytest.mark.parametrize("kwargs", [dict(depth_error=-0.1), dict(near_positions=(0.9, 0.8)),
                                    dict(near_values=(0.2, 1.5)), dict(floor="carpet"), dict(footprint_samples=-1)])
def test_bad_parameters_rejected(kwargs):
    with pytest.raises(InputError):
        SensorModel(**kwargs)


def test_dict_round_trip():
    sensor = SensorModel(depth_error=0.05, near_positions=(0.6, 0.7))
    assert SensorModel.from_dict(sensor.to_dict()) == sensor
    with pytest.raises(InputError, match="unknown"):
        SensorModel.from_dict({"depht_error": 0.1})


def test_features_inside_the_robot_body_give_no_samples():
    robot = Robot(radius=0.25, sensor_height=1.0, body_height=1.0)
    inside = Features(np.array([[0.1, 0.05, -0.5], [0.0, -0.2, -0.9]]), np.array([0.9, 0.9]))
    outside = Features(np.array([[0.3, 0.0, -0.5]]), np.array([0.9]))
    model = SensorModel(footprint_samples=0)
    assert model.is_on_robot(inside, robot).all() and not model.is_on_robot(outside, robot).any()
    assert len(model.samples(inside, robot)) == 0
    assert len(model.samples(outside, robot)) == 5


def test_evidence_zero_features_are_free_rays_in_every_floor_mode():
    from occtool.sensor import SAMPLE_KINDS

    robot = Robot()
    # A wall feature 2 m ahead with evidence 0.9 and a no-return beam written at 3 m.
    features = Features(np.array([[2.0, 0.0, -0.5], [0.0, 3.0, -0.5]]), np.array([0.9, 0.0]))
    for floor in ("free", "drop", "obstacle"):
        model = SensorModel(floor=floor, footprint_samples=0)
        samples = model.samples(features, robot)
        hits = samples.kind == SAMPLE_KINDS["hit"]
        # Only the wall gives hits; the free ray gives free-ray samples, all of value 0.
        assert np.allclose(samples.alpha[hits], 0.0)
        free = samples.kind == SAMPLE_KINDS["floor"]
        assert free.sum() == 2 and np.allclose(samples.alpha[free], np.pi / 2)
        assert np.all(samples.m[samples.alpha == np.pi / 2] == 0.0)
        assert model.is_obstacle(features, robot).tolist() == [True, False]
        assert model.is_free_ray(features, robot).tolist() == [False, True]
