"""Model and inverse files: round trips, determinism outside `run`, rejection of bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from occtool.errors import ModelFormatError
from occtool.features import Features
from occtool.fit import OccupancyRegressor
from occtool.formats.model import (
    FORMAT_VERSION,
    MODEL_FORMAT,
    load_inverse,
    load_model,
    model_to_dict,
    read_any,
    save_inverse,
    save_model,
)


def room(seed: int = 0, n: int = 1500) -> Features:
    rng = np.random.default_rng(seed)
    a = rng.uniform(-np.pi, np.pi, n)
    d = np.where(np.cos(a) > 0.8, 1.0, 1.8)
    z = rng.uniform(-0.9, 0.5, n)
    return Features.from_xyz(d * np.cos(a), d * np.sin(a), z, rng.uniform(0.6, 1.0, n))


@pytest.fixture(scope="module")
def model() -> OccupancyRegressor:
    return OccupancyRegressor(pieces=12, seed=1).fit(room())


def test_round_trip_is_exact(model, tmp_path):
    path = tmp_path / "model.json"
    save_model(model, path, run={"seconds": 0.1, "host": "test"})
    loaded = load_model(path)
    assert loaded.tree_ == model.tree_
    assert loaded.sensor_ == model.sensor_ and loaded.robot_ == model.robot_
    assert loaded.slope_bounds_ == model.slope_bounds_
    assert loaded.run_ == {"seconds": 0.1, "host": "test"}
    alpha = np.linspace(-np.pi, np.pi, 50)
    assert np.array_equal(loaded.inverse_range(alpha, -0.5, 0.6), model.inverse_range(alpha, -0.5, 0.6))
    # the constraints still hold exactly after the trip through JSON
    assert (loaded.tree_.c >= loaded.c_min).all() and (loaded.tree_.angle_weight <= loaded.a_max).all()
    assert (np.abs(loaded.tree_.b) <= loaded.b_max).all()


def test_file_content(model):
    data = model_to_dict(model)
    assert data["format"] == MODEL_FORMAT and data["format_version"] == FORMAT_VERSION
    assert data["frame"]["id"] == "base_link" and data["units"]["r"] == "m"
    assert len(data["pieces"]) == 12 and data["tree"]["op"] == "max"
    assert data["training"]["n_features"] == 1500 and len(data["training"]["features_sha256"]) == 64
    assert "run" not in data


def test_same_input_and_seed_identical_outside_run(tmp_path):
    paths = []
    for i in range(2):
        fitted = OccupancyRegressor(pieces=8, seed=7).fit(room(3))
        paths.append(tmp_path / f"m{i}.json")
        save_model(fitted, paths[-1], run={"attempt": i})
    a, b = (json.loads(p.read_text()) for p in paths)
    assert a.pop("run") != b.pop("run")
    assert json.dumps(a) == json.dumps(b)


def test_digest_changes_with_input():
    a = OccupancyRegressor(pieces=4).fit(room(1)).features_digest_
    b = OccupancyRegressor(pieces=4).fit(room(2)).features_digest_
    assert a != b


def test_inverse_file_round_trip(model, tmp_path):
    path = tmp_path / "inverse.json"
    save_inverse(model.invert(), path, model=model)
    inverse = load_inverse(path)
    assert inverse == model.invert()
    kind, obj = read_any(path)
    assert kind == "inverse"


def _write(tmp_path, data) -> str:
    path = tmp_path / "bad.json"
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return str(path)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.update(format_version=FORMAT_VERSION + 1), "newer"),
        (lambda d: d.update(format="something-else"), "not an occtool-model"),
        (lambda d: d.pop("pieces"), "no 'pieces'"),
        (lambda d: d["pieces"][0].update(c=-1.0), "c ="),
        (lambda d: d["pieces"][0].update(b=1e6), "height weight"),
        (lambda d: d.update(tree={"op": "max", "children": [0]}), "every piece"),
        (lambda d: d.pop("training"), "training"),
        (lambda d: d["sensor_model"].update(depth_error=5.0), "depth error"),
        (lambda d: d.update(units={"r": "dm"}), "units"),
    ],
)
def test_malformed_model_rejected(model, tmp_path, mutate, message):
    data = json.loads(json.dumps(model_to_dict(model)))
    mutate(data)
    with pytest.raises(ModelFormatError, match=message):
        load_model(_write(tmp_path, data))


def test_a_file_from_before_the_construction_option_was_removed_still_loads(model, tmp_path):
    data = json.loads(json.dumps(model_to_dict(model)))
    assert "construction" not in data["fit"]
    data["fit"]["construction"] = "profile"
    loaded = load_model(_write(tmp_path, data))
    assert loaded.tree_ == model.tree_ and loaded.get_params(deep=False)["pieces"] == 12
    assert not hasattr(loaded, "construction")


def test_a_model_of_the_removed_regression_construction_is_refused_in_one_line(model, tmp_path):
    data = json.loads(json.dumps(model_to_dict(model)))
    data["fit"]["construction"] = "regression"
    with pytest.raises(ModelFormatError, match="construction 'regression' is no longer supported") as error:
        load_model(_write(tmp_path, data))
    assert "\n" not in str(error.value)


def test_not_json_rejected(tmp_path):
    with pytest.raises(ModelFormatError, match="not valid JSON"):
        load_model(_write(tmp_path, "{ nope"))
    with pytest.raises(ModelFormatError, match="JSON object"):
        load_model(_write(tmp_path, "[1, 2]"))


def test_read_any_ignores_other_files(tmp_path):
    path = tmp_path / "features.csv"
    path.write_text("x,y,z,m\n1,0,0,1\n")
    assert read_any(path) is None
