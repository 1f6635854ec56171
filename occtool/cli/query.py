"""``occtool query``: occupancy of points in a saved world map."""

from __future__ import annotations

import click

from occtool.cli.options import config_option, overwrite_option, refuse_existing


@click.command("query")
@click.argument("world_map", metavar="MAP.occmap", type=click.Path(exists=True, dir_okay=False))
@click.argument("points", metavar="POINTS.csv", type=click.Path(exists=True, dir_okay=False, allow_dash=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, allow_dash=True),
              help="Output CSV (- for standard output): the rows of POINTS.csv with an occupancy column.")
@click.option("--precision", type=click.IntRange(min=0, max=17), default=4, show_default=True,
              help="Decimal places of the occupancy.")
@overwrite_option
@config_option
def query(world_map: str, points: str, output: str, precision: int, overwrite: bool) -> None:
    """Occupancy at the x, y, z rows of POINTS.csv (the frame of the log's poses, metres) in
    MAP.occmap, the world map `occtool map` writes: each row is written back with an
    `occupancy` column in [0, 1], 0.5 where nothing was observed. A 3D map (from a depth
    camera or a 3D lidar) answers in all of x, y, z; a 2D map (a 2D laser) answers in the
    robot's body band, z the height above the floor, and 0.5 outside it."""
    import logging

    from occtool.formats.query_csv import query_csv
    from occtool.fuse import load_map

    refuse_existing(overwrite, output)
    world = load_map(world_map)
    rows = query_csv(world, points, output, overwrite=overwrite, precision=precision)
    parts = "surface patches" if hasattr(world, "patch_count") else "wall segments"
    logging.getLogger("occtool.query").info("%d points queried in %s (%d %s)", rows, world_map, len(world), parts)
