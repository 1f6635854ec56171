"""tools/pictures.py: every picture in docs/images/ has its commands or a reason, and the
commands are occtool's (parsed, never run: the maps take minutes)."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import click
import pytest

from occtool.cli.main import cli

REPO = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("pictures", REPO / "tools" / "pictures.py")
assert _spec is not None and _spec.loader is not None
pictures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(pictures)


def _command(argv: list[str]) -> tuple[click.Command, click.Context]:
    """The occtool command ARGV names, parsed as click would (files not checked)."""
    # The table's commands start with their (sub)command names and use no group options,
    # so walk the groups by name and parse the rest with the command itself.
    ctx = click.Context(cli, info_name="occtool", resilient_parsing=True)
    cmd: click.Command = cli
    rest = list(argv)
    while isinstance(cmd, click.Group):
        name, rest = rest[0], rest[1:]
        sub = cmd.get_command(ctx, name)
        assert sub is not None, f"no occtool command {name!r} in {argv}"
        ctx = click.Context(sub, info_name=name, parent=ctx, resilient_parsing=True)
        cmd = sub
    return cmd, cmd.make_context(ctx.info_name, rest, parent=ctx.parent, resilient_parsing=True)


def test_every_image_is_drawn_or_explained() -> None:
    images = {p.stem for p in (REPO / "docs" / "images").iterdir() if p.is_file()}
    assert not set(pictures.PICTURES) & set(pictures.NOT_OURS)
    assert images - set(pictures.PICTURES) - set(pictures.NOT_OURS) == set()
    # and the table names no picture the docs no longer have
    assert set(pictures.PICTURES) <= images


@pytest.mark.parametrize("name", sorted(pictures.PICTURES))
def test_commands_parse(name: str) -> None:
    commands = pictures.PICTURES[name]
    for argv in commands:
        cmd, ctx = _command(argv)
        # resilient parsing lets unknown options through: check each against the command's
        known = {o for p in cmd.params for o in (*p.opts, *p.secondary_opts)}
        for arg in argv:
            if arg.startswith("-") and not re.fullmatch(r"-?[\d.]+", arg):
                assert arg in known, f"{name}: {cmd.name} has no option {arg}"
        expanded = pictures.expand(argv)
        assert not any("{" in a for a in expanded), expanded
    # the last command draws the picture into docs/images/NAME.png
    last = commands[-1]
    assert last[0] == "plot"
    assert pictures.expand(last)[last.index("-o") + 1] == str(pictures.IMAGES / f"{name}.png")


def test_list_prints_every_picture_and_runs_nothing() -> None:
    out = subprocess.run([sys.executable, str(REPO / "tools" / "pictures.py"), "--list"],
                         capture_output=True, text=True, check=True, timeout=60).stdout
    for name, commands in pictures.PICTURES.items():
        assert f"{name}.png" in out
        for argv in commands:
            assert pictures.show(argv) in out


def test_readme_commands_match_the_table() -> None:
    """The README's worked examples draw their pictures with the table's options."""
    readme = (REPO / "README.md").read_text()
    for name in ("intel-map", "cabinet-map"):
        plot = pictures.PICTURES[name][-1]
        flags = [a for a in plot if a.startswith("--")]
        line = next(ln for ln in readme.splitlines() if ln.startswith(f"occtool plot map {name}/"))
        assert [a for a in line.split() if a.startswith("--")] == flags
