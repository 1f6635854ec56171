"""Options shared by several subcommands.

Each ``*_options`` decorator adds a group of options to a command; the matching
``*_from_kwargs`` helper (where there is one) pops those options out of the command's
keyword arguments and builds the library's parameter object, so every command that
fits, extracts or compares reads them the same way.

``--config FILE`` reads defaults for any option from a TOML file: top-level keys or
keys under ``[sensor]``, ``[fit]``, ``[extract]``, ``[log]`` tables, spelled as the
flags without their dashes (``topic``, ``depth-error = 0.03``, ``no-path = true``) or as
the parameter's name, with dashes or underscores. Each value passes the option's own
click type and callback (:mod:`occtool.cli._config`). Options given on the command line win.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from occtool.cli._config import COMMA_LISTS, load_config
from occtool.io.read_options import (  # a light module: --help imports no numpy
    DEFAULT_CONSTANT_EVIDENCE,
    DEFAULT_DEPTH_MIN_RANGE,
    FORMATS,
    GROUP_BY_CHOICES,
    OPTION_NAMES,
    ReadOptions,
    check_no_return_range,
)
from occtool.limits import (
    DEFAULT_MEMORY_LIMIT,
    MAX_ANGLES,
    MAX_BODY_SAMPLES,
    MAX_DISTANCE,
    MAX_FEATURES,
    MAX_PIECES,
    MAX_ROBOT_SIZE,
    MAX_SWEEPS,
    MAX_WEIGHT,
)

F = TypeVar("F", bound=Callable[..., Any])

if TYPE_CHECKING:
    from occtool.features import RangeLog


def _compose(*decorators: Callable[[F], F]) -> Callable[[F], F]:
    def apply(function: F) -> F:
        for decorator in reversed(decorators):
            function = decorator(function)
        return function

    return apply


def float_list(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> tuple[float, ...] | None:
    """Parse ``"-0.9,-0.5,-0.1"`` (or a TOML list) into a tuple of floats."""
    if value is None or value == "":
        return None
    if isinstance(value, (list, tuple)):
        items = list(value)
    else:
        items = [v for v in str(value).replace(" ", "").split(",") if v]
    try:
        return tuple(float(v) for v in items)
    except ValueError:
        raise click.BadParameter(f"expected comma-separated numbers, got {value!r}") from None


# --- configuration file (read by occtool.cli._config) ---------------------------------

config_option = click.option(
    "--config",
    type=click.Path(dir_okay=False),
    callback=load_config,
    is_eager=True,
    expose_value=False,
    help="TOML file with defaults for any option of this command.",
)

# --- output ---------------------------------------------------------------------------

output_option = click.option(
    "-o", "--output", type=click.Path(dir_okay=True, allow_dash=True), default=None,
    help="Output file ('-' or absent: standard output, where the command allows it).",
)
seed_option = click.option("--seed", type=click.IntRange(min=0, max=2**63 - 1), default=0, show_default=True,
                           help="Random seed, a whole number >= 0.")
overwrite_option = click.option(
    "--overwrite/--no-overwrite", default=True, show_default=True,
    help="Replace existing output files, or refuse (and write nothing) if one exists.",
)



def _memory_limit(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> str | None:
    """``--memory-limit``: checked here (a usage error naming the flag), passed on as given."""
    from occtool.errors import InputError
    from occtool.limits import memory_bytes

    try:
        return None if memory_bytes(value, "--memory-limit") is None else str(value)
    except InputError as exc:
        raise click.BadParameter(str(exc).removeprefix("--memory-limit "), ctx=ctx, param=param) from None


#: ``--memory-limit`` (``map``): the library's ``memory_limit`` (:func:`occtool.fuse._memory.check_map_memory`).
memory_limit_option = click.option(
    "--memory-limit", default=DEFAULT_MEMORY_LIMIT, show_default=True, metavar="SIZE", callback=_memory_limit,
    help="Refuse (before the work) a run estimated to need more memory than SIZE: bytes, or 500M, 8G "
         "(decimal); 'none': no limit. The estimate counts the positions and the raster of the log's extent.",
)

#: ``--memory-limit`` (``plot map``, ``info``): the library's ``memory_limit`` of
#: :func:`occtool.formats.nav2.read_nav2`, reading a Nav2 map back.
read_memory_limit_option = click.option(
    "--memory-limit", default=DEFAULT_MEMORY_LIMIT, show_default=True, metavar="SIZE", callback=_memory_limit,
    help="Refuse (before reading its pixels) a Nav2 map estimated to need more memory than SIZE: bytes, or "
         "500M, 8G (decimal); 'none': no limit. A PGM map takes a byte a cell (less when drawn reduced), a PNG "
         "map about 16.",
)

#: ``--keyframe-share`` (``map``, ``evaluate-log``): what it changes for the user. The cells
#: are :data:`occtool.fuse._keyframes.KEYFRAME_CELL` wide (not imported: numpy, cold start).
KEYFRAME_SHARE_HELP = (
    "Fit a position of LOG only when at least this share (0-1) of the 0.2 m world cells its returns "
    "hit were hit by no position fitted before it. Raised: fewer positions fitted (faster, a smaller "
    "map, each wall seen by fewer positions); lowered: more positions fitted, slower (on Intel, 0.05 "
    "fits 420 of 819 positions)."
)


def json_option(what: str) -> Callable[[F], F]:
    """``--json [FILE]``, the same in every command that reports figures: the report (``what``)
    as JSON to FILE, ``-`` or no FILE for standard output instead of the table. The keyword
    argument is ``json_path`` (``None`` without the option)."""
    return click.option(
        "--json", "json_path", type=click.Path(dir_okay=False, allow_dash=True), default=None,
        is_flag=False, flag_value="-", metavar="[FILE]",
        help=f"Write {what} as JSON to FILE (the table is still printed), or with '-' or no FILE to "
             "standard output instead of the table.")


def write_json_report(json_path: str | None, text: str) -> bool:
    """Write a ``--json`` report (:func:`json_option`); true when it went to standard output
    (the command then prints no table)."""
    if json_path is None:
        return False
    from occtool._files import atomic_write

    with atomic_write(json_path, "w") as handle:
        handle.write(text + "\n")
    return json_path == "-"


def refuse_existing(overwrite: bool, *paths: Any) -> None:
    """With ``--no-overwrite``, stop before any work if one of the output files exists."""
    if overwrite:
        return
    for path in paths:
        if path is not None and str(path) != "-" and Path(path).exists():
            raise click.ClickException(f"{path} exists already (pass --overwrite to replace it)")

# --- where positions run (owner: model sets) -------------------------------------------

def _jobs(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or int(value) != value or int(value) < 1:
        raise click.BadParameter(f"must be a whole number >= 1, got {value}")
    return int(value)


def jobs_options(work: str, *, subject: str = "Model sets",
                 default: str = "as many as the machine has cores") -> Callable[[F], F]:
    """``-j`` and ``--scheduler``, their help saying what runs in parallel for this command
    (``work``: "positions fitted at once", "models extracted at once", ...), for what
    (``subject``) and how many by default (``default``)."""
    return _compose(
        click.option("-j", "--jobs", type=int, default=None, callback=_jobs, metavar="N",
                     help=f"{subject}: {work}, each in a local process [default: {default}]. "
                          "The output is the same for any N."),
        click.option("--scheduler", default=None, metavar="ADDRESS",
                     help=f"{subject}: run the same work on the Dask cluster at ADDRESS (tcp://host:8786) "
                          "instead of local processes; needs occtool[dask] here and occtool on the workers."),
    )

# --- range-log reading (owner: readers) ------------------------------------------------

def _position_tolerance(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> tuple[float, float]:
    values = float_list(ctx, param, value)
    if values is None or len(values) != 2 or any(v < 0 or v != v for v in values):
        raise click.BadParameter(f"expected 'METRES,RADIANS' (two numbers >= 0), got {value!r}")
    return values[0], values[1]


def _unit_interval(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> float | None:
    if value is None:
        return None
    if not 0.0 <= float(value) <= 1.0:
        raise click.BadParameter(f"must lie in [0, 1], got {value}")
    return float(value)


def no_return_range_callback(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> float | None:
    # The readers' own check, so the rule lives in one place; click names the option.
    from occtool.errors import InputError

    name = (param.name if param is not None and param.name else "no_return_range").replace("_", " ")
    try:
        return check_no_return_range(value, name.replace("no return", "no-return"))
    except InputError as exc:
        raise click.BadParameter(str(exc)) from None


def _text(values: Any) -> str:
    """A default as the command line spells it: ``0.25,0.26`` for a pair."""
    if isinstance(values, (tuple, list)):
        return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in values)
    return f"{values:g}" if isinstance(values, float) else str(values)


_READ_DEFAULTS = {f.name: f.default for f in dataclasses.fields(ReadOptions)}

#: Each :class:`occtool.io.ReadOptions` field's command-line option, in the field's order:
#: its flags and click settings. The default is the field's (``_READ_DEFAULTS``), never
#: written here; a test holds this table and the dataclass to the same names.
LOG_FLAGS: dict[str, tuple[tuple[str, ...], dict[str, Any]]] = {
    "format": (("--format", "format"), dict(
        type=click.Choice(list(FORMATS), case_sensitive=False),
        help="Log format (default: from the content and extension).")),
    "topics": (("--topic", "topics"), dict(
        multiple=True,
        help="MCAP or ROS bag topic to read (repeatable; default: the one supported range channel).")),
    "evidence_field": (("--evidence-field",), dict(
        show_default=True,
        help="Point field or CSV column holding the evidence value (CSV also accepts m).")),
    "evidence": (("--evidence",), dict(
        type=float, callback=_unit_interval,
        help="Constant evidence for data without an evidence field (laser scans: "
             f"{DEFAULT_CONSTANT_EVIDENCE:g} if not given).")),
    "use_intensities": (("--intensities", "use_intensities"), dict(
        is_flag=True, help="Laser scans: evidence from the intensities, scaled by the scan's largest.")),
    "sensor_frame": (("--sensor-frame",), dict(help="MCAP: frame the points are in (default: the message's).")),
    "base_frame": (("--base-frame",), dict(help="MCAP: robot base frame (default: base_link, if in /tf_static).")),
    "position_tolerance": (("--position-tolerance",), dict(
        show_default=True, callback=_position_tolerance,
        help="Consecutive scans within DIST,ANGLE (metres, radians) of a position's first scan form one position.")),
    "group_by": (("--group-by",), dict(
        type=click.Choice(list(GROUP_BY_CHOICES)), show_default=True,
        help="Group scans into robot positions, or make each message its own position.")),
    "skip_invalid": (("--skip-invalid",), dict(
        is_flag=True,
        help="Drop invalid rows/points (NaN, evidence outside [0, 1], unparsable) and report how many.")),
    "no_return_range": (("--no-return-range",), dict(
        type=float, callback=no_return_range_callback, metavar="METRES",
        help="Laser scans (CARMEN, LaserScan): keep each beam that returned nothing within range as a "
             "free ray, a feature with evidence 0 at min(METRES, the beam's max range), saying its ray is "
             "free and nothing about an obstacle (default: such beams are dropped; ignored for point clouds "
             "and CSV).")),
    "no_return_code": (("--no-return-code",), dict(
        type=float, callback=no_return_range_callback, metavar="METRES",
        help="CARMEN laser logs: readings at or above METRES are the laser's no-return code, not returns "
             "(default: found in the log, its repeated largest readings, per laser; occtool info LOG names "
             "them).")),
    "depth_features": (("--depth-features",), dict(
        type=click.IntRange(min=1, max=MAX_FEATURES), show_default=True, metavar="N",
        help="Depth images: most features kept of each frame, on a regular pixel grid (keeps each surface's "
             "share).")),
    "depth_noise": (("--depth-noise",), dict(
        type=click.FloatRange(min=0.0, max=1.0), show_default=True, metavar="K",
        help="Depth images: depth noise sigma = K z^2 metres that gives each pixel its evidence "
             f"({_READ_DEFAULTS['depth_noise']:g} structured light, about 0.005-0.01 stereo).")),
    "depth_max_range": (("--depth-max-range",), dict(
        type=click.FloatRange(min=DEFAULT_DEPTH_MIN_RANGE, max=MAX_DISTANCE, min_open=True), show_default=True,
        metavar="METRES",
        help="Depth images: farther depths are no returns (dropped, or free rays with --no-return-range).")),
    "poses": (("--poses",), dict(
        type=click.Path(exists=True, dir_okay=False), metavar="POSES.txt",
        help="Scans (a folder of *.pcd, *.ply, KITTI *.bin, or point-cloud files): a KITTI-style poses file, "
             "line i the row-major 3x4 scan-to-world transform of scan i.")),
}
#: The log options' names: :class:`occtool.io.ReadOptions`' fields, the keywords of :func:`occtool.io.read_log`.
LOG_OPTION_NAMES = OPTION_NAMES


def log_option(name: str, **changes: Any) -> Callable[[F], F]:
    """The click option of the :class:`~occtool.io.ReadOptions` field ``name``, its default the
    field's; ``changes`` replace settings of :data:`LOG_FLAGS` (a command's own help text)."""
    flags, settings = LOG_FLAGS[name]
    default = _READ_DEFAULTS[name]
    if isinstance(default, tuple):
        default = _text(default)  # a pair is typed METRES,RADIANS and parsed by its callback
    return click.option(*flags, default=default, **{**settings, **changes})


log_options = _compose(*(log_option(name) for name in OPTION_NAMES))


def pop_log_options(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Pop the :data:`log_options` out of a command's keyword arguments: the keywords of
    :func:`occtool.io.read_log` (no ``--topic``: ``topics=None``)."""
    options = {name: kwargs.pop(name) for name in LOG_OPTION_NAMES if name in kwargs}
    if "topics" in options:
        options["topics"] = list(options["topics"]) or None
    return options


def read_log_from_kwargs(path: str, kwargs: dict[str, Any]) -> RangeLog:
    """Pop the :data:`log_options` out of a command's keyword arguments and read the log.

    Returns the :class:`occtool.features.RangeLog`; its notes (skipped rows, missing
    poses at WARNING, routine facts at INFO) are logged by :func:`occtool.features.log_notes`.
    """
    import logging

    from occtool.features import log_notes
    from occtool.io import read_log

    options = pop_log_options(kwargs)
    if str(path) == "-":
        from occtool.io.stream import read_log_stream

        log = read_log_stream(**options)
    else:
        log = read_log(path, **options)
    log_notes(logging.getLogger("occtool.io"), Path(path).name, log.notes)
    return log

# --- sensor model and fit (owner: core model) -----------------------------------------

#: The library's defaults as the command line states them: the options that leave the
#: choice to the library (default None) name them in their help, the robot's and the
#: extraction's take them as their own. Spelled here, once, because the library's modules
#: import numpy and ``--help`` must not; tests/test_cli_model.py holds each equal to the
#: library keyword it maps to (``SensorModel``'s and ``Robot``'s fields,
#: ``OccupancyRegressor.__init__``'s and ``navigation_map``'s keywords).
LIBRARY_DEFAULTS: dict[str, Any] = {
    # occtool.sensor.SensorModel
    "depth_error": 0.03, "near_positions": (0.8, 0.9), "near_values": (0.2, 0.4), "floor": "free",
    "footprint_samples": 512, "background_samples": 0, "background_weight": 0.05, "background_range": 3.0,
    # occtool.fit.OccupancyRegressor
    "basis": "trig", "c_min": 0.25, "a_max": 12.0, "b_max": 8.0, "c_max": 8.0, "loss": "huber", "huber_delta": 0.1,
    "max_sweeps": 0, "focus_range": 4.0, "guard": True,
    # occtool.robot.Robot (--robot-radius is its radius)
    "robot_radius": 0.25, "sensor_height": 1.0, "body_height": 1.0, "ground_clearance": 0.05,
    # occtool.navigation.navigation_map (--angles is its n_angles)
    "threshold": 0.6, "max_range": 1.5, "n_angles": 360, "return_snap": 0.5,
}


def _default(name: str) -> str:
    """`` [default: X]`` for a help text, X the library's default of ``name``."""
    return f" [default: {_text(LIBRARY_DEFAULTS[name])}]"


SENSOR_OPTION_NAMES = (
    "depth_error", "near_positions", "near_values", "floor", "footprint_samples", "background_samples",
    "background_weight", "background_range",
)
FIT_OPTION_NAMES = ("pieces", "basis", "c_min", "a_max", "b_max", "c_max", "loss", "huber_delta", "groups", "max_sweeps",
                    "focus_range", "guard")


def _pair(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> tuple[float, float] | None:
    values = float_list(ctx, param, value)
    if values is not None and len(values) != 2:
        raise click.BadParameter(f"expected two comma-separated numbers, got {value!r}")
    return values


# Callbacks that read a comma-separated list of numbers: a TOML list is written out for them.
COMMA_LISTS.update((float_list, _pair, _position_tolerance))

sensor_options = _compose(
    click.option("--depth-error", type=float, default=None,
                 help=f"Relative depth error: hit samples at r(1 -+ e){_default('depth_error')}."),
    click.option("--near-positions", callback=_pair, default=None,
                 help=f"Near samples' positions as fractions of the feature's range, 'P1,P2'{_default('near_positions')}."),
    click.option("--near-values", callback=_pair, default=None,
                 help=f"Near samples' values as fractions of the feature's evidence, 'V1,V2'{_default('near_values')}."),
    click.option("--floor", type=click.Choice(["free", "drop", "obstacle"]), default=None,
                 help="Floor features (below the ground clearance): free-space samples only, dropped, "
                      f"or obstacles{_default('floor')}."),
    click.option("--footprint-samples", type=click.IntRange(min=0, max=MAX_BODY_SAMPLES), default=None,
                 help=f"Zero-occupancy samples filling the robot's body{_default('footprint_samples')}."),
    click.option("--background-samples", type=click.IntRange(min=0, max=MAX_BODY_SAMPLES), default=None,
                 help=f"Zero-occupancy background samples for featureless directions{_default('background_samples')}."),
    click.option("--background-weight", type=float, default=None,
                 help=f"Weight of each background sample{_default('background_weight')}."),
    click.option("--background-range", type=click.FloatRange(min=0, max=MAX_DISTANCE, min_open=True), default=None,
                 help=f"Farthest background sample, metres{_default('background_range')}."),
)


def fit_options(function: F) -> F:
    """The fit's options: pieces, basis, constraints, loss, plus the sensor and robot options."""
    options = _compose(
        sensor_options,
        robot_options,
        click.option("-L", "--pieces", type=click.IntRange(min=1, max=MAX_PIECES), default=None,
                     help="Number of linear pieces [default: 64, and beyond 10,000 features a position more, "
                          "up to 128 from 40,000 on]."),
        click.option("--basis", type=click.Choice(["trig", "linear"]), default=LIBRARY_DEFAULTS["basis"], show_default=True,
                     help="Pieces a1 cos(alpha) + a2 sin(alpha) + b h + c r + d (seam-free) or the paper's "
                          "a alpha + b h + c r + d."),
        click.option("--c-min", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None,
                     help=f"Lower bound of the range weight c, per metre{_default('c_min')}."),
        click.option("--a-max", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None,
                     help=f"Bound of |dF/dalpha|, per radian{_default('a_max')}."),
        click.option("--b-max", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None,
                     help=f"Bound of the height weight |b|, per metre{_default('b_max')}."),
        click.option("--c-max", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None,
                     help="How steeply a model's occupancy may rise with range at an obstacle, occupancy per "
                          "metre: the step from free (0) to occupied (1) in front of a wall spans at least 1/C "
                          f"metres (8: 12.5 cm). Raised: sharper walls, but the navigation map's safety margin "
                          f"grows with the steepest piece; lowered: smoother walls, a step over more range"
                          f"{_default('c_max')}."),
        click.option("--loss", type=click.Choice(["huber", "squared"]), default=LIBRARY_DEFAULTS["loss"], show_default=True,
                     help="Regression loss (Huber is robust to outliers)."),
        click.option("--huber-delta", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None,
                     help=f"Huber loss threshold{_default('huber_delta')}."),
        click.option("--groups", type=click.IntRange(min=1), default=None,
                     help="Angular segments of the tree [default: pieces // 4]."),
        click.option("--max-sweeps", type=click.IntRange(min=0, max=MAX_SWEEPS), default=None,
                     help=f"Least-squares refit sweeps after the construction{_default('max_sweeps')}."),
        click.option("--focus-range", type=click.FloatRange(min=0.0, max=MAX_DISTANCE, min_open=True), default=None, callback=_positive,
                     help="Farthest horizontal distance fitted, metres; scale it with the maps' "
                          f"--max-range (about 2.5x){_default('focus_range')}."),
        click.option("--guard/--no-guard", default=None,
                     help="Keep the position's returns in the model, so that every navigation map keeps the "
                          "robot's radius from each of them [default: guard]."),
    )
    return options(function)


def sensor_from_kwargs(kwargs: dict[str, Any]) -> Any:
    """Pop the :data:`sensor_options` out of a command's keyword arguments: a :class:`occtool.sensor.SensorModel`."""
    from occtool.sensor import SensorModel

    values = {name: kwargs.pop(name) for name in SENSOR_OPTION_NAMES if name in kwargs}
    return SensorModel(**{k: v for k, v in values.items() if v is not None})


def fit_from_kwargs(kwargs: dict[str, Any], *, seed: int = 0) -> Any:
    """Pop the :func:`fit_options` out of a command's keyword arguments: an unfitted
    :class:`occtool.fit.OccupancyRegressor` with its sensor model and robot."""
    from occtool.fit import OccupancyRegressor

    sensor = sensor_from_kwargs(kwargs)
    robot = robot_from_kwargs(kwargs)
    values = {name: kwargs.pop(name) for name in FIT_OPTION_NAMES if name in kwargs}
    return OccupancyRegressor(**{k: v for k, v in values.items() if v is not None}, sensor=sensor, robot=robot, seed=seed)

# --- navigation extraction (owner: navigation) ----------------------------------------

#: Each robot option and the :class:`occtool.robot.Robot` field it sets.
ROBOT_FIELDS = {"robot_radius": "radius", "sensor_height": "sensor_height", "body_height": "body_height",
                "ground_clearance": "ground_clearance"}
ROBOT_OPTION_NAMES = tuple(ROBOT_FIELDS)
EXTRACT_OPTION_NAMES = ("threshold", "heights", "slice_spacing", "max_range", "n_angles", "point_spacing",
                        "return_snap")
#: The library's :data:`occtool.navigation.RETURN_SNAP` (not imported: the CLI starts without numpy).
RETURN_SNAP = LIBRARY_DEFAULTS["return_snap"]


def _positive(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> float | None:
    if value is not None and not (float(value) > 0 and float(value) < float("inf")):
        raise click.BadParameter(f"must be a finite number > 0, got {value}")
    return value


def _occupancy(ctx: click.Context | None, param: click.Parameter | None, value: Any) -> float | None:
    # NaN passes every range comparison: test for the interval itself.
    if value is not None and not 0.0 < float(value) < 1.0:
        raise click.BadParameter(f"an occupancy threshold must lie strictly between 0 and 1, got {value}")
    return value


robot_options = _compose(
    click.option("--robot-radius", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=LIBRARY_DEFAULTS["robot_radius"],
                 show_default=True, help="Robot footprint radius, metres: the navigation polygon is shrunk by it."),
    click.option("--sensor-height", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=LIBRARY_DEFAULTS["sensor_height"],
                 show_default=True, help="Height of the sensor centre above the floor, metres."),
    click.option("--body-height", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=LIBRARY_DEFAULTS["body_height"],
                 show_default=True, help="Height of the top of the robot above the floor, metres."),
    click.option("--ground-clearance", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=LIBRARY_DEFAULTS["ground_clearance"],
                 show_default=True, help="Obstacles lower than this above the floor are driven over, metres."),
)

extract_options = _compose(
    robot_options,
    click.option("--threshold", type=float, default=LIBRARY_DEFAULTS["threshold"], show_default=True, callback=_occupancy,
                 help="Occupancy at or above which space is an obstacle, in (0, 1)."),
    click.option("--heights", callback=float_list, default=None, metavar="H,H,...",
                 help="Sensor-frame heights to cut the model at, metres, comma-separated (floor at "
                      "-SENSOR_HEIGHT; default: spanning the robot body)."),
    click.option("--slice-spacing", type=float, default=None, callback=_positive,
                 help="Largest gap between cuts, metres: cuts are added between the heights so the map "
                      "holds between them (default: from the model's slope bounds)."),
    click.option("--max-range", type=click.FloatRange(min=0, max=MAX_DISTANCE, min_open=True), default=LIBRARY_DEFAULTS["max_range"], show_default=True,
                 callback=_positive,
                 help="Radius of the circle bounding the navigation polygon, metres."),
    click.option("--angles", "n_angles", type=click.IntRange(min=8, max=MAX_ANGLES), default=LIBRARY_DEFAULTS["n_angles"],
                 show_default=True,
                 help="Pan angles swept, evenly spaced."),
    click.option("--point-spacing", type=float, default=None, callback=_positive,
                 help="Arc length between obstacle/exploration points on the max-range circle, metres "
                      "(default: the robot radius, at least a tenth of the max range)."),
    click.option("--return-snap", type=click.FloatRange(min=0, max=MAX_DISTANCE), default=RETURN_SNAP,
                 show_default=True,
                 help="Metres. The model's free space ends a little in front of a wall by design; where it "
                      "ends at most this far in front of the position's own measured returns, the navigation "
                      "polygon is carried on to those returns. Raised: the polygon reaches walls farther "
                      "away from where the model stopped (narrow aisles open up); lowered or 0: the model's "
                      "own, more cautious edge. The polygon keeps a robot radius from every return either way."),
)

geojson_options = _compose(
    click.option("--slices", "include_slices", is_flag=True, default=False,
                 help="Also write the free polygon at each height (kind 'slice')."),
    click.option("--sequence/--collection", default=False, show_default=True,
                 help="Write newline-delimited GeoJSON features instead of one FeatureCollection."),
    click.option("--precision", type=click.IntRange(min=0, max=17), default=None,
                 help="Decimal places of the coordinates (default: full precision)."),
    click.option("--indent", type=click.IntRange(min=0), default=None,
                 help="Indentation of the JSON collection (default: compact)."),
)


def robot_from_kwargs(kwargs: dict[str, Any]) -> Any:
    """Pop the :data:`robot_options` out of a command's keyword arguments: an :class:`occtool.robot.Robot`."""
    from occtool.robot import Robot

    return Robot(**{field: kwargs.pop(name) for name, field in ROBOT_FIELDS.items() if name in kwargs})


def extract_from_kwargs(kwargs: dict[str, Any], *, robot: Any = None) -> dict[str, Any]:
    """Pop the :data:`extract_options` out of a command's keyword arguments.

    Returns the keyword arguments of :func:`occtool.navigation.navigation_map` (``robot``
    included), all but ``inverse_range`` and ``slope_bounds``, which come from the model.
    ``robot``: the robot already built from these options (by :func:`fit_from_kwargs`),
    instead of popping the robot options again.
    """
    options = {name: kwargs.pop(name) for name in EXTRACT_OPTION_NAMES if name in kwargs}
    options["robot"] = robot if robot is not None else robot_from_kwargs(kwargs)
    return options
