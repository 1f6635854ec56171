"""Logging levels: a reader's routine facts at INFO, what the user should act on at WARNING."""

from __future__ import annotations

import logging
import pickle
from pathlib import Path

import pytest
from click.testing import CliRunner

from occtool.cli.main import cli
from occtool.features import Note, log_notes, note_level
from occtool.io import read_log

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "logs"
CLEAN = FIXTURES / "tiny.carmen.log"


@pytest.fixture
def unparsable(tmp_path):
    """The clean CARMEN log with one laser line that does not parse."""
    log = tmp_path / "bad.carmen.log"
    log.write_text(CLEAN.read_text() + "FLASER 4 1.0 nonsense\n")
    return log


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def heights(command):
    """``fit`` takes a planar log's laser heights itself; ``map`` warns until they are given
    (the laser plane at the default body band's edge is something to act on)."""
    return ["-j", "1"] if command == "fit" else ["--sensor-height", "0.3", "--body-height", "0.5"]


def warning_lines(output: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith("WARNING")]


@pytest.mark.parametrize("command", ["map", "fit"])
def test_a_clean_log_prints_no_warning(command, tmp_path):
    result = run(command, CLEAN, "-o", f"{tmp_path / 'out'}/", *heights(command))
    assert result.exit_code == 0, result.output
    assert warning_lines(result.output) == []
    # the routine facts are still there, one -v away
    verbose = run("-v", command, CLEAN, "-o", f"{tmp_path / 'verbose'}/", *heights(command))
    assert any("constant evidence" in line for line in verbose.output.splitlines() if line.startswith("INFO"))


@pytest.mark.parametrize("command", ["map", "fit"])
def test_an_unparsable_line_is_a_warning(command, tmp_path, unparsable):
    result = run(command, unparsable, "--skip-invalid", "-o", f"{tmp_path / 'out'}/", *heights(command))
    assert result.exit_code == 0, result.output
    lines = warning_lines(result.output)
    assert len(lines) == 1 and "do not parse" in lines[0], result.output


def test_the_reader_marks_its_notes(unparsable):
    notes = read_log(unparsable, skip_invalid=True).notes
    levels = {note: note_level(note) for note in notes}
    assert levels["skipped 1 laser line(s) that do not parse"] == logging.WARNING
    assert [level for note, level in levels.items() if note.startswith("constant evidence")] == [logging.INFO]


def test_info_still_shows_every_note(unparsable):
    result = run("info", CLEAN)
    assert result.exit_code == 0, result.output
    for note in read_log(CLEAN).notes:
        assert note.split(" (")[0] in result.output


def test_a_note_keeps_its_level_through_copies_and_processes(caplog):
    note = Note.warn("dropped 3 scan(s) whose pose is not finite")
    again = pickle.loads(pickle.dumps(note))
    assert again == note and note_level(again) == logging.WARNING
    assert note_level(list([note])[0]) == logging.WARNING
    logger = logging.getLogger("occtool.test_levels")
    with caplog.at_level(logging.DEBUG, logger="occtool.test_levels"):
        log_notes(logger, "x.log", ["a routine fact", note])
    assert [(r.levelno, r.getMessage()) for r in caplog.records] == [
        (logging.INFO, "x.log: a routine fact"), (logging.WARNING, f"x.log: {note}")]


def test_other_readers_mark_what_to_act_on(tmp_path):
    plain = read_log(FIXTURES / "tiny.xyz").notes
    assert plain and all(note_level(note) == logging.INFO for note in plain)  # constant evidence: routine
    rows = tmp_path / "rows.csv"
    rows.write_text("x,y,z,m\n1,0,0,0.9\n1,zero,0,0.9\n0,1,0,0.9\n")
    notes = read_log(rows, skip_invalid=True).notes
    skipped = [note for note in notes if note.startswith("skipped 1 invalid row")]
    assert skipped and note_level(skipped[0]) == logging.WARNING
