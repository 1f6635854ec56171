"""JSON parsing for files a user hands in: integers and nesting bounded.

``json.loads`` turns a 400-digit integer into a Python int that overflows every float
conversion later, and a document nested a thousand deep into a RecursionError. Here both
are :class:`json.JSONDecodeError`, which every reader already reports in one line.
"""

from __future__ import annotations

import json
from typing import Any

#: Longest integer literal accepted: counts, versions and seeds have at most 19 digits.
MAX_INTEGER_DIGITS = 20


def _parse_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INTEGER_DIGITS:
        # JSONDecodeError needs a document and position; the caller adds the file name.
        raise json.JSONDecodeError(f"an integer of {digits} digits ({text[:12]}...) is too long to be a value", text, 0)
    return int(text)


def loads(text: str) -> Any:
    """``json.loads`` with integers of at most :data:`MAX_INTEGER_DIGITS` digits and a
    nesting the parser can follow; both failures are :class:`json.JSONDecodeError`."""
    try:
        return json.loads(text, parse_int=_parse_int)
    except RecursionError:
        raise json.JSONDecodeError("nested too deeply", text, 0) from None
