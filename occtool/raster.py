"""The fused map drawn as a free / occupied / unknown grid (Nav2's trinary pixel values)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool._files import read_at

#: Nav2 pixel values (trinary mode).
FREE, OCCUPIED, UNKNOWN = 254, 0, 205
#: Occupancy at and above which a map's raster cell is occupied (map_server's own
#: ``occupied_thresh``), and at and below which it may be free (the 2D and 3D maps' rules
#: add what else a free cell needs).
RASTER_OCCUPIED, RASTER_FREE = 0.65, 0.35


class PackedFlags:
    """A ``(rows, cols)`` bool array kept as bits, eight cells a byte (:func:`numpy.packbits`
    along each row): a large raster's explored flags (:attr:`Raster.explored`) in an eighth
    of the memory of a bool array.

    Read as numpy reads a bool array: ``flags[low:high]`` (rows, unpacked), ``flags[row, col]``
    (cells), ``numpy.asarray(flags)`` and ``~flags`` (all of it, unpacked); written a band of rows at a time
    (``flags[low:high] = rows``).
    """

    ndim = 2
    dtype = np.dtype(bool)

    def __init__(self, shape: tuple[int, int]) -> None:
        self.shape = (int(shape[0]), int(shape[1]))
        self.bits = np.zeros((self.shape[0], -(-self.shape[1] // 8)), dtype=np.uint8)

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]

    def __len__(self) -> int:
        return self.shape[0]

    def __setitem__(self, rows: slice, values: ArrayLike) -> None:
        if not isinstance(rows, slice):
            raise TypeError("packed flags are written a slice of whole rows at a time")
        self.bits[rows] = np.packbits(np.asarray(values, dtype=bool), axis=1)

    def __getitem__(self, key: object) -> NDArray[np.bool_]:
        if isinstance(key, tuple) and len(key) == 2:
            row, col = key
            if isinstance(row, slice) or isinstance(col, slice):
                return self[row][:, col] if isinstance(row, slice) else self[row][col]
            col = np.asarray(col)
            return ((self.bits[row, col >> 3] >> (7 - (col & 7))) & 1).astype(bool)
        rows = self.bits[key]  # type: ignore[call-overload]
        if rows.ndim == 1:
            return np.unpackbits(rows, count=self.shape[1]).astype(bool)
        return np.unpackbits(rows, axis=1, count=self.shape[1]).astype(bool)

    def __invert__(self) -> NDArray[np.bool_]:
        return ~self[:]

    def __array__(self, dtype: object = None, copy: object = None) -> NDArray[np.bool_]:
        whole = self[:]
        return whole if dtype is None else whole.astype(dtype)  # type: ignore[call-overload]


class SpilledCells:
    """A ``(rows, cols)`` uint8 array kept in an unnamed temporary file instead of memory: a
    large raster's cells (:attr:`Raster.cells`), which a run otherwise holds whole while it
    writes its files (a byte a cell: 0.3 GB for ten campuses at 0.05 m).

    The file holds the rows as a PGM image holds its pixels, the top row (the highest y)
    first, and nothing else; it has no name (``tempfile.TemporaryFile``), so it goes with the
    object or the process, however the process ends. Rows are read and written with
    ``os.pread``/``os.pwrite``, never mapped: what was read is not held in the process.

    Read as numpy reads an array: ``cells[low:high]`` (rows, bottom first as in memory),
    ``cells[row, col]`` (index arrays), ``numpy.asarray(cells)`` and comparisons with a
    number (all of it); written a band of rows at a time (``cells[low:high] = rows``). It
    pickles as the array it holds.
    """

    ndim = 2
    dtype = np.dtype(np.uint8)
    __hash__ = None  # type: ignore[assignment]

    def __init__(self, shape: tuple[int, int], fill: int, folder: str | os.PathLike[str] | None = None) -> None:
        import tempfile

        self.shape = (int(shape[0]), int(shape[1]))
        self._file = tempfile.TemporaryFile(dir=folder)
        row = np.full(self.shape[1], fill, dtype=np.uint8).tobytes()
        step = max(1, (1 << 22) // max(1, self.shape[1]))  # about 4 MB written at a time
        for low in range(0, self.shape[0], step):
            self._file.write(row * min(step, self.shape[0] - low))
        self._file.flush()

    @property
    def size(self) -> int:
        return self.shape[0] * self.shape[1]

    def __len__(self) -> int:
        return self.shape[0]

    def _rows(self, low: int, high: int) -> NDArray[np.uint8]:
        """Rows ``low`` to ``high`` (clipped), bottom first."""
        low, high = max(0, low), min(high, self.shape[0])
        if high <= low:
            return np.zeros((0, self.shape[1]), dtype=np.uint8)
        cols = self.shape[1]
        out = read_at(self._file.fileno(), bytearray((high - low) * cols), (self.shape[0] - high) * cols,
                      "the raster's temporary file")
        return np.frombuffer(out, dtype=np.uint8).reshape(high - low, cols)[::-1].copy()

    def __setitem__(self, rows: slice, values: ArrayLike) -> None:
        low, high, stride = rows.indices(self.shape[0]) if isinstance(rows, slice) else (0, 0, 0)
        if stride != 1:
            raise TypeError("spilled cells are written a slice of whole rows at a time")
        block = np.broadcast_to(np.asarray(values, dtype=np.uint8), (high - low, self.shape[1]))
        os.pwrite(self._file.fileno(), np.ascontiguousarray(block[::-1]).tobytes(),
                  (self.shape[0] - high) * self.shape[1])

    def __getitem__(self, key: object) -> Any:
        if isinstance(key, slice):
            low, high, stride = key.indices(self.shape[0])
            return self._rows(low, high)[::stride] if stride > 0 else self[:][key]
        if isinstance(key, tuple) and len(key) == 2 and not isinstance(key[0], slice):
            # Index arrays: the rows they name, each read once.
            row, col = np.broadcast_arrays(np.asarray(key[0], dtype=np.intp), np.asarray(key[1]))
            row = np.where(row < 0, row + self.shape[0], row)
            out = np.empty(row.shape, dtype=np.uint8)
            if row.size and (row.min() < 0 or row.max() >= self.shape[0]):
                raise IndexError(f"row index out of range for {self.shape[0]} rows")
            for r in np.unique(row).tolist():
                at = row == r
                out[at] = self._rows(r, r + 1)[0][col[at]]
            return out
        if isinstance(key, (int, np.integer)):
            r = int(key) + (self.shape[0] if key < 0 else 0)
            if not 0 <= r < self.shape[0]:
                raise IndexError(f"row {key} out of range for {self.shape[0]} rows")
            return self._rows(r, r + 1)[0]
        return np.asarray(self)[key]  # type: ignore[call-overload]

    def __array__(self, dtype: object = None, copy: object = None) -> NDArray[np.uint8]:
        whole = self._rows(0, self.shape[0])
        return whole if dtype is None else whole.astype(dtype)  # type: ignore[call-overload]

    def __eq__(self, other: object) -> Any:
        return np.asarray(self) == other

    def __ne__(self, other: object) -> Any:
        return np.asarray(self) != other

    def __reduce__(self) -> tuple[Any, ...]:
        return (np.asarray, (np.asarray(self),))


@dataclass
class Raster:
    """A free / occupied / unknown grid in the world (map) frame.

    ``cells`` is ``(ny, nx)`` uint8 with :data:`FREE`, :data:`OCCUPIED`, :data:`UNKNOWN`
    (an array, or a large run's :class:`SpilledCells`, read as one), row 0 at ``origin[1]``
    (the bottom: y grows with the row); cell ``(j, i)`` spans
    ``origin + (i, j) * resolution`` to one resolution more. ``conflict`` marks cells where
    positions contradicted each other (a read-only view of one ``False`` where no cell can:
    it costs no memory); ``probability`` is the fused occupancy (0.5 unknown), ``None``
    when the raster was drawn without it (a large one, whose occupancy as float32 would
    take four times its cells: :meth:`occtool.fuse.WorldMap.rasterise`).
    ``explored`` (``None``: none) marks cells the run observed: an unknown cell there is
    uncertain (a wall's edge), not unexplored, and no frontier; a bool array, or for a world
    map's raster the same flags packed eight a byte (:class:`PackedFlags`, read as one).
    """

    cells: NDArray[np.uint8] | SpilledCells
    resolution: float
    origin: tuple[float, float]
    probability: NDArray[np.float32] | None
    conflict: NDArray[np.bool_]
    explored: NDArray[np.bool_] | PackedFlags | None = field(default=None)

    def graded(self) -> NDArray[np.float32]:
        """The fused occupancy of every cell the run observed (or placed a wall near), NaN
        elsewhere: the cells of a ``scale`` Nav2 map (:func:`occtool.formats.nav2.write_nav2_scale`),
        which keeps the map's grades where the trinary cells round them to three."""
        if self.probability is None:
            from occtool.errors import InputError

            raise InputError("this raster was drawn without its occupancy (occupancy=False): no graded map")
        out = self.probability.astype(np.float32)  # a copy, blanked a strip of rows at a time
        step = max(1, (1 << 20) // max(1, out.shape[1]))
        for low in range(0, out.shape[0], step):
            unknown = self.cells[low:low + step] == UNKNOWN
            if self.explored is not None:
                unknown &= ~self.explored[low:low + step]
            out[low:low + step][unknown] = np.float32(np.nan)
        return out

    def unexplored(self, row: NDArray[np.intp], col: NDArray[np.intp]) -> NDArray[np.bool_]:
        """Whether cells ``(row, col)`` are unknown because nothing observed them."""
        unknown = self.cells[row, col] == UNKNOWN
        return unknown if self.explored is None else unknown & ~self.explored[row, col]

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.cells.shape[0]), int(self.cells.shape[1]))

    def cell_of(self, xy: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        """Row, column and inside-flag of world ``(K, 2)`` points."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        col = np.floor((xy[:, 0] - self.origin[0]) / self.resolution).astype(np.intp)
        row = np.floor((xy[:, 1] - self.origin[1]) / self.resolution).astype(np.intp)
        inside = (row >= 0) & (row < self.shape[0]) & (col >= 0) & (col < self.shape[1])
        return np.clip(row, 0, self.shape[0] - 1), np.clip(col, 0, self.shape[1] - 1), inside

    def counts(self) -> dict[str, int]:
        # A strip of rows at a time: a whole-raster comparison would take a byte a cell.
        counts = {"free": 0, "occupied": 0, "unknown": 0, "conflict": 0}
        step = max(1, (1 << 22) // max(1, self.cells.shape[1]))
        for low in range(0, self.cells.shape[0], step):
            strip = self.cells[low:low + step]
            for name, value in (("free", FREE), ("occupied", OCCUPIED), ("unknown", UNKNOWN)):
                counts[name] += int(np.count_nonzero(strip == value))
            counts["conflict"] += int(np.count_nonzero(self.conflict[low:low + step]))
        return counts
