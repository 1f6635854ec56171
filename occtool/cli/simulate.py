"""``occtool simulate``: a synthetic scene's features (CSV) and truth (JSON)."""

from __future__ import annotations

from pathlib import Path

import click

from occtool.cli.options import LIBRARY_DEFAULTS, config_option, overwrite_option, refuse_existing, seed_option
from occtool.limits import MAX_DISTANCE, MAX_FEATURES, MAX_RANGE_NOISE, MAX_ROBOT_SIZE


def _scene_name(ctx: click.Context, param: click.Parameter, value: str) -> str:
    from occtool.simulate import SCENES

    if value not in SCENES:
        raise click.BadParameter(f"unknown scene {value!r}; choose one of: {', '.join(SCENES)}")
    return value


class _SimulateCommand(click.Command):
    """``simulate``, whose help lists every scene of the catalogue with its description, read
    from :data:`occtool.simulate.SCENES` itself so that the list cannot drift from it."""

    def format_help_text(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        super().format_help_text(ctx, formatter)
        # Imported here, not at the module's top: the catalogue imports numpy and the scene
        # geometry (cold start), and only the help needs it before a scene is built.
        from occtool.simulate import SCENES

        with formatter.section("Scenes (see docs/scenes.md)"):
            formatter.write_dl(list(SCENES.items()))


@click.command("simulate", cls=_SimulateCommand)
@click.argument("scene", callback=_scene_name, metavar="SCENE")
@click.option("-o", "--output", "output", required=True, type=click.Path(file_okay=False),
              help="Folder to write features.csv and truth.json into (created if missing).")
@click.option("--features", type=click.IntRange(min=1, max=MAX_FEATURES), default=10000, show_default=True,
              help="Number of features to register.")
@seed_option
@click.option("--noise", type=click.FloatRange(min=0.0, max=MAX_RANGE_NOISE), default=0.01, show_default=True,
              help="Stereo range noise: sigma = NOISE * r^2 metres at range r.")
@click.option("--outlier-rate", type=click.FloatRange(0.0, 1.0),
              default=0.05, show_default=True, help="Share of features registered at a wrong range along their ray.")
@click.option("--yaw", type=float, default=0.0, show_default=True,
              help="Turn the whole scene (features and truth) by this many radians.")
@click.option("--sensor-height", type=click.FloatRange(min=0.0, max=MAX_ROBOT_SIZE, min_open=True),
              default=LIBRARY_DEFAULTS["sensor_height"], show_default=True,
              help="Height of the camera above the floor, metres.")
@click.option("--body-height", type=click.FloatRange(min=0.0, max=MAX_ROBOT_SIZE, min_open=True),
              default=LIBRARY_DEFAULTS["body_height"], show_default=True,
              help="Height of the robot's top above the floor, metres.")
@click.option("--radius", type=click.FloatRange(min=0.0, max=MAX_ROBOT_SIZE),
              default=LIBRARY_DEFAULTS["robot_radius"], show_default=True,
              help="Robot radius, metres (recorded in the truth).")
@click.option("--ground-clearance", type=click.FloatRange(min=0.0, max=MAX_ROBOT_SIZE),
              default=LIBRARY_DEFAULTS["ground_clearance"], show_default=True,
              help="Obstacles lower than this are driven over, metres.")
@click.option("--sensor-range", type=click.FloatRange(min=0.0, max=MAX_DISTANCE, min_open=True),
              default=6.0, show_default=True, help="Farthest range at which the camera registers features, metres.")
@click.option("--depth-frames", type=click.Choice(["tum", "3dmatch"]), default=None,
              help="Also render the scene as depth images (a 160x120 pinhole camera at the sensor, 8 frames "
                   "45 degrees apart, tilted 25 degrees down) into DIR/depth-tum/ or DIR/depth-3dmatch/.")
@overwrite_option
@config_option
def simulate(scene: str, output: str, features: int, seed: int, noise: float, outlier_rate: float,
             yaw: float, sensor_height: float, body_height: float, radius: float, ground_clearance: float,
             sensor_range: float, depth_frames: str | None, overwrite: bool) -> None:
    """Simulate a pan-tilt stereo camera in SCENE and write DIR/features.csv and DIR/truth.json.

    SCENE is one of the scenes listed below. Features are in the sensor-centred robot
    frame (x forward, y left, z up, metres); the truth holds the scene's obstacles as
    prisms with heights above the floor.
    """
    import logging

    from occtool.robot import Robot
    from occtool.simulate import save_features_csv, simulate_scene

    folder = Path(output)
    features_path, truth_path = folder / "features.csv", folder / "truth.json"
    refuse_existing(overwrite, features_path, truth_path)
    robot = Robot(radius=radius, sensor_height=sensor_height, body_height=body_height,
                  ground_clearance=ground_clearance)
    registered, truth = simulate_scene(scene, n_features=features, seed=seed, range_noise=noise,
                                     outlier_rate=outlier_rate, robot=robot, yaw=yaw, sensor_range=sensor_range)
    folder.mkdir(parents=True, exist_ok=True)
    comments = [
        f"occtool simulate {scene}: {len(registered)} features, seed {seed}, range noise {noise:g}*r^2 m, "
        f"outlier rate {outlier_rate:g}, yaw {yaw:g} rad, sensor range {sensor_range:g} m",
        f"frame base_link: x forward, y left, z up, metres, centred at the sensor {sensor_height:g} m above the floor",
        f"robot: radius {radius:g} m, body height {body_height:g} m, ground clearance {ground_clearance:g} m",
        "truth: truth.json beside this file",
    ]
    truth.save_truth(truth_path)
    save_features_csv(registered, features_path, comments)
    logging.getLogger("occtool.simulate").info("wrote %s and %s", features_path, truth_path)
    if depth_frames:
        from occtool.simulate import render_depth_frames, write_depth_folder

        frames, _ = render_depth_frames(truth, max_range=sensor_range, seed=seed)
        target = write_depth_folder(frames, folder / f"depth-{depth_frames}", layout=depth_frames)
        logging.getLogger("occtool.simulate").info("wrote %d depth frames into %s", len(frames), target)
