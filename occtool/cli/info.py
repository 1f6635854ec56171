"""``occtool info``: a readable summary of any file occtool reads or writes: a model or
inverse file, a model set, a world map (``world.occmap``), a Nav2 map folder, a range log."""

from __future__ import annotations

import click

from occtool.cli.options import log_option, read_memory_limit_option


@click.command(short_help="Describe a model, a model set, a world map, a Nav2 map or a range log.")
@click.argument("path", metavar="FILE|FOLDER", type=click.Path(exists=True, dir_okay=True))
@click.option("--pieces/--no-pieces", "show_pieces", default=False, show_default=True,
              help="Model and inverse files: list the coefficients of every piece.")
@log_option("skip_invalid",
            help="Range log: count invalid rows/points in a note instead of stopping at the first.")
@log_option("no_return_range",
            help="Range log: count laser beams that returned nothing as free rays at this range "
                 "(as fit --no-return-range does).")
@read_memory_limit_option
def info(path: str, show_pieces: bool, skip_invalid: bool, no_return_range: float | None,
         memory_limit: str | None) -> None:
    """Summarise FILE or FOLDER: a model or inverse file (pieces, tree, constraints, fit
    error, samples, run), a model set (`occtool fit LOG -o DIR/`: DIR or its index.json), a
    world map (`world.occmap`), a Nav2 map (`map.yaml`, or the folder `occtool map` wrote:
    its map.yaml and world.occmap both), or any range log the readers understand.

    A model's fit error is the RMSE of F against its samples' evidence m (weighted; F is
    not clipped to [0, 1], so samples far past an obstacle weigh in) and the loss the fit
    minimised."""
    from pathlib import Path

    from rich.console import Console

    from occtool.formats.model import read_any

    console = Console()
    target = Path(path)
    if target.is_dir() and (target / "index.json").is_file():
        console.print(_model_set_summary(target))
        return
    if target.is_dir() and (target / "map.yaml").is_file():
        for part in (target / "world.occmap", target / "map.yaml"):
            if part.is_file():
                console.print(_world_map_summary(part) if part.suffix == ".occmap"
                              else _nav2_summary(part, memory_limit))
        return
    if target.name == "index.json":
        console.print(_model_set_summary(target))
        return
    if _is_world_map(target):
        console.print(_world_map_summary(target))
        return
    if target.suffix in (".yaml", ".yml"):
        console.print(_nav2_summary(target, memory_limit))
        return
    found = None if target.is_dir() else read_any(path)
    if found is None:
        from occtool.io import describe_log

        console.print(describe_log(path, skip_invalid=skip_invalid, no_return_range=no_return_range))
        return
    kind, obj = found
    if kind == "model":
        console.print(_model_summary(path, obj, show_pieces))
    else:
        console.print(_inverse_summary(path, obj, show_pieces))


def _pieces_table(tree, title: str):
    from rich.table import Table

    table = Table(title=title, show_lines=False)
    table.add_column("piece", justify="right")
    names = list(tree.pieces()[0])
    for name in names:
        table.add_column(name, justify="right")
    for i, piece in enumerate(tree.pieces()):
        table.add_row(f"p{i}", *(f"{piece[n]:.4g}" for n in names))
    return table


def _model_summary(path: str, model, show_pieces: bool):
    from rich.console import Group
    from rich.table import Table

    tree = model.tree_
    basis = "a1 cos(alpha) + a2 sin(alpha) + b h + c r + d" if tree.basis == "trig" else "a alpha + b h + c r + d"
    table = Table(title=f"occtool model: {path}", show_header=False)
    table.add_column("key", style="bold")
    table.add_column("value")
    table.add_row("pieces", f"{tree.n_pieces} ({basis})")
    table.add_row("tree", f"depth {tree.depth()}: {tree.describe()}")
    table.add_row("constraints", f"c >= {model.c_min:g}, |dF/dalpha| <= {model.a_max:g}, |b| <= {model.b_max:g}")
    table.add_row("slope bounds", ", ".join(f"{k} {v:.4g}" for k, v in model.slope_bounds_.items()))
    table.add_row(
        "fit error", f"RMSE {model.rmse_:.4f}, loss {model.loss_:.5f} ({model.loss} loss), {model.n_sweeps_} sweeps"
    )
    counts = ", ".join(f"{k} {v}" for k, v in model.sample_counts_.items() if v)
    table.add_row("training", f"{model.n_features_} features -> {model.n_samples_} samples ({counts})")
    table.add_row("input sha256", model.features_digest_)
    guard = model.guard_
    table.add_row("return guard", "none (fitted with --no-guard, or an older file)" if guard is None else
                  f"{guard.n_returns_bins} of {guard.bins} pan bins hold returns (evidence >= {guard.level:g}), "
                  f"nearest {float(guard.distance.min()):.3f} m" if guard.n_returns_bins else
                  f"no returns in the body band (of {guard.bins} pan bins)")
    sensor = model.sensor_
    table.add_row("sensor model", f"depth error {sensor.depth_error:g}, near {sensor.near_positions} x r with "
                  f"{sensor.near_values} x m, floor {sensor.floor}, footprint {sensor.footprint_samples}, "
                  f"background {sensor.background_samples}")
    robot = model.robot_
    table.add_row("robot", f"radius {robot.radius:g} m, sensor height {robot.sensor_height:g} m, body height "
                  f"{robot.body_height:g} m, clearance {robot.ground_clearance:g} m")
    run = getattr(model, "run_", {})
    if run:
        table.add_row(
            "run", ", ".join(f"{k} {v}" for k, v in run.items() if k in ("seconds", "date", "occtool_version", "host"))
        )
    return Group(table, _pieces_table(tree, "pieces")) if show_pieces else table


def _inverse_summary(path: str, inverse, show_pieces: bool):
    from rich.console import Group
    from rich.table import Table

    table = Table(title=f"occtool inverse model: {path}", show_header=False)
    table.add_column("key", style="bold")
    table.add_column("value")
    table.add_row("function", "r = F^-1(alpha, h, m)")
    table.add_row("pieces", f"{inverse.n_pieces} ({inverse.basis} basis)")
    table.add_row("tree", f"depth {inverse.depth()}: {inverse.describe()}")
    return Group(table, _pieces_table(inverse, "inverse pieces")) if show_pieces else table


def _key_value_table(title: str):
    from rich.table import Table

    table = Table(title=title, show_header=False)
    table.add_column("key", style="bold")
    table.add_column("value", overflow="fold")
    return table


def _is_world_map(path) -> bool:
    from occtool.formats.occmap import MAGIC

    try:
        with open(path, "rb") as handle:
            return handle.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


def _world_map_summary(path):
    """A world map: what it holds, where, at what precision and in how many bytes."""
    from occtool.formats.occmap import decode, header_version, read_map_bytes
    from occtool.fuse import WorldMap

    data = read_map_bytes(path)  # the file's bytes (one read), then the map built of them
    if header_version(data) in (5, 6):
        return _world_map_3d_summary(path, data)
    arrays = decode(data, str(path))
    world = WorldMap.from_arrays(arrays)
    lower, upper = world.bounds
    size = path.stat().st_size
    table = _key_value_table(f"occtool world map: {path}")
    table.add_row("format", f"occmap version {arrays.version} (this occtool writes version "
                            f"{_occmap_version()}), {size:,} bytes")
    table.add_row("frame", "map: the frame of the log's poses (x, y in metres); heights from the sensor, the "
                           f"body band {world.band[0]:g} to {world.band[1]:g} m")
    table.add_row("extent", f"x {lower[0]:.2f} to {upper[0]:.2f} m, y {lower[1]:.2f} to {upper[1]:.2f} m "
                            f"({upper[0] - lower[0]:.1f} x {upper[1] - lower[1]:.1f} m)")
    trusted = int((world.trust >= 0.5).sum()) if len(world) else 0
    table.add_row("walls", f"{len(world):,} segments (MIN nodes over linear pieces under one MAX), {trusted:,} "
                           f"trusted; stored to {arrays.unit * 1000:g} mm"
                           + (f", lengths to {arrays.half_unit * 2000:g} mm" if arrays.half_unit else ""))
    area = float(world.region.area) if world.region is not None else 0.0
    table.add_row("observed region", f"{area:,.1f} m² where some position observed (unknown elsewhere)")
    positions = 0 if world.positions is None else len(world.positions)
    table.add_row("positions", f"{positions:,} kept (the free level rises away from them)")
    table.add_row("a byte grid at 0.1 m", f"{world.grid_bytes(0.1):,} bytes over the same extent")
    table.add_row("settings", ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                                        for k, v in world.params().items() if k != "band"))
    return table


def _world_map_3d_summary(path, data):
    """A 3D world map (version 5 or 6): its frame, box, cells, patches per level and bytes."""
    import numpy as np

    from occtool.formats.occmap import header_version
    from occtool.formats.occmap3d import FORMAT_VERSION, decode
    from occtool.fuse._world3d import from_arrays

    world = from_arrays(decode(bytes(data), str(path)))
    version = header_version(data)
    lower, upper = world.bounds
    table = _key_value_table(f"occtool world map (3D): {path}")
    table.add_row("format", f"occmap version {version} (3D: this occtool writes version {FORMAT_VERSION} for depth "
                            f"cameras and 3D lidars), {len(data):,} bytes")
    if world.to_map is None:
        frame = "map: the frame of the log's poses (x, y, z in metres)"
    else:
        angle = float(np.degrees(np.arccos(np.clip((np.trace(world.to_map[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))))
        shift = (np.round(world.to_map[:3, 3], 3) + 0.0).tolist()  # + 0.0: no negative zeros
        frame = (f"queries in the frame of the log's poses, moved into the map's frame (levelled on its floor) by "
                 f"the stored transform: {angle:.1f} degrees, shift {shift} m")
    table.add_row("frame", frame)
    extent = upper - lower
    table.add_row("extent", f"x {lower[0]:.2f} to {upper[0]:.2f} m, y {lower[1]:.2f} to {upper[1]:.2f} m, "
                            f"z {lower[2]:.2f} to {upper[2]:.2f} m "
                            f"({extent[0]:.1f} x {extent[1]:.1f} x {extent[2]:.1f} m)")
    levels = ", ".join(f"{len(codes):,} in {world.resolution * (1 << level):g} m cells"
                       for level, codes in enumerate(world.patches) if len(codes))
    table.add_row("surfaces", f"{world.patch_count:,} planar patches (each a MIN over 7 linear pieces, under one "
                              f"MAX): {levels or 'none'}")
    free_size = world.free_box[2]
    graded = (f"occupancy {world.free_table.min():.2f} to {world.free_table.max():.2f}, lower the more rays crossed"
              if world.free_table is not None else f"occupancy {world.free_level:g}")
    table.add_row("free space", f"{world.free_cells:,} cells of {free_size:g} m that training rays crossed "
                                f"({graded}; 0.5 where no ray passed)")
    table.add_row("a byte grid at 0.1 m", f"{world.grid_bytes(0.1):,} bytes for the same known space")
    return table


def _occmap_version() -> int:
    from occtool.formats.occmap import FORMAT_VERSION

    return FORMAT_VERSION


def _nav2_summary(path, memory_limit=None):
    """A Nav2 map as map_server loads it: mode, size, resolution, origin and its cells."""
    import numpy as np

    from occtool.formats.nav2 import read_nav2

    nav2 = read_nav2(path, memory_limit=memory_limit)
    rows, cols = nav2.cells.shape
    table = _key_value_table(f"Nav2 map: {path}")
    table.add_row("image", f"{nav2.image} ({nav2.mode} mode, negate {nav2.negate})")
    table.add_row("size", f"{cols} x {rows} cells at {nav2.resolution:g} m "
                          f"({cols * nav2.resolution:.1f} x {rows * nav2.resolution:.1f} m)")
    x, y, yaw = nav2.origin
    table.add_row("origin", f"x {x:g} m, y {y:g} m, yaw {yaw:g} rad (the bottom-left cell's corner)")
    table.add_row("thresholds", f"occupied >= {nav2.occupied_thresh:g}, free <= {nav2.free_thresh:g}")
    free, occupied, unknown = (int(np.count_nonzero(nav2.cells == v)) for v in (0, 100, -1))
    graded = nav2.cells.size - free - occupied - unknown
    table.add_row("cells", f"{free:,} free, {occupied:,} occupied, {unknown:,} unknown"
                           + (f", {graded:,} graded" if graded else ""))
    return table


def _model_set_summary(path):
    """A model set: its positions, what they were fitted from, and the files."""
    from occtool.modelset import read_model_set

    folder, entries = read_model_set(path)
    table = _key_value_table(f"occtool model set: {folder}")
    table.add_row("models", f"{len(entries):,} positions")
    posed = sum(1 for entry in entries if entry.get("pose") is not None)
    table.add_row("poses", f"{posed:,} of {len(entries):,} in the world frame (occtool extract --world, occtool map)")
    if entries:
        first, last = entries[0]["position"], entries[-1]["position"]
        table.add_row("positions", f"{first} to {last} of the log")
    size = sum((folder / entry["file"]).stat().st_size for entry in entries)
    table.add_row("files", f"{size:,} bytes of model files")
    return table
