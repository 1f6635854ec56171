"""``--config FILE``: defaults for a command's options from a TOML file, checked as the flags are.

Keys are spelled as the flags without their dashes (``topic`` for ``--topic``, ``no-path``
for ``--path/--no-path``'s off switch) or as the parameter's name (``topics``), with
dashes or underscores alike, at the top level or in one level of tables (``[sensor]``,
``[fit]``, ``[extract]``, ``[log]``). Each value passes the option's own click type and
callback before it becomes the command's default; what TOML can say and a command line
cannot (a boolean for a number, a number for a switch, a list for an option given once,
a date, a table in a table) is refused. Every refusal is one line naming the file and the
key. Options given on the command line win.
"""

from __future__ import annotations

import datetime
import sys
from collections.abc import Callable
from typing import Any, NoReturn

import click

#: Callbacks that read a comma-separated list of numbers (``--near-positions 0.7,0.85``):
#: a TOML list is written out for them as the command line spells it. Filled by
#: :mod:`occtool.cli.options`, which defines them.
COMMA_LISTS: set[Callable[..., Any]] = set()

#: Largest ``--config`` file read (a settings file is a few hundred bytes).
MAX_CONFIG_BYTES = 1 << 20


def _config_key(name: str) -> str:
    return name.strip().lstrip("-").replace("-", "_")


def _config_names(command: click.Command) -> dict[str, tuple[click.Parameter, bool]]:
    """Each spelling a config key may take -> (its parameter, whether it negates a flag).

    A key is the option's flag without its dashes (``topic`` for ``--topic``, ``path`` for
    ``--path/--no-path``, ``no_path`` for its off switch) or the parameter's name
    (``topics``, ``draw_path``); dashes and underscores are alike. A flag's own spelling
    wins over another parameter's name.
    """
    names: dict[str, tuple[click.Parameter, bool]] = {}
    params = [p for p in command.params if p.expose_value and p.name]
    for param in params:
        names[_config_key(str(param.name))] = (param, False)
    for param in params:
        if isinstance(param, click.Option):
            for flag in param.opts:
                if flag.startswith("--"):
                    names[_config_key(flag)] = (param, False)
            for flag in param.secondary_opts:
                if flag.startswith("--"):
                    names[_config_key(flag)] = (param, True)
    return names


def _flag_of(param: click.Parameter) -> str:
    """The option as the command line spells it (``--topic``), or an argument's name."""
    if isinstance(param, click.Option):
        long = [flag for flag in param.opts if flag.startswith("--")]
        return (long or param.opts)[0]
    return str(param.name).upper()


def _scalar(value: Any) -> bool:
    return isinstance(value, (str, int, float))  # bool is an int


def _config_value(ctx: click.Context, param: click.Parameter, negated: bool, value: Any,
                  refuse: Callable[[str], NoReturn]) -> Any:
    """The value of one setting as the default click will read, checked as click checks the flag.

    TOML gives typed values where the command line gives text: a boolean only for a flag,
    a list only for an option given several times (or a comma-separated list of numbers),
    no dates, times or tables; the value then passes the parameter's own type and callback.
    """
    flag = _flag_of(param)
    if isinstance(value, (datetime.date, datetime.time)):
        refuse(f"a date or time is no value for {flag}")
    if isinstance(value, dict):
        refuse(f"a table is no value for {flag}")
    is_flag = isinstance(param, click.Option) and param.is_flag
    if is_flag or isinstance(param.type, click.types.BoolParamType):
        if not isinstance(value, bool):
            refuse(f"{flag} is a switch: give true or false, got {value!r}")
        return (not value) if negated else value
    if isinstance(value, bool):
        integer = isinstance(param.type, (click.types.IntParamType, click.IntRange))
        refuse(f"{flag} must be {'a whole number' if integer else 'a value'}, not {str(value).lower()}")
    many = param.multiple or param.nargs != 1
    if isinstance(value, list):
        if any(not _scalar(item) or isinstance(item, bool) for item in value):
            refuse(f"{flag} takes a list of plain values, not nested lists, tables, dates or true/false")
        if param.callback in COMMA_LISTS:
            # A comma-separated option: the list written as the command line spells it.
            return ",".join(repr(item) if isinstance(item, float) else str(item) for item in value)
        if not many:
            refuse(f"{flag} takes one value, not a list (lists are for options given several times)")
    elif param.multiple:
        value = [value]  # one value of a repeatable option
    if isinstance(value, float) and isinstance(param.type, (click.types.IntParamType, click.IntRange)) \
            and not value.is_integer():
        refuse(f"{flag} must be a whole number, got {value}")  # click would truncate 8.7 to 8
    try:
        converted = param.type_cast_value(ctx, value)
        if param.callback is not None:
            param.callback(ctx, param, converted)
    except click.BadParameter as exc:
        refuse(f"{flag}: {exc.message}")
    except (TypeError, ValueError, OverflowError) as exc:
        refuse(f"{flag}: {value!r} is not a valid value ({exc})")
    return value


def load_config(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    if value is None:
        return None
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    try:
        with open(value, "rb") as handle:
            content = handle.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise click.BadParameter(f"cannot read {value}: {exc.strerror}") from None
    if len(content) > MAX_CONFIG_BYTES:
        raise click.BadParameter(f"{value}: a settings file larger than {MAX_CONFIG_BYTES >> 20} MB")
    try:
        data = tomllib.loads(content.decode("utf-8"))
    except UnicodeDecodeError:
        raise click.BadParameter(f"{value} is not a TOML file: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise click.BadParameter(f"{value} is not valid TOML: {exc}") from None
    except RecursionError:
        raise click.BadParameter(f"{value}: arrays or tables nested too deeply") from None

    def refuse(key: str) -> Callable[[str], NoReturn]:
        def fail(message: str) -> NoReturn:
            raise click.BadParameter(f"{value}: {key}: {message}")
        return fail

    names = _config_names(ctx.command)
    settings: dict[str, tuple[click.Parameter, bool, Any]] = {}
    unknown: list[str] = []
    for key, item in data.items():
        # Top-level keys, or keys of one level of tables ([sensor], [fit], [extract], [log]).
        entries = [(f"[{key}] {sub}", sub, sub_item) for sub, sub_item in item.items()] \
            if isinstance(item, dict) else [(key, key, item)]
        for where, name, setting in entries:
            if isinstance(setting, dict):
                refuse(where)(f"a table inside [{key}]: settings sit at the top or in one level of tables")
            found = names.get(_config_key(name))
            if found is None:
                unknown.append(name)
                continue
            target, negated = found
            if target.name in settings:
                refuse(where)(f"{_flag_of(target)} is set twice")
            settings[str(target.name)] = (target, negated, _config_value(ctx, target, negated, setting,
                                                                          refuse(where)))
    if unknown:
        raise click.BadParameter(f"{value}: unknown settings for `{ctx.info_name}`: {', '.join(sorted(unknown))}")
    flat = {name: setting for name, (_, _, setting) in settings.items()}
    ctx.default_map = {**(ctx.default_map or {}), **flat}
    return value


__all__ = ["COMMA_LISTS", "MAX_CONFIG_BYTES", "load_config"]
