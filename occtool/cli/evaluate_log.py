"""``occtool evaluate-log``: the fused map of a log against a dense grid, on held-out scans."""

from __future__ import annotations

from typing import Any

import click

from occtool.cli.options import (
    KEYFRAME_SHARE_HELP,
    config_option,
    fit_options,
    json_option,
    log_options,
    seed_option,
    write_json_report,
)


@click.command(short_help="Score the fused map of a log against a grid on held-out scans.")
@click.argument("log_path", metavar="LOG", type=click.Path(exists=True, dir_okay=False))
@click.option("--holdout", type=click.FloatRange(min=0.0, max=0.5, min_open=True), default=0.1, show_default=True,
              help="Share of scans held out.")
@click.option("--block", type=click.IntRange(min=1), default=40, show_default=True,
              help="Scans are held out in blocks of this many consecutive scans.")
@click.option("--resolution", type=click.FloatRange(min=0.0, min_open=True, max=100.0), default=0.05,
              show_default=True, help="Cell size of the grid and of the map's raster, metres.")
@click.option("--keyframe-share", type=click.FloatRange(min=0.0, max=1.0), default=None,
              help=KEYFRAME_SHARE_HELP + " Default 0.05; 0 fits every training position.")
@json_option("the figures")
@fit_options
@log_options
@seed_option
@config_option
def evaluate_log(log_path: str, holdout: float, block: int, resolution: float, keyframe_share: float | None,
                 json_path: str | None, seed: int, **kwargs: Any) -> None:
    """Hold out --holdout of LOG's scans in blocks of --block consecutive scans, fuse the
    local models of the rest, build a dense 2D log-odds grid (OctoMap's parameters), the
    textbook log-odds grid at 0.05 and 0.1 m (tuned on an inner split of the training
    scans, and with l_occ 0.85, l_free -0.4, clamp [-2, 3.5]), the counting-model grid at
    0.05 and 0.1 m (its prior tuned the same way) and an OctoMap (when
    pyoctomap is installed) from the same scans, and score them on the held-out beams (end
    points occupied, points along each beam up to 0.1 m before its end free): ROC AUC,
    model bytes, build times, and how well the fused map's raster agrees with its
    training scans (Nav2 agreement, per beam and per cell)."""
    import json

    from occtool.cli.options import fit_from_kwargs, pop_log_options
    from occtool.scoring import evaluate_log as score

    template = fit_from_kwargs(kwargs, seed=seed)
    options = pop_log_options(kwargs)
    no_return = options.pop("no_return_range", None)
    result = score(log_path, template, holdout=holdout, block=block, seed=seed, resolution=resolution,
                   no_return_range=no_return, read_options=options, keyframe_share=keyframe_share).as_dict()
    if write_json_report(json_path, json.dumps(result, indent=1)):
        return
    auc = result["auc"]
    click.echo(f"{result['source']}: {result['scans']} scans, {result['held_out_scans']} held out "
               f"in blocks of {block}; {result['occupied_points']} occupied and "
               f"{result['free_points']} free test points")
    for name, value in auc.items():
        click.echo(f"  AUC {name:<24} {value:.4f}")
    click.echo(f"  fused map {result['fused_bytes'] / 1e6:.2f} MB ({result['fused_positions']} keyframes of "
               f"{result['training_positions']} positions, "
               f"fit {result['fit_s']:.1f} s, raster {result['raster_s']:.1f} s); "
               f"grid {result['grid_bytes'] / 1e6:.2f} MB (built in {result['grid_s']:.1f} s); "
               f"test points the fused map covers: {result['coverage']:.1%}")
    if result.get("world_bytes") is not None:
        hits = result["nav2_hits"]
        click.echo(f"  world map (world.occmap) {result['world_bytes'] / 1e3:.1f} KB, {result['world_segments']} wall "
                   f"segments; its Nav2 map: held-out returns on occupied / free / unknown cells "
                   f"{hits['returns_on_occupied']:.1%} / {hits['returns_on_free']:.1%} / "
                   f"{hits['returns_on_unknown']:.1%}, "
                   f"free points on occupied {hits['free_on_occupied']:.1%}, on unknown {hits['free_on_unknown']:.1%}")
    for name, figures in (result["textbook"] or {}).items():
        how = ("tuned on an inner split of the training scans" + (f", {figures['note']}" if figures.get("note") else "")
               if "inner_auc" in figures else "fixed, not tuned")
        setting = (f"prior {figures['prior']:g} pseudo-beams" if "prior" in figures else
                   f"l_occ {figures['l_occ']:g}, l_free {figures['l_free']:g}, clamp "
                   f"[{figures['clamp'][0]:g}, {figures['clamp'][1]:g}]")
        click.echo(f"  {name}: {setting} ({how}); {figures['bytes'] / 1e6:.2f} MB at a byte a cell")
    if result["octomap_bytes"] is not None:
        click.echo(f"  OctoMap {result['octomap_bytes'] / 1e6:.2f} MB at {resolution:g} m "
                   f"(built in {result['octomap_s']:.1f} s)")
    else:
        click.echo(f"  OctoMap: not scored ({result['octomap_note']})")
    for name, label in (("nav2", "fused map's raster"), ("nav2_grid", "grid read as Nav2 reads it")):
        nav2 = result[name]
        click.echo(f"  Nav2 agreement with the training scans, {label}:")
        click.echo(f"    per beam: returns on an occupied cell or neighbour {nav2['returns_on_occupied']:.1%}, "
                   f"beams clear to 0.1 m before the end {nav2['beams_clear']:.1%}; "
                   f"scans with >= 95 % of both: {nav2['scans_both_95']:.1%}")
        click.echo(f"    per cell (OctoMap's map accuracy): end-point cells on occupied (or neighbour) "
                   f"{nav2['endpoint_cells_on_occupied']:.1%}, traversed cells not occupied "
                   f"{nav2['traversed_cells_clear']:.1%}; scans with >= 95 % of both: "
                   f"{nav2['scans_cells_both_95']:.1%}")
