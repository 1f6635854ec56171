"""Issue 12, classes 5 and 6: the operating system says no, or the user stops the run.

A full disk, a read-only file system, the file-size limit, a 255-character output name and
a closed standard output each end in one line on stderr and a non-zero exit, with no file
left behind; SIGTERM, SIGHUP and SIGINT during a write remove the temporary file. The
signal and ulimit cases need a real process (the console entry point installs the
handlers); the others run in-process.
"""

from __future__ import annotations

import errno
import os
import resource
import signal
import subprocess
import sys
import time
import traceback
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool._files import atomic_write
from occtool.cli.main import cli

ROOT = Path(__file__).resolve().parent.parent
FIXTURES = ROOT / "fixtures"
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def run(*args: object):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_error_line(result) -> str:
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    assert result.exit_code == 1, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1 and "Traceback" not in result.output, result.output
    return errors[0]


@pytest.fixture(scope="module")
def csv(tmp_path_factory) -> Path:
    lines = (FIXTURES / "office" / "features.csv").read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("x,"))
    path = tmp_path_factory.mktemp("in") / "features.csv"
    path.write_text("\n".join(lines[start: start + 2001]) + "\n")
    return path


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
@pytest.mark.parametrize("command", [["convert", "{csv}", "-o", "/dev/full", "--to", "csv"],
                                     ["fit", "{csv}", "-o", "/dev/full", "--pieces", "8"]])
def test_a_full_disk_is_one_line(csv, command):
    error = one_error_line(run(*[str(a).format(csv=csv) for a in command]))
    assert "No space left on device" in error


@pytest.mark.parametrize(("code", "words"), [(errno.EROFS, "Read-only file system"), (errno.ENOSPC, "No space left"),
                                             (errno.EFBIG, "ulimit -f"), (errno.EIO, "Input/output error")])
def test_write_failures_of_the_file_system_are_one_line_and_leave_nothing(csv, tmp_path, monkeypatch, code, words):
    def failing_replace(source, target):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr("occtool._files.os.replace", failing_replace)
    out = tmp_path / "out"
    out.mkdir()
    error = one_error_line(run("convert", csv, "-o", out / "x.csv"))
    assert words in error
    assert list(out.iterdir()) == []


@settings(max_examples=20)
@given(length=st.integers(200, 255))
def test_long_output_names_up_to_name_max_are_written(tmp_path_factory, length):
    folder = tmp_path_factory.mktemp("long")
    name = "a" * (length - 4) + ".csv"
    with atomic_write(folder / name) as handle:
        handle.write("x\n")
    assert [p.name for p in folder.iterdir()] == [name]


def test_a_255_character_output_name_is_written_and_a_longer_one_is_one_line(csv, tmp_path):
    name = "n" * 251 + ".csv"
    assert run("convert", csv, "-o", tmp_path / name).exit_code == 0
    assert [p.name for p in tmp_path.iterdir()] == [name]
    error = one_error_line(run("convert", csv, "-o", tmp_path / ("n" * 252 + ".csv")))
    assert "File name too long" in error and len(error) < 200


# --- real processes: signals, ulimit, closed stdout ------------------------------------------------

SLOW_WRITER = """
import os, signal, sys, time
# Ctrl-C as in a terminal: a shell's background job (nohup, `&`) starts with SIGINT ignored,
# and Python then keeps ignoring it.
signal.signal(signal.SIGINT, signal.default_int_handler)
real_fsync = os.fsync
def slow_fsync(fd):  # atomic_write syncs the temporary file before renaming it
    open(sys.argv[1], "w").close()   # the temporary file is written: tell the test
    time.sleep(30)
    real_fsync(fd)
os.fsync = slow_fsync
from occtool.cli.main import main
main(sys.argv[2:])
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_a_signal_during_convert_removes_the_temporary_file(csv, tmp_path, signum):
    out = tmp_path / "out"
    out.mkdir()
    ready = tmp_path / "ready"
    process = subprocess.Popen(
        [sys.executable, "-c", SLOW_WRITER, str(ready), "convert", str(csv), "-o", str(out / "log.mcap")],
        env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not ready.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert any(p.name.endswith(".tmp") for p in out.iterdir())
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode != 0
    assert list(out.iterdir()) == []
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: interrupted by"), stderr


def test_the_file_size_limit_is_one_line(csv, tmp_path):
    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))

    out = tmp_path / "out"
    out.mkdir()
    result = subprocess.run([sys.executable, "-m", "occtool", "convert", str(csv), "-o", str(out / "x.csv")],
                            env=ENV, capture_output=True, text=True, preexec_fn=limit, timeout=120, check=False)
    assert result.returncode == 1, result.stderr
    assert result.stderr.strip().splitlines() == [
        "Error: cannot write the output: File too large (the file-size limit, ulimit -f, was reached)"]
    assert list(out.iterdir()) == []


@pytest.mark.parametrize("command", [["info", "{csv}"], ["convert", "{csv}", "-o", "-"]])
def test_a_closed_standard_output_is_one_line(csv, command):
    args = [str(a).format(csv=csv) for a in command]
    result = subprocess.run([sys.executable, "-m", "occtool", *args], env=ENV, capture_output=False,
                            stdout=None, stderr=subprocess.PIPE, text=True, timeout=120,
                            preexec_fn=lambda: os.close(1), check=False)
    assert result.returncode == 1
    assert result.stderr.strip().splitlines() == [
        "Error: cannot write the output: standard output is closed: name an output file with -o"]


def test_a_reader_that_goes_away_is_one_line(csv):
    process = subprocess.Popen([sys.executable, "-m", "occtool", "convert", str(csv), "-o", "-"], env=ENV,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    process.stdout.close()  # gone before the first write (like `| head -0`)
    with process.stderr:
        stderr = process.stderr.read()
    process.wait(timeout=120)
    assert process.returncode == 1
    assert stderr.strip().splitlines() == ["Error: standard output was closed before the output was written"]


def test_a_bad_option_is_one_line_on_stderr_from_the_console_script(tmp_path):
    result = subprocess.run([sys.executable, "-m", "occtool", "simulate", "office", "-o", str(tmp_path / "d/"),
                             "--features", "1000000000"], capture_output=True, text=True, check=False)
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("Error: Invalid value for '--features'")
    assert "--help" in result.stderr and not (tmp_path / "d").exists()


def test_an_interrupt_the_moment_the_temporary_file_exists_leaves_nothing(tmp_path, monkeypatch):
    # A signal handled right after the temporary file is made (a SIGTERM on a loaded
    # machine once landed there) must still remove it: its name is known before it exists.
    import occtool._files as atomic

    real_open = os.open

    def open_then_interrupt(path, flags, mode=0o777):
        real_open(path, flags, mode)
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "open", open_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        with atomic_write(tmp_path / "out.json") as handle:
            handle.write("{}")
    assert list(tmp_path.iterdir()) == []
