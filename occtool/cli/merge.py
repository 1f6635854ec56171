"""``occtool merge``: several saved world maps (``world.occmap``) fused into one."""

from __future__ import annotations

import math
import os
from typing import Any

import click

from occtool.cli.options import config_option, overwrite_option, refuse_existing


def _pose(text: str) -> tuple[float, float, float]:
    """``X,Y,YAW`` (metres, radians; ``YAW`` may end in ``deg``) as three finite numbers."""
    items = [item.strip() for item in text.split(",")]
    if len(items) != 3:
        raise ValueError(f"expected X,Y,YAW (three numbers), got {text!r}")
    yaw = items[2]
    degrees = yaw.lower().endswith("deg")
    try:
        x, y, angle = float(items[0]), float(items[1]), float(yaw[:-3] if degrees else yaw)
    except ValueError:
        raise ValueError(f"expected X,Y,YAW (three numbers), got {text!r}") from None
    if not all(math.isfinite(v) for v in (x, y, angle)):
        raise ValueError(f"X,Y,YAW must be finite numbers, got {text!r}")
    return x, y, math.radians(angle) if degrees else angle


def _transforms(ctx: click.Context, param: click.Parameter, value: Any) -> tuple[tuple[str, Any], ...]:
    """Each ``--transform FILE X,Y,YAW`` as ``(FILE, (x, y, yaw))``."""
    out = []
    for name, text in value or ():
        try:
            out.append((name, _pose(text)))
        except ValueError as exc:
            raise click.BadParameter(f"{name}: {exc}", ctx=ctx, param=param) from None
    return tuple(out)


def _same(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)


@click.command("merge")
@click.argument("maps", metavar="MAP.occmap...", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="The merged map (an .occmap file, written completely or not at all).")
@click.option("--transform", "transforms", nargs=2, multiple=True, metavar="MAP.occmap X,Y,YAW",
              callback=_transforms,
              help="Place MAP.occmap (one of the inputs) in the merged frame: its point p lands at "
                   "R(YAW) p + (X, Y); metres, YAW in radians counter-clockwise (or degrees as 90deg). "
                   "Repeat for each map to move; the others are already in the merged frame.")
@overwrite_option
@config_option
def merge(maps: tuple[str, ...], output: str, transforms: tuple[tuple[str, Any], ...], overwrite: bool) -> None:
    """Merge the world maps MAP.occmap... (`occtool map` writes DIR/world.occmap; a folder
    stands for its world.occmap) into one:
    each wall once (of segments several maps give, a few centimetres apart, the longest),
    the union of the observed regions and every map's positions. The maps must share the
    robot's body band and settings. The output's bytes do not depend on the order of the
    inputs (docs/map.md, "Merging maps")."""
    import logging

    from occtool.fuse import merge_files

    placed: list[Any] = [None] * len(maps)
    for name, pose in transforms:
        matches = [k for k, path in enumerate(maps) if _same(path, name)]
        if not matches:
            raise click.BadParameter(f"{name} is not one of the maps to merge", param_hint="'--transform'")
        for k in matches:
            if placed[k] is not None:
                raise click.BadParameter(f"{name} is given two transforms", param_hint="'--transform'")
            placed[k] = pose
    refuse_existing(overwrite, output)
    merged = merge_files(list(maps), output, placed, overwrite=overwrite)
    logging.getLogger("occtool.merge").info("%d maps merged into %s: %d wall segments, %d positions, %d bytes",
                                            len(maps), output, len(merged), merged.positions.shape[0],
                                            os.path.getsize(output))
