"""Issue 12, class 7 (model files): a broken model or inverse file is a one-line error.

A tree nested 500 deep (RecursionError), a coefficient of 400 digits (OverflowError) and
strings, lists or huge integers wherever a number belongs are ModelFormatErrors, for every
command that reads a model; the bytes occtool writes do not change.
"""

from __future__ import annotations

import copy
import json
import math
import traceback
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import ModelFormatError
from occtool.formats.model import load_inverse, load_model

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"


def run(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def assert_one_line_error(result) -> None:
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    assert sum(line.startswith("Error:") for line in result.output.splitlines()) == 1, result.output


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("model")
    lines = (FIXTURES / "office" / "features.csv").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("x,"))
    csv = folder / "features.csv"
    csv.write_text("\n".join(lines[start: start + 301]) + "\n")
    assert run("fit", csv, "-o", folder / "model.json", "--pieces", "8").exit_code == 0
    assert run("invert", folder / "model.json", "-o", folder / "inverse.json").exit_code == 0
    # A model set's file also keeps what its position observed (occtool.fuse.Observation).
    from occtool.formats.model import model_text, save_model_text
    from occtool.fuse import observe
    from occtool.io import read_log

    features = read_log(csv).single().features
    model = load_model(folder / "model.json")
    save_model_text(model_text(model, run=model.run_, observed=observe(model, features)), folder / "observed.json")
    return {"model": folder / "model.json", "inverse": folder / "inverse.json", "observed": folder / "observed.json"}


def _nested(data: dict, depth: int) -> str:
    """The file's text with its tree wrapped in ``depth`` MIN nodes (json.dumps would recurse)."""
    inner = json.dumps(data["tree"])
    text = json.dumps({**data, "tree": "@TREE@"})
    return text.replace('"@TREE@"', '{"op": "min", "children": [' * depth + inner + "]}" * depth)


@pytest.mark.parametrize("kind", ["model", "inverse"])
@pytest.mark.parametrize("depth", [70, 500, 5000])
def test_a_deeply_nested_tree_is_a_format_error(files, tmp_path, kind, depth):
    path = tmp_path / f"{kind}.json"
    path.write_text(_nested(json.loads(files[kind].read_text()), depth))
    with pytest.raises(ModelFormatError, match="nested"):
        (load_model if kind == "model" else load_inverse)(path)
    for command in (["info", path], ["extract", path, "-o", tmp_path / "n.geojson"]):
        assert_one_line_error(run(*command))
    assert not (tmp_path / "n.geojson").exists()


def _paths(data: object, prefix: tuple = ()) -> list[tuple]:
    """Every path to a number in a JSON document."""
    if isinstance(data, dict):
        return [p for key, value in data.items() for p in _paths(value, (*prefix, key))]
    if isinstance(data, list):
        return [p for index, value in enumerate(data) for p in _paths(value, (*prefix, index))]
    return [prefix] if isinstance(data, (int, float)) and not isinstance(data, bool) else []


def _set(data: dict, path: tuple, value: object) -> dict:
    copied = copy.deepcopy(data)
    target = copied
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return copied


def _dump(data: dict, big: int | None = None) -> str:
    text = json.dumps(data)
    return text if big is None else text.replace('"@BIG@"', str(big))


def test_a_400_digit_coefficient_is_a_format_error(files, tmp_path):
    data = json.loads(files["model"].read_text())
    path = tmp_path / "model.json"
    path.write_text(_dump(_set(data, ("pieces", 0, "a1"), "@BIG@"), 10**399))
    with pytest.raises(ModelFormatError, match="400 digits.*too long"):
        load_model(path)
    assert_one_line_error(run("extract", path, "-o", tmp_path / "n.geojson"))


REPLACEMENTS = st.one_of(
    st.text(max_size=5), st.just("@BIG@"), st.lists(st.integers(), max_size=2), st.none(), st.booleans(),
    st.dictionaries(st.text(max_size=2), st.integers(), max_size=1),
    st.sampled_from([float("nan"), float("inf"), -1.0, 0.0, 1e308, -(2**70)]),
)


@settings(max_examples=120)
@given(data=st.data(), replacement=REPLACEMENTS, kind=st.sampled_from(["model", "inverse", "observed"]))
def test_any_number_replaced_by_a_wrong_value_loads_or_fails_cleanly(files, tmp_path_factory, data, replacement, kind):
    original = json.loads(files[kind].read_text())
    path_in_file = data.draw(st.sampled_from(_paths(original)))
    path = tmp_path_factory.mktemp("fuzz") / f"{kind}.json"
    path.write_text(_dump(_set(original, path_in_file, replacement), 10**400), encoding="utf-8")
    before = _get(original, path_in_file)
    unchanged = type(before) is type(replacement) and before == replacement
    try:
        (load_inverse if kind == "inverse" else load_model)(path)
    except ModelFormatError as exc:
        assert str(exc).startswith(f"{path}: "), str(exc)  # one line naming the file
        assert not unchanged, f"the file as written fails to load: {exc}"
        return
    # occtool never writes NaN or infinity (nor a 400-digit number): one there is damage.
    assert not (isinstance(replacement, float) and not math.isfinite(replacement)), \
        f"{kind} with {'/'.join(map(str, path_in_file))} = {replacement} loaded"
    assert replacement != "@BIG@", f"{kind} with a 400-digit {'/'.join(map(str, path_in_file))} loaded"


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["model", "inverse", "observed"])
@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_nan_or_infinity_anywhere_is_a_format_error(files, tmp_path, kind, value):
    # A bound, setting or summary left NaN loaded before, and every map made from it was wrong.
    original = json.loads(files[kind].read_text())
    path = tmp_path / f"{kind}.json"
    numbers = [p for p in _paths(original) if isinstance(_get(original, p), (int, float))
               and not isinstance(_get(original, p), bool)]
    assert len(numbers) > 20
    for where in numbers:
        path.write_text(_dump(_set(original, where, value)), encoding="utf-8")
        with pytest.raises(ModelFormatError, match="is not a finite number") as caught:
            (load_inverse if kind == "inverse" else load_model)(path)
        assert str(caught.value).startswith(f"{path}: "), str(caught.value)


def _get(data: object, path: tuple) -> object:
    for key in path:
        data = data[key]  # type: ignore[index]
    return data


@pytest.mark.parametrize(("damage", "message"), [
    (lambda o: o.update(reach_bins=119), "120 reach bins"),
    (lambda o: o["returns_mm"].pop(), "list of 360 values"),
    (lambda o: o["reach_cm"].__setitem__(3, None), "reach_cm' 3 is not a whole number"),
    (lambda o: o["return_offsets"].__setitem__(0, 256), "return_offsets' 0 is not a whole number 0-255"),
    (lambda o: o["first_obstacle_cm"].__setitem__(5, -2), "first_obstacle_cm' 5"),
    (lambda o: o.clear() or o.update(x=[1]), "120 reach bins"),
])
def test_a_damaged_observation_is_a_one_line_format_error(files, tmp_path, damage, message):
    data = json.loads(files["observed"].read_text())
    damage(data["observed"])
    path = tmp_path / "model.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ModelFormatError, match=message):
        load_model(path)
    assert_one_line_error(run("info", path))


@settings(max_examples=15, deadline=None)
@given(data=st.data(), replacement=REPLACEMENTS)
def test_commands_reading_a_mutated_model_never_trace_back(files, tmp_path_factory, data, replacement):
    original = json.loads(files["model"].read_text())
    path_in_file = data.draw(st.sampled_from(_paths(original)))
    folder = tmp_path_factory.mktemp("cli")
    path = folder / "model.json"
    path.write_text(_dump(_set(original, path_in_file, replacement), 10**400), encoding="utf-8")
    for command in (["info", path], ["invert", path, "-o", folder / "i.json"],
                    ["extract", path, "-o", folder / "n.geojson", "--angles", "36"]):
        result = run(*command)
        if result.exception is not None and not isinstance(result.exception, SystemExit):
            raise AssertionError(f"{path_in_file} = {replacement!r}:\n"
                                 + "".join(traceback.format_exception(*result.exc_info)))
        assert "Traceback" not in result.output


def test_the_bytes_written_do_not_change(files, tmp_path):
    """Reading is stricter; writing is as before: a model read back and saved is byte-identical."""
    from occtool.formats.model import save_model

    for kind in ("model", "observed"):
        model = load_model(files[kind])
        out = tmp_path / f"{kind}-again.json"
        save_model(model, out, run=model.run_)
        assert out.read_bytes() == files[kind].read_bytes()


# --- every JSON a user hands in: navigation maps, scene truths --------------------------------------


@settings(max_examples=40)
@given(depth=st.integers(1, 20_000), digits=st.integers(1, 1000))
def test_user_json_is_bounded_in_nesting_and_integer_length(depth, digits):
    from occtool import _json

    for text in ("[" * depth + "]" * depth, "[" + "7" * digits + "]"):
        try:
            value = _json.loads(text)
        except json.JSONDecodeError as exc:
            assert "nested too deeply" in exc.msg or "too long" in exc.msg
        else:
            assert value is not None


@pytest.mark.parametrize("damage", ["deep", "big"])
def test_a_damaged_navigation_map_or_truth_is_one_line_for_evaluate(files, tmp_path, damage):
    truth = FIXTURES / "office" / "truth.json"
    nav = tmp_path / "nav.geojson"
    assert run("extract", files["model"], "-o", nav, "--angles", "36").exit_code == 0
    for target, source in (("nav", nav), ("truth", truth)):
        text = source.read_text()
        broken = tmp_path / f"broken-{target}.json"
        huge = text.replace("{", '{"n": ' + "9" * 400 + ", ", 1)
        broken.write_text("[" * 5000 + "]" * 5000 if damage == "deep" else huge)
        args = ["evaluate", broken, truth] if target == "nav" else ["evaluate", nav, broken]
        assert_one_line_error(run(*args))
