"""Options shared by several subcommands.

Each ``*_options`` decorator adds a group of options to a command; the matching
``*_from_kwargs`` helper (where there is one) pops those options out of the command's
keyword arguments and builds the library's parameter object, so every command that
fits, extracts or compares reads them the same way.

``--config FILE`` reads defaults for any option from a TOML file: top-level keys or
keys under ``[sensor]``, ``[fit]``, ``[extract]``, ``[log]`` tables, named as the
options are, with dashes or underscores (``depth-error = 0.03``). Options given on the
command line win.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from occtool.limits import (
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


# --- configuration file -------------------------------------------------------------

def _load_config(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    if value is None:
        return None
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    try:
        with open(value, "rb") as handle:
            data = tomllib.load(handle)
    except OSError as exc:
        raise click.BadParameter(f"cannot read {value}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise click.BadParameter(f"{value} is not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise click.BadParameter(f"{value} is not a TOML file: not UTF-8 text") from None
    flat: dict[str, Any] = {}
    for key, item in data.items():
        if isinstance(item, dict):
            for sub_key, sub_item in item.items():
                flat[sub_key.replace("-", "_")] = sub_item
        else:
            flat[key.replace("-", "_")] = item
    known = {p.name for p in ctx.command.params}
    unknown = sorted(set(flat) - known)
    if unknown:
        raise click.BadParameter(f"{value}: unknown settings for `{ctx.info_name}`: {', '.join(unknown)}")
    # Click turns 8.7 into 8 for an integer option: a whole-number setting must be one.
    for option in ctx.command.params:
        setting = flat.get(option.name)
        integer = isinstance(option.type, click.types.IntParamType) or (
            isinstance(option.type, click.IntRange))
        if integer and isinstance(setting, float) and not setting.is_integer():
            raise click.BadParameter(f"{value}: {option.name} must be a whole number, got {setting}")
        if isinstance(setting, bool) and integer:
            raise click.BadParameter(f"{value}: {option.name} must be a whole number, got {setting}")
    ctx.default_map = {**(ctx.default_map or {}), **flat}
    return value


config_option = click.option(
    "--config",
    type=click.Path(dir_okay=False),
    callback=_load_config,
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


jobs_options = _compose(
    click.option("-j", "--jobs", type=int, default=None, callback=_jobs, metavar="N",
                 help="Model sets: positions fitted at once, in local processes [default: the cores]."),
    click.option("--scheduler", default=None, metavar="ADDRESS",
                 help="Model sets: run the positions on the Dask cluster at ADDRESS (tcp://host:8786) "
                      "instead; needs occtool[dask] here and occtool on the workers."),
)

# --- range-log reading (owner: readers) ------------------------------------------------

# occtool.io.read_options' depth defaults, spelled here so that --help imports no numpy
# (tests/test_io_depth.py holds them equal).
DEFAULT_DEPTH_FEATURES = 10_000
DEFAULT_DEPTH_NOISE = 0.0015
DEFAULT_DEPTH_MAX_RANGE = 8.0

LOG_OPTION_NAMES = (
    "format", "topics", "evidence_field", "evidence", "use_intensities", "sensor_frame", "base_frame",
    "position_tolerance", "group_by", "skip_invalid", "no_return_range", "depth_features", "depth_noise",
    "depth_max_range",
)


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
    from occtool.io import check_no_return_range

    try:
        return check_no_return_range(value)
    except InputError as exc:
        raise click.BadParameter(str(exc)) from None


log_options = _compose(
    click.option(
        "--format", "format", type=click.Choice(["csv", "mcap", "carmen", "xyz", "pcd", "ply", "rosbag", "urg", "tum",
                                                 "3dmatch"], case_sensitive=False),
        default=None, help="Log format (default: from the content and extension).",
    ),
    click.option(
        "--topic", "topics", multiple=True,
        help="MCAP or ROS bag topic to read (repeatable; default: the one supported range channel).",
    ),
    click.option(
        "--evidence-field", default="evidence", show_default=True,
        help="Point field or CSV column holding the evidence value (CSV also accepts m).",
    ),
    click.option(
        "--evidence", type=float, default=None, callback=_unit_interval,
        help="Constant evidence for data without an evidence field (laser scans: 0.9 if not given).",
    ),
    click.option(
        "--intensities", "use_intensities", is_flag=True, default=False,
        help="Laser scans: evidence from the intensities, scaled by the scan's largest.",
    ),
    click.option("--sensor-frame", default=None, help="MCAP: frame the points are in (default: the message's)."),
    click.option("--base-frame", default=None, help="MCAP: robot base frame (default: base_link, if in /tf_static)."),
    click.option(
        "--position-tolerance", default="0.25,0.26", show_default=True, callback=_position_tolerance,
        help="Consecutive scans within DIST,ANGLE (metres, radians) of a position's first scan form one position.",
    ),
    click.option(
        "--group-by", type=click.Choice(["position", "message"]), default="position", show_default=True,
        help="Group scans into robot positions, or make each message its own position.",
    ),
    click.option(
        "--skip-invalid", is_flag=True, default=False,
        help="Drop invalid rows/points (NaN, evidence outside [0, 1], unparsable) and report how many.",
    ),
    click.option(
        "--no-return-range", type=float, default=None, callback=no_return_range_callback, metavar="METRES",
        help="Laser scans (CARMEN, LaserScan): keep each beam that returned nothing within range as a "
             "free ray, a feature with evidence 0 at min(METRES, the beam's max range), saying its ray is "
             "free and nothing about an obstacle (default: such beams are dropped; ignored for point clouds "
             "and CSV).",
    ),
    click.option(
        "--depth-features", type=click.IntRange(min=1, max=MAX_FEATURES), default=DEFAULT_DEPTH_FEATURES,
        show_default=True, metavar="N",
        help="Depth images: most features kept of each frame, on a regular pixel grid (keeps each surface's share).",
    ),
    click.option(
        "--depth-noise", type=click.FloatRange(min=0.0, max=1.0), default=DEFAULT_DEPTH_NOISE, show_default=True,
        metavar="K",
        help="Depth images: depth noise sigma = K z^2 metres that gives each pixel its evidence "
             "(0.0015 structured light, about 0.005-0.01 stereo).",
    ),
    click.option(
        "--depth-max-range", type=click.FloatRange(min=0.1, max=MAX_DISTANCE, min_open=True), default=DEFAULT_DEPTH_MAX_RANGE,
        show_default=True, metavar="METRES",
        help="Depth images: farther depths are no returns (dropped, or free rays with --no-return-range).",
    ),
)


def read_log_from_kwargs(path: str, kwargs: dict[str, Any]) -> RangeLog:
    """Pop the :data:`log_options` out of a command's keyword arguments and read the log.

    Returns the :class:`occtool.features.RangeLog`; its notes (skipped rows, missing
    poses) are logged at warning level.
    """
    import logging

    from occtool.io import read_log

    options = {name: kwargs.pop(name) for name in LOG_OPTION_NAMES if name in kwargs}
    if "topics" in options:
        options["topics"] = list(options["topics"]) or None
    if str(path) == "-":
        from occtool.io.stream import read_log_stream

        log = read_log_stream(**options)
    else:
        log = read_log(path, **options)
    logger = logging.getLogger("occtool.io")
    for note in log.notes:
        logger.warning("%s: %s", Path(path).name, note)
    return log

# --- sensor model and fit (owner: core model) -----------------------------------------

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


sensor_options = _compose(
    click.option("--depth-error", type=float, default=None,
                 help="Relative depth error: hit samples at r(1 -+ e) [default: 0.03]."),
    click.option("--near-positions", callback=_pair, default=None,
                 help="Near samples' positions as fractions of the feature's range, 'P1,P2' [default: 0.8,0.9]."),
    click.option("--near-values", callback=_pair, default=None,
                 help="Near samples' values as fractions of the feature's evidence, 'V1,V2' [default: 0.2,0.4]."),
    click.option("--floor", type=click.Choice(["free", "drop", "obstacle"]), default=None,
                 help="Floor features (below the ground clearance): free-space samples only, dropped, "
                      "or obstacles [default: free]."),
    click.option("--footprint-samples", type=click.IntRange(min=0, max=MAX_BODY_SAMPLES), default=None,
                 help="Zero-occupancy samples filling the robot's body [default: 512]."),
    click.option("--background-samples", type=click.IntRange(min=0, max=MAX_BODY_SAMPLES), default=None,
                 help="Zero-occupancy background samples for featureless directions [default: 0]."),
    click.option("--background-weight", type=float, default=None, help="Weight of each background sample [default: 0.05]."),
    click.option("--background-range", type=click.FloatRange(min=0, max=MAX_DISTANCE, min_open=True), default=None,
                 help="Farthest background sample, metres [default: 3]."),
)


def fit_options(function: F) -> F:
    """The fit's options: pieces, basis, constraints, loss, plus the sensor and robot options."""
    options = _compose(
        sensor_options,
        robot_options,
        click.option("-L", "--pieces", type=click.IntRange(min=1, max=MAX_PIECES), default=None,
                     help="Number of linear pieces [default: 64, and beyond 10,000 features a position more, "
                          "up to 128 from 40,000 on]."),
        click.option("--basis", type=click.Choice(["trig", "linear"]), default="trig", show_default=True,
                     help="Pieces a1 cos(alpha) + a2 sin(alpha) + b h + c r + d (seam-free) or the paper's "
                          "a alpha + b h + c r + d."),
        click.option("--c-min", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None, help="Lower bound of the range weight c, per metre [default: 0.25]."),
        click.option("--a-max", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None, help="Bound of |dF/dalpha|, per radian [default: 12]."),
        click.option("--b-max", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None, help="Bound of the height weight |b|, per metre [default: 8]."),
        click.option("--c-max", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None,
                     help="Largest range weight of a centre piece, per metre [default: 8]."),
        click.option("--loss", type=click.Choice(["huber", "squared"]), default="huber", show_default=True,
                     help="Regression loss (Huber is robust to outliers)."),
        click.option("--huber-delta", type=click.FloatRange(min=0, max=MAX_WEIGHT, min_open=True), default=None, help="Huber loss threshold [default: 0.1]."),
        click.option("--groups", type=click.IntRange(min=1), default=None,
                     help="Angular segments of the tree [default: pieces // 4]."),
        click.option("--max-sweeps", type=click.IntRange(min=0, max=MAX_SWEEPS), default=None,
                     help="Least-squares refit sweeps after the construction [default: 0]."),
        click.option("--focus-range", type=click.FloatRange(min=0.0, max=MAX_DISTANCE, min_open=True), default=None, callback=_positive,
                     help="Farthest horizontal distance fitted, metres; scale it with the maps' "
                          "--max-range (about 2.5x) [default: 4]."),
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

ROBOT_OPTION_NAMES = ("robot_radius", "sensor_height", "body_height", "ground_clearance")
EXTRACT_OPTION_NAMES = ("threshold", "heights", "slice_spacing", "max_range", "n_angles", "point_spacing",
                        "return_snap")
#: The library's :data:`occtool.navigation.RETURN_SNAP` (not imported: the CLI starts without numpy).
RETURN_SNAP = 0.5


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
    click.option("--robot-radius", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=0.25, show_default=True,
                 help="Robot footprint radius, metres: the navigation polygon is shrunk by it."),
    click.option("--sensor-height", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=1.0, show_default=True,
                 help="Height of the sensor centre above the floor, metres."),
    click.option("--body-height", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=1.0, show_default=True,
                 help="Height of the top of the robot above the floor, metres."),
    click.option("--ground-clearance", type=click.FloatRange(min=0, max=MAX_ROBOT_SIZE), default=0.05, show_default=True,
                 help="Obstacles lower than this above the floor are driven over, metres."),
)

extract_options = _compose(
    robot_options,
    click.option("--threshold", type=float, default=0.6, show_default=True, callback=_occupancy,
                 help="Occupancy at or above which space is an obstacle, in (0, 1)."),
    click.option("--heights", callback=float_list, default=None, metavar="H,H,...",
                 help="Sensor-frame heights to cut the model at, metres, comma-separated (floor at "
                      "-SENSOR_HEIGHT; default: spanning the robot body)."),
    click.option("--slice-spacing", type=float, default=None, callback=_positive,
                 help="Largest gap between cuts, metres: cuts are added between the heights so the map "
                      "holds between them (default: from the model's slope bounds)."),
    click.option("--max-range", type=click.FloatRange(min=0, max=MAX_DISTANCE, min_open=True), default=1.5, show_default=True, callback=_positive,
                 help="Radius of the circle bounding the navigation polygon, metres."),
    click.option("--angles", "n_angles", type=click.IntRange(min=8, max=MAX_ANGLES), default=360, show_default=True,
                 help="Pan angles swept, evenly spaced."),
    click.option("--point-spacing", type=float, default=None, callback=_positive,
                 help="Arc length between obstacle/exploration points on the max-range circle, metres "
                      "(default: the robot radius, at least a tenth of the max range)."),
    click.option("--return-snap", type=click.FloatRange(min=0, max=MAX_DISTANCE), default=RETURN_SNAP,
                 show_default=True,
                 help="A ray whose model crossing stops at most this far (metres) in front of the model's "
                      "guarded returns is carried on to them, where the surface was measured; 0: the "
                      "model's crossing."),
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

    values = {name: kwargs.pop(name) for name in ROBOT_OPTION_NAMES if name in kwargs}
    if "robot_radius" in values:
        values["radius"] = values.pop("robot_radius")
    return Robot(**values)


def extract_from_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Pop the :data:`extract_options` out of a command's keyword arguments.

    Returns the keyword arguments of :func:`occtool.navigation.navigation_map` (``robot``
    included), all but ``inverse_range`` and ``slope_bounds``, which come from the model.
    """
    options = {name: kwargs.pop(name) for name in EXTRACT_OPTION_NAMES if name in kwargs}
    options["robot"] = robot_from_kwargs(kwargs)
    return options
