"""The ``occtool`` command group.

Subcommands live one per module in this package and are imported only when invoked,
so ``occtool --help`` stays instant. Library errors (:class:`occtool.errors.OcctoolError`)
and file-system errors become a one-line ``Error: ...`` and exit status 1; usage errors
exit with 2, as click does.
"""

from __future__ import annotations

import errno
import importlib
import io
import logging
import os
import signal
import sys
import warnings
from typing import Any

import click

from occtool._version import __version__

# name -> (module, function, one-line help). Order is the order of `occtool --help`.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "simulate": ("occtool.cli.simulate", "simulate", "Generate a synthetic scene: features.csv and truth.json."),
    "fit": ("occtool.cli.fit", "fit", "Fit a parametric occupancy model to a range log."),
    "info": ("occtool.cli.info", "info", "Describe a model file or a range log."),
    "invert": ("occtool.cli.invert", "invert", "Write the inverted model r = F^-1(alpha, h, m)."),
    "extract": ("occtool.cli.extract", "extract", "Extract the navigation polygon and points as GeoJSON."),
    "evaluate": ("occtool.cli.evaluate", "evaluate", "Score a navigation polygon against a scene's truth."),
    "map": ("occtool.cli.map", "map_command", "Fuse every position of a log into one world map (Nav2, Foxglove)."),
    "query": ("occtool.cli.query", "query", "Occupancy of x, y, z points in a saved world map (world.occmap)."),
    "merge": ("occtool.cli.merge", "merge", "Merge saved world maps (world.occmap) into one, in any order."),
    "evaluate-log": ("occtool.cli.evaluate_log", "evaluate_log",
                     "Score a log's fused map against a grid on held-out scans."),
    "compare-grid": ("occtool.cli.compare_grid", "compare_grid", "Compare the model with occupancy grids."),
    "convert": ("occtool.cli.convert", "convert", "Convert a range log (CSV, MCAP, ...) to CSV or MCAP."),
    "plot": ("occtool.cli.plot", "plot", "Draw features, models, navigation maps and reports."),
}


class LazyGroup(click.Group):
    """A group that imports a subcommand's module only when that subcommand runs."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in COMMANDS:
            return None
        module_name, attribute, _ = COMMANDS[name]
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                return None
            raise
        return getattr(module, attribute)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name][2]) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        from occtool.cli.wording import as_flags
        from occtool.errors import OcctoolError

        try:
            return super().invoke(ctx)
        except OcctoolError as exc:
            raise click.ClickException(as_flags(str(exc))) from exc
        except KeyboardInterrupt as exc:
            raise click.ClickException("interrupted by SIGINT (Ctrl-C)") from exc
        except BrokenPipeError as exc:
            # The reader of standard output went away (`| head`, a closed pipe).
            _detach_stdout()
            raise click.ClickException("standard output was closed before the output was written") from exc
        except OSError as exc:
            # Missing files, permissions, a full disk (ENOSPC), a read-only file system
            # (EROFS), the file-size limit (EFBIG, with SIGXFSZ ignored), a name too long.
            raise click.ClickException(_describe_os_error(exc)) from exc
        except MemoryError as exc:
            raise click.ClickException("out of memory: try fewer features or a coarser resolution") from exc


def _describe_os_error(exc: OSError) -> str:
    if exc.filename is not None and exc.strerror:
        name = str(exc.filename)
        if len(name) > 80:
            name = name[:40] + "..." + name[-20:]
        return f"{exc.strerror}: {name}"
    if exc.strerror:
        hint = {errno.ENOSPC: " (the output device or disk is full)",
                errno.EFBIG: " (the file-size limit, ulimit -f, was reached)"}.get(exc.errno or 0, "")
        return f"cannot write the output: {exc.strerror}{hint}"
    from occtool.cli.wording import as_flags

    return as_flags(str(exc))


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", "verbosity", count=True, help="More log messages (repeatable).")
@click.option("-q", "--quiet", "quietness", count=True, help="Fewer log messages (repeatable).")
@click.version_option(__version__, prog_name="occtool")
@click.pass_context
def cli(ctx: click.Context, verbosity: int, quietness: int) -> None:
    """Parametric occupancy models and navigation maps from robot range data.

    Coordinates follow ROS REP-103 (x forward, y left, z up) in metres and radians,
    in the robot frame centred at the sensor.
    """
    level = max(10, min(50, 30 - 10 * (verbosity - quietness)))
    from occtool.cli.wording import FlagWording

    handler = _RichOnFirstRecord()
    # The library names its keywords; the command line's messages name its flags.
    handler.addFilter(FlagWording())
    logging.basicConfig(level=level, format="%(message)s", handlers=[handler], force=True)
    # A numpy RuntimeWarning (or any other) is one log line, not a source line on stderr.
    warnings.showwarning = _log_warning
    ctx.ensure_object(dict)
    ctx.obj["verbosity"] = verbosity - quietness


class _RichOnFirstRecord(logging.Handler):
    """rich's log handler on standard error, made when the first record is emitted: a
    command that logs nothing (a fit at the default level) does not import rich (about
    40 ms of a fresh process's CPU)."""

    def __init__(self) -> None:
        super().__init__()
        self._rich: logging.Handler | None = None

    def emit(self, record: logging.LogRecord) -> None:
        if self._rich is None:
            from rich.console import Console
            from rich.logging import RichHandler

            self._rich = RichHandler(console=Console(stderr=True), show_time=False, show_path=False)
            self._rich.setFormatter(self.formatter)
        self._rich.handle(record)

    def setFormatter(self, fmt: logging.Formatter | None) -> None:  # noqa: N802 - logging's name
        super().setFormatter(fmt)
        if self._rich is not None:
            self._rich.setFormatter(fmt)


def _log_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                 file: Any = None, line: str | None = None) -> None:
    first_line = str(message).splitlines()[0] if str(message) else ""
    logging.getLogger("occtool").warning("%s: %s", category.__name__, first_line)


class Interrupted(BaseException):
    """Raised in the main thread on SIGTERM or SIGHUP, so every ``finally`` and temporary-file
    cleanup runs as for Ctrl-C (a BaseException: ``except Exception`` does not swallow it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _raise_interrupted(signum: int, frame: Any) -> None:
    raise Interrupted(signum)


def _install_signal_handlers() -> None:
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _raise_interrupted)
    if hasattr(signal, "SIGXFSZ"):
        # Past `ulimit -f` a write then fails with EFBIG (one line) instead of killing us.
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


class _ClosedStdout(io.TextIOBase):
    """Stands in for a standard output the process was started without (``>&-``): any
    write fails with EBADF, so a command printing to it ends in one line, not silence."""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        raise OSError(errno.EBADF, "standard output is closed: name an output file with -o")

    @property
    def buffer(self) -> _ClosedStdout:
        return self

    def isatty(self) -> bool:
        return False


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: signals and a closed standard output end in one line.

    Run as the process's entry point (``argv`` None: ``occtool ...``, ``python -m occtool``),
    the process ends at once after a command (:func:`_end_process`)."""
    code = _run(argv)
    if argv is None:
        _end_process(code)
    sys.exit(code)


def _run(argv: list[str] | None) -> int:
    """The command's exit status, its error (if any) told on standard error."""
    _one_blas_thread()
    _install_signal_handlers()
    if sys.stdout is None:
        sys.stdout = _ClosedStdout()
    try:
        code = cli.main(args=argv, prog_name="occtool", standalone_mode=False)
    except Interrupted as exc:
        print(f"Error: interrupted by {signal.Signals(exc.signum).name}", file=sys.stderr)
        return 128 + exc.signum
    except click.UsageError as exc:
        # One line, as every other error: the usage is one --help away.
        command = exc.ctx.command_path if exc.ctx is not None else "occtool"
        print(f"Error: {exc.format_message()} (see '{command} --help')", file=sys.stderr)
        return exc.exit_code
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except click.Abort:
        print("Error: aborted", file=sys.stderr)
        return 1
    return code if isinstance(code, int) else 0


def _end_process(code: int) -> None:
    """End the process without tearing the interpreter down: the exit handlers run
    (logging's, a pool's, temporary folders'), the standard streams are flushed, and
    ``os._exit`` ends it. Freeing numpy's and every module's objects one by one at the
    usual exit took 30-60 ms of CPU on this project's 2-core machine, a third of a fresh
    ``occtool fit`` of 10k features besides interpreter start and imports.

    Returns, for the usual exit, while another thread runs (the usual exit waits for
    it) or when a stream cannot be flushed (the usual exit reports that as it did)."""
    import threading

    if threading.active_count() > 1:
        return
    import atexit

    atexit._run_exitfuncs()
    try:
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
    except (OSError, ValueError):
        return
    os._exit(code)


#: Variables OpenBLAS (numpy's BLAS) reads its thread count from, in its order.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def _one_blas_thread() -> None:
    """One OpenBLAS thread unless the environment asks for a count (set before numpy loads).

    numpy starts one BLAS thread per core when it is imported, and they spin while they
    wait: on this project's 2-core machine the import then took 0.2 s of CPU instead of
    0.09 s, in every command. occtool's matrix products are small (a fit of a million
    features took no less wall time with them), and ``-j`` runs processes of its own.
    """
    if not any(os.environ.get(name) for name in BLAS_THREAD_VARIABLES):
        os.environ["OPENBLAS_NUM_THREADS"] = "1"


def _detach_stdout() -> None:
    """Point standard output at /dev/null, so the flush at exit does not fail a second time."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass


if __name__ == "__main__":  # pragma: no cover
    main()
