"""Query points as CSV: ``x,y,z`` rows in, the same rows out with an ``occupancy`` column.

:func:`query_csv` streams the file in chunks of :data:`CHUNK_ROWS` rows (memory does not
grow with its length), asks a map's ``predict`` for each chunk and writes every row back
as it was read (its other columns kept, ``#`` comment and blank lines dropped) with the
occupancy appended, through a temporary file renamed into place.
"""

from __future__ import annotations

import csv
import os
from typing import Any

import numpy as np

from occtool.errors import InputError

#: Rows read, queried and written at a time.
CHUNK_ROWS = 100_000
COLUMN = "occupancy"


def _columns(header: list[str], source: str) -> tuple[int, int, int]:
    names = [h.strip().lower() for h in header]
    missing = [c for c in ("x", "y", "z") if c not in names]
    if missing:
        raise InputError(f"{source}: the header needs columns x, y and z (missing {', '.join(missing)})")
    if COLUMN in names:
        raise InputError(f"{source}: already has an {COLUMN!r} column")
    return names.index("x"), names.index("y"), names.index("z")


def query_csv(world: Any, source: str | os.PathLike[str], output: str | os.PathLike[str], *,
              overwrite: bool = True, precision: int = 4) -> int:
    """Write ``source``'s rows to ``output`` with ``world.predict`` of their ``x, y, z`` appended
    as ``occupancy`` (``precision`` decimals); returns the rows written. ``output`` may be ``"-"``."""
    from occtool._files import atomic_write

    name = str(source)
    try:
        handle = open(source, newline="", encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{name}: cannot read the points: {exc.strerror or exc}") from None
    written = 0
    with handle, atomic_write(output, "w", overwrite=overwrite) as out:
        lines = (line for line in handle if line.strip() and not line.lstrip().startswith("#"))
        reader = csv.reader(lines)
        writer = csv.writer(out, lineterminator="\n")
        try:
            header = next(reader)
        except StopIteration:
            raise InputError(f"{name}: empty file (expected a header with x, y, z)") from None
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{name}: not CSV text ({exc})") from None
        ix, iy, iz = _columns(header, name)
        writer.writerow([*header, COLUMN])
        while True:
            try:
                rows = [row for _, row in zip(range(CHUNK_ROWS), reader)]
            except (csv.Error, UnicodeDecodeError) as exc:
                raise InputError(f"{name}: not CSV text near row {written + 2} ({exc})") from None
            if not rows:
                break
            try:
                xyz = np.array([(row[ix], row[iy], row[iz]) for row in rows], dtype=np.float64)
            except (IndexError, ValueError):
                bad = next(n for n, row in enumerate(rows) if not _numeric(row, (ix, iy, iz)))
                raise InputError(f"{name}: row {written + bad + 2} has no number in x, y or z: "
                                 f"{','.join(rows[bad])[:80]!r}") from None
            if not np.isfinite(xyz).all():
                bad = int(np.flatnonzero(~np.isfinite(xyz).all(axis=1))[0])
                raise InputError(f"{name}: row {written + bad + 2} has a coordinate that is not finite")
            occupancy = world.predict(xyz)
            text = np.char.mod(f"%.{precision}f", occupancy)
            writer.writerows([*row, value] for row, value in zip(rows, text.tolist()))
            written += len(rows)
    return written


def _numeric(row: list[str], columns: tuple[int, ...]) -> bool:
    try:
        for column in columns:
            float(row[column])
    except (IndexError, ValueError):
        return False
    return True


__all__ = ["CHUNK_ROWS", "COLUMN", "query_csv"]
