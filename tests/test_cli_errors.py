"""Bad input on the command line: a one-line ``Error: ...``, a non-zero exit, no traceback,
and no output file (complete or absent, no stray temporary file).

Every command but ``compare-grid`` (tests/test_cli_compare.py) is fed a missing file,
broken CSV rows, damaged MCAP files, malformed model and GeoJSON files and an output
path it cannot write; the overwrite behaviour (replace by default, ``--no-overwrite``
refuses) is checked for every command that writes files.
"""

from __future__ import annotations

import json
import os
import stat
import threading
import traceback
from pathlib import Path

import pytest
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.io import read_log, write_mcap

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"
TRUTH = FIXTURES / "office" / "truth.json"


def run(*args: object):
    if args and args[0] == "plot":
        pytest.importorskip("matplotlib")  # the plot extra
    # Wide enough that rich folds no line: outputs compare by content, whatever the tmp paths' lengths.
    return CliRunner().invoke(cli, [str(a) for a in args], env={"COLUMNS": "240"})


def assert_fails(result, *fragments: str, exit_code: int | None = None) -> str:
    """Non-zero exit, no traceback, an ``Error:`` line naming each fragment (case-insensitive)."""
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    output = " ".join(result.output.split())
    assert result.exit_code != 0, output
    if exit_code is not None:
        assert result.exit_code == exit_code, output
    assert "Traceback" not in output
    assert "Error:" in output, output
    for fragment in fragments:
        assert fragment.lower() in output.lower(), f"{fragment!r} not in {output!r}"
    return output


def assert_nothing_written(folder: Path) -> None:
    """The output folder holds nothing: no result, no ``.name.*.tmp``."""
    assert sorted(p.name for p in folder.iterdir()) == []


# --- inputs ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A small valid log (CSV and MCAP), a model fitted to it, its inverse and navigation map."""
    folder = tmp_path_factory.mktemp("inputs")
    lines = (FIXTURES / "office" / "features.csv").read_text().splitlines()
    header_end = next(i for i, line in enumerate(lines) if line.startswith("x,"))
    csv = folder / "features.csv"
    csv.write_text("\n".join(lines[: header_end + 1 + 400]) + "\n")
    mcap = folder / "features.mcap"
    write_mcap(read_log(csv), mcap)
    model = folder / "model.json"
    for args in (("fit", csv, "-o", model, "--pieces", "8"), ("invert", model, "-o", folder / "inverse.json"),
                 ("extract", model, "-o", folder / "nav.geojson", "--angles", "72")):
        result = run(*args)
        assert result.exit_code == 0, result.output
    return {"csv": csv, "mcap": mcap, "model": model, "inverse": folder / "inverse.json",
            "nav": folder / "nav.geojson"}


@pytest.fixture
def out(tmp_path) -> Path:
    folder = tmp_path / "out"
    folder.mkdir()
    return folder


# Commands reading a range log: (arguments for LOG and an output folder, output suffix).
LOG_COMMANDS = {
    "fit": lambda log, out, inputs: ["fit", log, "-o", out / "model.json", "--pieces", "8"],
    "info": lambda log, out, inputs: ["info", log],
    "convert": lambda log, out, inputs: ["convert", log, "-o", out / "log.csv"],
    "convert-mcap": lambda log, out, inputs: ["convert", log, "-o", out / "log.mcap"],
    "plot-features": lambda log, out, inputs: ["plot", "features", log, "-o", out / "features.png"],
    "plot-nav": lambda log, out, inputs: ["plot", "nav", inputs["nav"], "--features", log, "-o", out / "nav.png"],
}
# Commands reading a model (or inverse) file.
MODEL_COMMANDS = {
    "info": lambda model, out, inputs: ["info", model],
    "invert": lambda model, out, inputs: ["invert", model, "-o", out / "inverse.json"],
    "extract": lambda model, out, inputs: ["extract", model, "-o", out / "nav.geojson", "--angles", "72"],
    "plot-model": lambda model, out, inputs: ["plot", "model", model, "-o", out / "model.png", "--resolution", "16"],
}
# Commands reading a navigation GeoJSON.
NAV_COMMANDS = {
    "evaluate": lambda nav, out, inputs: ["evaluate", nav, TRUTH, "--rays", "64"],
    "plot-nav": lambda nav, out, inputs: ["plot", "nav", nav, "-o", out / "nav.png"],
}


# --- missing input ---------------------------------------------------------------------------

MISSING = {
    "fit": lambda m, out, inputs: ["fit", m, "-o", out / "model.json"],
    "info": lambda m, out, inputs: ["info", m],
    "invert": lambda m, out, inputs: ["invert", m, "-o", out / "inverse.json"],
    "extract": lambda m, out, inputs: ["extract", m, "-o", out / "nav.geojson"],
    "evaluate-nav": lambda m, out, inputs: ["evaluate", m, TRUTH],
    "evaluate-truth": lambda m, out, inputs: ["evaluate", inputs["nav"], m],
    "convert": lambda m, out, inputs: ["convert", m, "-o", out / "log.csv"],
    "plot-features": lambda m, out, inputs: ["plot", "features", m, "-o", out / "features.png"],
    "plot-nav": lambda m, out, inputs: ["plot", "nav", m, "-o", out / "nav.png"],
    "plot-nav-features": lambda m, out, inputs: ["plot", "nav", inputs["nav"], "--features", m, "-o", out / "n.png"],
    "plot-nav-truth": lambda m, out, inputs: ["plot", "nav", inputs["nav"], "--truth", m, "-o", out / "n.png"],
    "plot-model": lambda m, out, inputs: ["plot", "model", m, "-o", out / "model.png"],
}


@pytest.mark.parametrize("command", sorted(MISSING))
def test_missing_input_file(command, inputs, out, tmp_path):
    missing = tmp_path / "no_such_file.csv"
    result = run(*MISSING[command](missing, out, inputs))
    assert_fails(result, "no_such_file.csv", "does not exist", exit_code=2)
    assert_nothing_written(out)


# --- broken CSV ------------------------------------------------------------------------------

BAD_CSV = {
    # name: (content, what the message must say)
    "not a number": ("# a comment\nx,y,z,m\n1,0,0,0.5\n1,abc,0,0.5\n", ["line 4", "not a number", "abc"]),
    "nan": ("x,y,z,m\n1,0,0,0.5\n1,nan,0,0.5\n", ["line 3", "NaN"]),
    "evidence 1.5": ("x,y,z,m\n1,0,0,0.5\n1,0,0,1.5\n", ["line 3", "evidence 1.5", "[0, 1]"]),
    "origin": ("x,y,z,m\n1,0,0,0.5\n0,0,0,0.5\n", ["line 3", "origin"]),
    "short row": ("x,y,z,m\n1,0,0,0.5\n1,0,0\n", ["line 3", "3 columns"]),
    "header only": ("x,y,z,m\n", ["no data rows"]),
    "empty": ("", ["is empty"]),
}


@pytest.mark.parametrize("command", sorted(LOG_COMMANDS))
@pytest.mark.parametrize("case", sorted(BAD_CSV))
def test_bad_csv(case, command, inputs, out, tmp_path):
    content, fragments = BAD_CSV[case]
    log = tmp_path / "bad.csv"
    log.write_text(content)
    result = run(*LOG_COMMANDS[command](log, out, inputs))
    assert_fails(result, "bad.csv", *fragments, exit_code=1)
    assert_nothing_written(out)


def test_skip_invalid_drops_the_bad_rows(inputs, out, tmp_path):
    log = tmp_path / "bad.csv"
    log.write_text(inputs["csv"].read_text() + "1,nan,0,0.5\n")
    result = run("info", log, "--skip-invalid")
    assert result.exit_code == 0 and "skipped 1 invalid row" in result.output
    result = run("convert", log, "-o", out / "log.csv", "--skip-invalid")
    assert result.exit_code == 0, result.output
    assert len(read_log(out / "log.csv").single().features) == 400


# --- broken MCAP -----------------------------------------------------------------------------


def _truncated(inputs, tmp_path, fraction):
    data = inputs["mcap"].read_bytes()
    path = tmp_path / "broken.mcap"
    path.write_bytes(data[: int(len(data) * fraction)])
    return path


def _random_bytes(inputs, tmp_path, fraction):
    path = tmp_path / "broken.mcap"
    path.write_bytes(os.urandom(3000))
    return path


def _flipped(inputs, tmp_path, fraction):
    data = bytearray(inputs["mcap"].read_bytes())
    position = int(len(data) * fraction)
    data[position: position + 16] = bytes(16)
    path = tmp_path / "broken.mcap"
    path.write_bytes(bytes(data))
    return path


BROKEN_MCAP = {
    "truncated to 9 bytes": (_truncated, 9 / 10**9),
    "truncated at 30%": (_truncated, 0.3),
    "truncated at 99%": (_truncated, 0.99),
    "random bytes": (_random_bytes, 0.0),
    "zeroed at 20%": (_flipped, 0.2),
    "zeroed at 50%": (_flipped, 0.5),
}


@pytest.mark.parametrize("command", sorted(LOG_COMMANDS))
@pytest.mark.parametrize("case", sorted(BROKEN_MCAP))
def test_broken_mcap(case, command, inputs, out, tmp_path):
    make, fraction = BROKEN_MCAP[case]
    log = make(inputs, tmp_path, fraction)
    result = run(*LOG_COMMANDS[command](log, out, inputs))
    if case.startswith("zeroed") and result.exit_code == 0:
        return  # the damage missed everything that is read (info reads only the summary)
    assert_fails(result, "broken.mcap", exit_code=1)
    assert_nothing_written(out)


def test_damaged_mcap_anywhere_is_a_clear_error(inputs, tmp_path):
    """Damage at any offset (a corrupt zstd chunk, a bad channel id, a bad summary offset)
    gives an OcctoolError, never another exception."""
    from occtool.errors import OcctoolError
    from occtool.io import describe_log

    data = inputs["mcap"].read_bytes()
    path = tmp_path / "damaged.mcap"
    for offset in range(8, len(data), max(1, len(data) // 150)):
        for damage in (bytes(4), b"\xff" * 4):
            damaged = bytearray(data)
            damaged[offset: offset + 4] = damage
            path.write_bytes(bytes(damaged))
            for function in (read_log, describe_log):
                try:
                    function(path)
                except OcctoolError:
                    pass


@pytest.mark.parametrize("command", sorted(set(LOG_COMMANDS) - {"info"}))
def test_mcap_unknown_topic_lists_the_channels(command, inputs, out):
    args = LOG_COMMANDS[command](inputs["mcap"], out, inputs)
    result = run(*args, "--topic", "/camera/points")
    assert_fails(result, "no topic '/camera/points'", "/occtool/features", exit_code=1)
    assert_nothing_written(out)


def test_topic_on_a_csv_is_an_error(inputs, out):
    result = run("fit", inputs["csv"], "--topic", "/points", "-o", out / "model.json")
    assert_fails(result, "--topic applies to MCAP logs only")
    assert_nothing_written(out)


# --- bad --no-return-range ------------------------------------------------------------------

CARMEN = FIXTURES / "logs" / "tiny.carmen.log"
# Every command taking the log options (info reads a log without them).
LOG_OPTION_COMMANDS = {
    **{name: make for name, make in LOG_COMMANDS.items() if name != "info"},
    "compare-grid": lambda log, out, inputs: ["compare-grid", log, "--json", out / "report.json"],
}
BAD_NO_RETURN_RANGE = {
    "0": "must be a finite number of metres > 0, got 0",
    "-1": "must be a finite number of metres > 0, got -1",
    "nan": "must be a finite number of metres > 0, got nan",
    "inf": "must be a finite number of metres > 0, got inf",
    "-inf": "must be a finite number of metres > 0, got -inf",
    "far": "'far' is not a valid float",
}


@pytest.mark.parametrize("command", sorted(LOG_OPTION_COMMANDS))
@pytest.mark.parametrize("value", sorted(BAD_NO_RETURN_RANGE))
def test_bad_no_return_range(value, command, inputs, out):
    result = run(*LOG_OPTION_COMMANDS[command](CARMEN, out, inputs), f"--no-return-range={value}")
    output = assert_fails(result, "--no-return-range", BAD_NO_RETURN_RANGE[value], exit_code=2)
    assert len([line for line in result.output.splitlines() if "Error" in line]) == 1, output
    assert_nothing_written(out)


def test_bad_no_return_range_in_a_config_file(out, tmp_path):
    config = tmp_path / "log.toml"
    config.write_text("[log]\nno-return-range = -2.0\n")
    result = run("convert", CARMEN, "-o", out / "log.csv", "--config", config)
    assert_fails(result, "--no-return-range", "must be a finite number of metres > 0", exit_code=2)
    assert_nothing_written(out)


# --- broken model files ----------------------------------------------------------------------


def _model_variants(model: dict) -> dict[str, tuple[str, list[str]]]:
    def changed(**updates):
        data = json.loads(json.dumps(model))
        for key, value in updates.items():
            if value is None:
                del data[key]
            else:
                data[key] = value
        return json.dumps(data)

    text = json.dumps(model)
    training = dict(model["training"], samples_by_kind=7)
    no_loss = {k: v for k, v in model["training"].items() if k != "loss"}
    return {
        "truncated": (text[: len(text) // 2], ["not valid JSON"]),
        "newer format": (changed(format_version=2), ["newer occtool", "format version 2"]),
        "format version text": (changed(format_version="1"), ["format_version"]),
        "no training": (changed(training=None), ["'training'"]),
        "samples not an object": (changed(training=training), ["training summary"]),
        "piece not numbers": (changed(pieces=[dict(p, c="x") for p in model["pieces"]]), ["not a number"]),
        "basis a list": (changed(basis=["trig"]), ["unknown basis"]),
        "constraint NaN": (changed(constraints=dict(model["constraints"], c_min=float("nan"))), ["c_min"]),
        "rmse NaN": (changed(training=dict(model["training"], rmse=float("nan"))), ["rmse"]),
        "bad tree": (changed(tree={"op": "max", "children": [0, 99]}), ["99"]),
        "binary": ("\x00\xff" * 10, []),
        "no loss": (changed(training=no_loss), []),  # optional: must load, and re-save
        "guard distance text": (changed(guard=dict(model["guard"], distance_mm=["x"] * model["guard"]["bins"])),
                                ["guard", "millimetres"]),
        "guard too short": (changed(guard=dict(model["guard"], distance_mm=[1000])), ["distance_mm"]),
        "guard level 2": (changed(guard=dict(model["guard"], level=2)), ["level"]),
    }


@pytest.mark.parametrize("command", sorted(MODEL_COMMANDS))
@pytest.mark.parametrize("case", [
    "truncated", "newer format", "format version text", "no training", "samples not an object",
    "piece not numbers", "basis a list", "constraint NaN", "rmse NaN", "bad tree", "no loss",
])
def test_broken_model(case, command, inputs, out, tmp_path):
    content, fragments = _model_variants(json.loads(inputs["model"].read_text()))[case]
    path = tmp_path / "model.json"
    path.write_text(content)
    result = run(*MODEL_COMMANDS[command](path, out, inputs))
    if case == "no loss":
        # The loss is optional: the model loads and the command does what it does with the
        # model as saved, to the byte (info says only that the loss is not recorded).
        assert result.exit_code == 0, result.output
        (tmp_path / "saved").mkdir()
        saved = tmp_path / "saved" / "model.json"
        saved.write_bytes(inputs["model"].read_bytes())
        (tmp_path / "saved" / "out").mkdir()
        expected = run(*MODEL_COMMANDS[command](saved, tmp_path / "saved" / "out", inputs))
        assert expected.exit_code == 0, expected.output
        written = sorted(p.name for p in out.iterdir())
        assert written == sorted(p.name for p in (tmp_path / "saved" / "out").iterdir())
        assert len(written) == (command != "info")
        for name in written:
            mine, theirs = (out / name).read_bytes(), (tmp_path / "saved" / "out" / name).read_bytes()
            if name.endswith(".json"):  # the inverse records the model's training summary and path
                mine_data, theirs_data = json.loads(mine), json.loads(theirs)
                assert mine_data["model_training"].pop("loss") is None
                assert isinstance(theirs_data["model_training"].pop("loss"), float)
                assert mine_data["run"].pop("model") == str(path) and theirs_data["run"].pop("model") == str(saved)
                mine_data["run"].pop("date"), theirs_data["run"].pop("date")
                assert mine_data == theirs_data, name
            else:
                assert mine == theirs, name
        if command == "info":
            def lines(output: str) -> list[str]:
                return [" ".join(line.split()) for line in output.replace(str(saved), str(path)).splitlines()]

            differ = [(a, b) for a, b in zip(lines(result.output), lines(expected.output)) if a != b]
            assert len(lines(result.output)) == len(lines(expected.output))
            # One line differs: the fit error's, where the missing loss reads nan.
            assert [("fit error" in a and "loss nan" in a, "loss nan" in b) for a, b in differ] == [(True, False)], \
                differ
        return
    assert_fails(result, "model.json", *fragments, exit_code=1)
    assert_nothing_written(out)


@pytest.mark.parametrize("command", sorted(MODEL_COMMANDS))
@pytest.mark.parametrize("case", ["guard distance text", "guard too short", "guard level 2"])
def test_broken_return_guard(case, command, inputs, out, tmp_path):
    content, fragments = _model_variants(json.loads(inputs["model"].read_text()))[case]
    path = tmp_path / "model.json"
    path.write_text(content)
    assert_fails(run(*MODEL_COMMANDS[command](path, out, inputs)), "model.json", *fragments, exit_code=1)
    assert_nothing_written(out)


@pytest.mark.parametrize("command", ["invert", "extract", "plot-model"])
def test_not_a_model(command, inputs, out, tmp_path):
    for content in ('{"a": 1}', "\x00\xff" * 10, ""):
        path = tmp_path / "model.json"
        path.write_bytes(content.encode("latin-1"))
        result = run(*MODEL_COMMANDS[command](path, out, inputs))
        assert_fails(result, "model.json", exit_code=1)
        assert_nothing_written(out)


def test_broken_inverse(inputs, out, tmp_path):
    data = json.loads(inputs["inverse"].read_text())
    data["format_version"] = 7
    path = tmp_path / "inverse.json"
    path.write_text(json.dumps(data))
    for args in (["extract", path, "-o", out / "nav.geojson"], ["info", path]):
        assert_fails(run(*args), "inverse.json", "newer occtool", exit_code=1)
    assert_nothing_written(out)


# --- broken GeoJSON --------------------------------------------------------------------------

POLYGON = {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}
BAD_GEOJSON = {
    "truncated": ('{"type": "FeatureCollection", "features": [', ["not valid GeoJSON"]),
    "not a feature": ('{"a": 1}', ["not a GeoJSON Feature"]),
    "a list": ("[1, 2]", ["not a GeoJSON Feature"]),
    "no navigation": ('{"type": "FeatureCollection", "features": []}', ["kind 'navigation'"]),
    "bad coordinates": (json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"kind": "navigation"},
         "geometry": {"type": "Polygon", "coordinates": "x"}}]}), ["malformed"]),
    "NaN coordinate": (json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"kind": "navigation"},
         "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [float("nan"), 1], [0, 0]]]}}]}),
        ["not a finite number"]),
    "point not polygon": (json.dumps({"type": "Feature", "properties": {"kind": "navigation"},
                                      "geometry": {"type": "Point", "coordinates": [0, 0]}}), ["not a Polygon"]),
    "empty": ("", ["empty"]),
    "binary": ("\x00\xc4\xff" * 20, ["not a text"]),
}


@pytest.mark.parametrize("command", sorted(NAV_COMMANDS))
@pytest.mark.parametrize("case", sorted(BAD_GEOJSON))
def test_broken_geojson(case, command, inputs, out, tmp_path):
    content, fragments = BAD_GEOJSON[case]
    path = tmp_path / "nav.geojson"
    path.write_bytes(content.encode("latin-1"))
    result = run(*NAV_COMMANDS[command](path, out, inputs))
    output = assert_fails(result, "nav.geojson", *fragments, exit_code=1)
    assert "Warning" not in output
    assert_nothing_written(out)


def test_broken_truth(inputs, out, tmp_path):
    path = tmp_path / "truth.json"
    path.write_text('{"format": "occtool-scene-truth", ')
    assert_fails(run("evaluate", inputs["nav"], path), "truth.json", "not valid JSON", exit_code=1)
    assert_fails(run("evaluate", inputs["nav"], inputs["model"]), "not a scene truth file", exit_code=1)
    assert_fails(run("plot", "nav", inputs["nav"], "--truth", path, "-o", out / "nav.png"), "truth.json",
                 exit_code=1)
    assert_nothing_written(out)


# --- outputs ---------------------------------------------------------------------------------

# Commands writing one file: arguments given the output path.
WRITERS = {
    "fit": (lambda inputs, o: ["fit", inputs["csv"], "-o", o, "--pieces", "8"], "model.json"),
    "invert": (lambda inputs, o: ["invert", inputs["model"], "-o", o], "inverse.json"),
    "extract": (lambda inputs, o: ["extract", inputs["model"], "-o", o, "--angles", "72"], "nav.geojson"),
    "convert-csv": (lambda inputs, o: ["convert", inputs["mcap"], "-o", o], "log.csv"),
    "convert-mcap": (lambda inputs, o: ["convert", inputs["csv"], "-o", o], "log.mcap"),
    "plot-features": (lambda inputs, o: ["plot", "features", inputs["csv"], "-o", o], "features.png"),
    "plot-nav": (lambda inputs, o: ["plot", "nav", inputs["nav"], "-o", o], "nav.png"),
    "plot-model": (lambda inputs, o: ["plot", "model", inputs["model"], "-o", o, "--resolution", "16"], "model.png"),
}


@pytest.mark.parametrize("command", sorted(WRITERS))
def test_output_in_a_missing_folder(command, inputs, tmp_path):
    make, name = WRITERS[command]
    result = run(*make(inputs, tmp_path / "no_such_folder" / name))
    assert_fails(result, "no_such_folder", "does not exist", exit_code=1)
    assert not (tmp_path / "no_such_folder").exists()


@pytest.mark.parametrize("command", ["invert", "extract"])  # fit -o DIR writes a model set into DIR
def test_output_that_is_a_folder(command, inputs, out):
    make, _ = WRITERS[command]
    result = run(*make(inputs, out))
    assert_fails(result, "is a directory", str(out), exit_code=1)
    assert_nothing_written(out)


def test_output_to_a_pipe_is_written_into_it(inputs, tmp_path):
    """A device or pipe (/dev/null, a FIFO) is written into, never replaced by a file."""
    if not hasattr(os, "mkfifo"):
        pytest.skip("no named pipes here")
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    result = run("invert", inputs["model"], "-o", fifo)
    reader.join(timeout=10)
    assert result.exit_code == 0, result.output
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert received and json.loads(received[0])["format"] == "occtool-inverse"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]


def test_simulate_into_a_file_is_an_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert_fails(run("simulate", "open", "--features", "50", "-o", blocker / "scene"), "not a directory",
                 exit_code=1)
    assert blocker.read_text() == "x"


@pytest.mark.parametrize("command", ["fit", "convert-csv", "plot-features"])
def test_a_failing_command_keeps_the_old_output(command, inputs, out, tmp_path):
    """An existing output survives a failure untouched: the new file is complete or not written."""
    make, name = WRITERS[command]
    target = out / name
    target.write_text("old")
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z,m\n1,0,0,0.5\n1,0,0,2\n")
    args = [bad if a == inputs["csv"] or a == inputs["mcap"] else a for a in make(inputs, target)]
    assert_fails(run(*args), "line 3")
    assert target.read_text() == "old"
    assert sorted(p.name for p in out.iterdir()) == [name]


# --- overwrite: replace by default, refuse with --no-overwrite --------------------------------


@pytest.mark.parametrize("command", sorted(WRITERS))
def test_overwrite_by_default_and_no_overwrite_refuses(command, inputs, out):
    make, name = WRITERS[command]
    target = out / name
    target.write_text("old")
    result = run(*make(inputs, target), "--no-overwrite")
    assert_fails(result, str(target), "exists already", "--overwrite", exit_code=1)
    assert target.read_text() == "old"
    result = run(*make(inputs, target))
    assert result.exit_code == 0, result.output
    assert target.read_bytes() != b"old"
    assert sorted(p.name for p in out.iterdir()) == [name]


def test_simulate_overwrite(out):
    args = ("simulate", "open", "--features", "60", "-o", out)
    assert run(*args).exit_code == 0
    (out / "features.csv").unlink()
    (out / "truth.json").write_text("old")
    assert_fails(run(*args, "--no-overwrite"), "truth.json", "exists already", exit_code=1)
    assert sorted(p.name for p in out.iterdir()) == ["truth.json"] and (out / "truth.json").read_text() == "old"
    assert run(*args).exit_code == 0 and (out / "truth.json").read_text() != "old"


def test_model_set_outputs_respect_no_overwrite(inputs, tmp_path):
    """fit -o DIR/ and extract DIR/ -o DIR/ check every file they would write, before writing any."""
    log = tmp_path / "two.csv"
    rows = inputs["csv"].read_text().splitlines()
    start = next(i for i, line in enumerate(rows) if line.startswith("x,"))
    body = rows[start + 1:]
    log.write_text("x,y,z,m,position\n" + "\n".join(f"{r},{i % 2}" for i, r in enumerate(body)) + "\n")
    models = tmp_path / "models"
    models.mkdir()
    (models / "index.json").write_text("old")
    assert_fails(run("fit", log, "-o", f"{models}/", "--pieces", "4", "--no-overwrite"), "index.json",
                 "exists already")
    assert sorted(p.name for p in models.iterdir()) == ["index.json"]
    assert run("fit", log, "-o", f"{models}/", "--pieces", "4").exit_code == 0
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "nav_0001.geojson").write_text("old")
    assert_fails(run("extract", models, "-o", f"{maps}/", "--angles", "36", "--no-overwrite"),
                 "nav_0001.geojson", "exists already")
    assert sorted(p.name for p in maps.iterdir()) == ["nav_0001.geojson"]
    assert run("extract", models, "-o", f"{maps}/", "--angles", "36").exit_code == 0
    assert sorted(p.name for p in maps.iterdir()) == ["nav_0000.geojson", "nav_0001.geojson"]


@pytest.mark.parametrize("value", ["1.5", "5", "1", "0", "-0.2", "nan"])
@pytest.mark.parametrize("command", ["extract", "compare-grid"])
def test_an_occupancy_threshold_outside_0_1_is_refused(value, command, inputs, out):
    # At 1.5 or 5 nothing reads occupied: 6 % and 45 % of a map were in collision.
    source = inputs["model"] if command == "extract" else inputs["csv"]
    args = [command, source, "--threshold", value] + (["-o", out / "nav.geojson"] if command == "extract" else [])
    assert_fails(run(*args), "--threshold")
    assert_nothing_written(out)


@pytest.mark.parametrize(("args", "fragment"), [
    (["--seed", "-1"], "--seed"),
    (["--focus-range", "inf"], "--focus-range"),
])
def test_fit_options_out_of_their_domain_are_refused(args, fragment, inputs, out):
    assert_fails(run("fit", inputs["csv"], "-o", out / "model.json", *args), fragment)
    assert_nothing_written(out)


def test_a_precision_beyond_a_double_is_refused(inputs, out):
    assert_fails(run("extract", inputs["model"], "-o", out / "nav.geojson", "--precision", "400"), "--precision")
    assert_nothing_written(out)


@pytest.mark.parametrize(("content", "fragment"), [
    (b"pieces = 8.7\n", "whole number"),
    (b"seed = true\n", "whole number"),
    (b"\xff\xfe not text", "UTF-8"),
])
def test_a_config_file_is_read_as_written_or_refused(content, fragment, inputs, out, tmp_path):
    config = tmp_path / "fit.toml"
    config.write_bytes(content)
    assert_fails(run("fit", inputs["csv"], "-o", out / "model.json", "--config", config), fragment)
    assert_nothing_written(out)


def test_library_keywords_in_messages_read_as_flags_on_the_command_line():
    from occtool.cli.wording import as_flags

    assert as_flags("pass skip_invalid=True to drop bad rows") == "pass --skip-invalid to drop bad rows"
    assert as_flags("pick one with position=N or a model set") == "pick one with --position N or a model set"
    assert as_flags("(group_by='message' splits them)") == "(--group-by message splits them)"
    assert as_flags("(no_return_range=5 m)") == "(--no-return-range 5 m)"
    assert as_flags("topics= applies to MCAP logs only") == "--topic applies to MCAP logs only"
    # Other words with '=' are left alone.
    assert as_flags("n_angles=10 and positions=3") == "n_angles=10 and positions=3"


def test_a_library_error_names_the_keyword_and_the_command_the_flag(tmp_path):
    from occtool.errors import InputError
    from occtool.io import read_log

    log = tmp_path / "bad.csv"
    log.write_text("x,y,z,m\n1,0,0,0.9\n1,0,0,abc\n")
    with pytest.raises(InputError, match="skip_invalid=True"):
        read_log(log)
    result = CliRunner().invoke(cli, ["fit", str(log), "-o", str(tmp_path / "m.json")])
    assert result.exit_code != 0 and "--skip-invalid" in result.output and "skip_invalid=" not in result.output
