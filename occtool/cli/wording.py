"""Library keywords in messages, as the command line spells them.

The library names its own keywords in errors, warnings and notes (``pass
skip_invalid=True to drop bad rows``, ``pick one with position=N``), as rasterio's
library errors do; the command line shows the same messages with its flags (``pass
--skip-invalid``, ``pick one with --position N``). This is the one table between the two.
"""

from __future__ import annotations

import logging
import re

#: Library keyword -> command-line flag.
KEYWORD_FLAGS = {
    "depth_features": "--depth-features",
    "depth_max_range": "--depth-max-range",
    "depth_noise": "--depth-noise",
    "evidence": "--evidence",
    "features": "--features",
    "format": "--format",
    "group_by": "--group-by",
    "memory_limit": "--memory-limit",
    "no_return_range": "--no-return-range",
    "octomap": "--octomap",
    "overwrite": "--overwrite",
    "pieces": "--pieces",
    "position": "--position",
    "resolution": "--resolution",
    "skip_existing": "--skip-existing",
    "skip_invalid": "--skip-invalid",
    "slice_spacing": "--slice-spacing",
    "topics": "--topic",
    "use_intensities": "--intensities",
    "world": "--world",
}

# `name=True` -> flag; `name='value'` or `name=N` / `name=5` -> "flag value"; `name=` -> flag.
_NAMES = "|".join(KEYWORD_FLAGS)
_KEYWORD = re.compile(rf"\b({_NAMES})=(?:(True)\b|'([^']*)'|(N\b|[0-9][0-9.]*))?")


def as_flags(text: str) -> str:
    """``text`` with each library keyword of :data:`KEYWORD_FLAGS` written as its flag."""

    def flag(match: re.Match[str]) -> str:
        value = match.group(3) if match.group(3) is not None else match.group(4)
        return KEYWORD_FLAGS[match.group(1)] + (f" {value}" if value else "")

    return _KEYWORD.sub(flag, text)


class FlagWording(logging.Filter):
    """A logging filter that writes library keywords in log messages as flags."""

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        worded = as_flags(message)
        if worded != message:
            record.msg, record.args = worded, None
        return True
