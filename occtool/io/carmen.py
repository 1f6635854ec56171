"""Read CARMEN laser logs (the classic 2D data sets: Intel lab, Freiburg 079, ACES, ...).

One record per line, whitespace-separated, optionally gzip-compressed
(``../shared/data/CARMEN_FORMAT.md``)::

    FLASER N r_0 ... r_{N-1} x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
    RLASER (the same, for a rear laser)
    ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode
                N r_0 ... r_{N-1} M v_0 ... v_{M-1} laser_x laser_y laser_theta robot_x robot_y robot_theta
                tv rv forward_safety side_safety turn_axis ipc_timestamp host logger_timestamp

Other records (``ODOM``, ``PARAM``, ``NEFF``, ``SYNC``, ``TRUEPOS``, comments) are
skipped: only scans carry the (corrected) laser pose.

Beam angles for ``FLASER``/``RLASER``: ``-pi/2 + i * delta`` with ``delta = pi / N``
for even ``N`` (180 or 360 beams covering -90..+89(.5) degrees) and
``pi / (N - 1)`` for odd ``N`` (361 beams covering -90..+90 degrees). Every reading
becomes a point in the scan plane (``z = 0``) of the laser pose, with constant
evidence.

Max-range readings mean "no return", not obstacles. Each laser of a log (``FLASER``,
``RLASER``, ``ROBOTLASER1``) logs them as codes near its largest reading, and they are told
per laser (:func:`no_return_limit`): readings that repeat (at least 10 times, or twice and
in 1 % of the readings) within 2 % of the laser's largest are its codes, as SICK's 81.83 and
81.91 m on the Freiburg campus, or a cluster of them a few centimetres apart, as the MIT
infinite corridor's 51.05-51.12 m; readings at or above the lowest code, less the codes'
spread, are no returns. ``no_return_code`` sets the limit when the log does not say.
+inf is no return too. No-return readings are dropped with readings <= 0 and NaN, or with
``no_return_range`` R kept as *free rays*: a feature along the beam at ``min(R, max
range)`` with evidence 0, which says the ray is free up to there and nothing about an
obstacle.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Note, Pose, RangeLog
from occtool.io.csv import open_text
from occtool.io.positions import Scan, check_pose, group_scans
from occtool.io.read_options import ReadOptions, as_read_options, options_as_keywords

#: A reading near a laser's largest is one of its no-return codes when it occurs this often
#: (or, in short logs, at least twice and in 1 % of the readings).
SENTINEL_MIN_COUNT = 10
#: ... and within this share of the laser's largest reading.
CODE_BAND = 0.02
#: Readings of the lines :class:`CarmenScans` keeps from its first reading, at most (``keep``;
#: a campus log's 725k readings and their angles take 12 MB).
KEPT_READINGS = 1 << 22
LASER_RECORDS = ("FLASER", "RLASER", "ROBOTLASER1")
OTHER_RECORDS = ("ODOM", "PARAM", "NEFF", "SYNC", "TRUEPOS", "RAWLASER1", "RAWLASER2", "RAWLASER3", "RAWLASER4",
                 "ROBOTLASER2", "GPSNMEA", "GPSGGA", "GPSRMC", "SONAR", "BUMPER", "SCANMARK", "POSITIONLASER")


def _beam_angles(count: int) -> NDArray[np.float64]:
    delta = np.pi / (count - 1) if count % 2 == 1 and count > 1 else np.pi / max(count, 1)
    return -np.pi / 2 + delta * np.arange(count)  # type: ignore[return-value]  # float64 at run time


class _Problem(Exception):
    pass


def _parse_laser(
    fields: list[str],
) -> tuple[NDArray[np.float64], NDArray[np.float64], Pose, float | None, float | None]:
    """Ranges, beam angles, laser pose, stamp and the record's own max range (ROBOTLASER1) of one laser line."""
    kind = fields[0]
    try:
        if kind in ("FLASER", "RLASER"):
            count = int(fields[1])
            if count < 1:
                raise _Problem(f"{kind} with {count} readings")
            if len(fields) < 2 + count + 6:
                raise _Problem(f"{kind} announces {count} readings but has only {len(fields) - 2} more fields")
            ranges = np.array(fields[2 : 2 + count], dtype=np.float64)
            x, y, theta = (float(v) for v in fields[2 + count : 5 + count])
            angles = _beam_angles(count)
            if kind == "RLASER":
                angles = angles + np.pi
            stamp_index = 2 + count + 6
            line_max = None
        else:  # ROBOTLASER1
            start, _fov, resolution = float(fields[2]), float(fields[3]), float(fields[4])
            line_max = float(fields[5])
            if not (np.isfinite(line_max) and line_max > 0.0):
                line_max = None  # no usable max range on the line
            count = int(fields[8])
            ranges = np.array(fields[9 : 9 + count], dtype=np.float64)
            remissions = int(fields[9 + count])
            base = 10 + count + remissions
            if len(fields) < base + 6:
                raise _Problem(f"ROBOTLASER1 announces {count} readings and {remissions} remissions but is too short")
            x, y, theta = (float(v) for v in fields[base : base + 3])
            if not (abs(start) <= 2.0 * np.pi and abs(resolution) <= 2.0 * np.pi):
                # A NaN or absurd angle would put every beam nowhere (or at the sensor origin).
                raise _Problem(f"ROBOTLASER1 start angle {start:g} and angular resolution {resolution:g} must be "
                               "finite angles of at most 2 pi radians")
            angles = start + resolution * np.arange(count)  # type: ignore[assignment]  # float64 at run time
            stamp_index = base + 11
        stamp = float(fields[stamp_index]) if len(fields) > stamp_index else None
    except (ValueError, IndexError) as exc:
        if isinstance(exc, _Problem):
            raise
        raise _Problem(f"{kind} record has a field that is not a number ({exc})") from None
    try:
        check_pose(f"{kind}", (x, y, 0.0), yaw=theta)
    except InputError as exc:
        raise _Problem(str(exc)) from None
    return ranges, angles, Pose(x, y, 0.0, theta), stamp, line_max


def read_carmen(
    path: str | os.PathLike[str],
    options: ReadOptions | None = None,
    **keywords: Any,
) -> RangeLog:
    """Read the laser scans of a CARMEN log into positions of features.

    Parameters
    ----------
    path
        ``.log`` or ``.log.gz`` file.
    options, **keywords
        The reading options (:class:`~occtool.io.ReadOptions`, or its fields by name). A
        CARMEN log uses ``evidence`` (given to every reading: a 2D laser reports none;
        :data:`~occtool.io.read_options.DEFAULT_CONSTANT_EVIDENCE` by default),
        ``position_tolerance``, ``group_by``, ``skip_invalid`` (skip laser lines that do
        not parse), ``no_return_range`` (below) and ``no_return_code`` (readings at or
        above it are no return; by default each laser's codes, see the module notes).

    Notes
    -----
    ``no_return_range`` ``None`` (default): no-return readings are dropped. A positive
    number R: each no-return reading becomes a *free ray*, a feature along its beam at
    ``min(R, max range)`` (the line's own max range for ``ROBOTLASER1``, else
    the laser's no-return limit) with evidence 0: its ray is free up to there,
    and it says nothing about an obstacle. Readings <= 0 or NaN are dropped either way.

    Raises
    ------
    InputError
        For a laser line that does not parse (naming it) or a log without scans.
    """
    settings = as_read_options(options, **keywords)
    scans = CarmenScans(path, settings, keep=True)
    positions = list(group_scans(scans, source=scans.name, tolerance=settings.position_tolerance,
                                 group_by=settings.group_by, notes=scans.notes))
    return RangeLog(positions=positions, source=scans.name, notes=scans.notes)


def no_return_limit(values: NDArray[np.float64], counts: NDArray[np.int64],
                    readings: int) -> tuple[float | None, list[float]]:
    """The no-return limit of one laser, and the codes that set it.

    ``values`` are the laser's distinct readings within :data:`CODE_BAND` of its largest
    (ascending, the largest last), ``counts`` how often each occurs, ``readings`` how many
    finite readings it logged. A code is a value that repeats (:data:`SENTINEL_MIN_COUNT`
    times, or twice and in 1 % of the readings); readings at or above the lowest code less
    the codes' spread are no returns, so a lone code is its own limit and a cluster's stray
    readings (the infinite corridor's 51.01 and 51.16 m round 51.05-51.12 m) go with it.
    ``(None, [])`` when no value repeats: the laser logged no code.

    >>> no_return_limit(np.array([49.9, 50.0]), np.array([1, 620]), 79_200)
    (50.0, [50.0])
    >>> no_return_limit(np.array([51.01, 51.05, 51.06, 51.11, 51.16]), np.array([3, 218, 3720, 466, 2]), 349_380)
    (50.99, [51.05, 51.06, 51.11])
    """
    if readings == 0 or values.size == 0:
        return None, []
    near = values >= values[-1] * (1.0 - CODE_BAND)
    repeated = (counts >= SENTINEL_MIN_COUNT) | ((counts >= 2) & (counts >= 0.01 * readings))
    codes = values[near & repeated]
    if codes.size == 0:
        return None, []
    return round(float(2 * codes[0] - codes[-1]), 6), codes.tolist()


class _TopReadings:
    """One laser's largest readings, gathered line by line: the distinct values within
    :data:`CODE_BAND` of the largest so far, with their counts (a few dozen values)."""

    def __init__(self) -> None:
        self.top = -np.inf
        self.counts: dict[float, int] = {}
        self.readings = 0

    def add(self, finite: NDArray[np.float64]) -> None:
        self.readings += finite.size
        high = float(finite.max())
        if high > self.top:
            self.top = high
            floor = high * (1.0 - CODE_BAND)
            self.counts = {value: count for value, count in self.counts.items() if value >= floor}
        values, counts = np.unique(finite[finite >= self.top * (1.0 - CODE_BAND)], return_counts=True)
        for value, count in zip(values.tolist(), counts.tolist()):
            self.counts[value] = self.counts.get(value, 0) + count

    def limit(self) -> tuple[float | None, list[float]]:
        values = np.array(sorted(self.counts), dtype=np.float64)
        return no_return_limit(values, np.array([self.counts[v] for v in values.tolist()], dtype=np.int64),
                               self.readings)


class CarmenScans:
    """The laser scans of a CARMEN log, read line by line: an iterable of
    :class:`~occtool.io.positions.Scan` that holds one line at a time.

    Each iteration reads the file again. Without ``no_return_code`` each laser's
    no-return codes are its repeated largest readings, which only the whole file tells:
    the first iteration reads every laser line once before yielding anything (keeping only
    each laser's largest readings and their counts), so a line that does not parse is an
    :class:`InputError` before the first scan, wherever it lies. ``notes`` is complete
    after a full iteration. Parameters are those of :func:`read_carmen`; ``keep``: the
    lines that first reading parsed are kept (up to :data:`KEPT_READINGS` readings) for the
    first iteration, not parsed again (:func:`read_carmen`, which holds the whole log anyway).
    """

    def __init__(self, path: str | os.PathLike[str], options: ReadOptions | None = None, *, keep: bool = False,
                 **keywords: Any) -> None:
        self.settings = as_read_options(options, **keywords)
        self.keep = keep
        self._kept: list[Any] | None = None  # the limits' reading's parsed lines (keep)
        self.path = path
        self.name = str(path)
        self.evidence = self.settings.constant_evidence
        self.skip_invalid = self.settings.skip_invalid
        self.no_return_range = self.settings.no_return_range
        self.notes: list[str] = []
        self._limits: dict[str, tuple[float | None, list[float]]] | None = None  # per laser, once read

    def _lines(self) -> Iterator[tuple[str, NDArray[np.float64], NDArray[np.float64], Pose, float | None,
                                       float | None, int]]:
        """Every laser line, parsed; counts the skipped lines and unknown records as it goes."""
        self.skipped_lines = 0
        self.unknown: set[str] = set()
        found = False
        try:
            with open_text(self.path) as handle:
                for line_number, line in enumerate(handle, start=1):
                    fields = line.split()
                    if not fields or fields[0].startswith("#"):
                        continue
                    if fields[0] not in LASER_RECORDS:
                        if fields[0] not in OTHER_RECORDS:
                            self.unknown.add(fields[0][:20])
                        continue
                    try:
                        ranges, angles, pose, stamp, line_max = _parse_laser(fields)
                    except _Problem as problem:
                        if not self.skip_invalid:
                            raise InputError(f"{self.name}, line {line_number}: {problem}") from None
                        self.skipped_lines += 1
                        continue
                    found = True
                    yield fields[0], ranges, angles, pose, stamp, line_max, line_number
        except (OSError, EOFError) as exc:
            if isinstance(exc, FileNotFoundError):
                raise
            raise InputError(f"{self.name}: cannot read the log ({exc})") from None
        if not found:
            raise InputError(f"{self.name} holds no laser scans (FLASER, RLASER or ROBOTLASER1 lines)")

    def limits(self) -> dict[str, tuple[float | None, list[float]]]:
        """Each laser's (record type's) no-return limit and the codes that set it: readings at
        or above the limit are no return (``None``: the laser logged no code). With
        ``no_return_code`` every laser's limit is that; else read from the file once, then kept."""
        if self.settings.no_return_code is not None:
            return {kind: (self.settings.no_return_code, []) for kind in LASER_RECORDS}
        if self._limits is None:
            top = {kind: _TopReadings() for kind in LASER_RECORDS}
            kept: list[Any] | None = [] if self.keep else None
            kept_readings = 0
            for line in self._lines():
                kind, ranges = line[0], line[1]
                finite = ranges[np.isfinite(ranges)]
                if finite.size:
                    top[kind].add(finite)
                if kept is not None:
                    kept_readings += ranges.size
                    kept = kept if kept_readings <= KEPT_READINGS else None
                    if kept is not None:
                        kept.append(line)
            self._limits = {kind: readings.limit() for kind, readings in top.items()}
            self._kept = kept
        return self._limits

    def __iter__(self) -> Iterator[Scan]:
        limits = self.limits()
        evidence, no_return_range, name = self.evidence, self.no_return_range, self.name
        self.notes.clear()
        readings = 0
        no_return = dict.fromkeys(LASER_RECORDS, 0)
        invalid = 0
        reach_low, reach_high = np.inf, -np.inf  # of every free ray
        # The lines the limits' reading kept (parsed once: a third of a campus log's reading), once.
        lines, self._kept = (self._lines() if self._kept is None else iter(self._kept)), None
        for kind, ranges, angles, pose, stamp, line_max, line_number in lines:
            readings += ranges.size
            limit = limits[kind][0]
            with np.errstate(invalid="ignore"):
                # +inf is a no-return reading too (as in ROS's REP 117); NaN, -inf and <= 0 are not readings.
                missing = np.isposinf(ranges) | (ranges >= limit if limit is not None else False)
                valid = np.isfinite(ranges) & (ranges > 0.0) & ~missing
            if no_return_range is None:
                no_return[kind] += int(ranges.size - valid.sum())
                r, a = ranges[valid], angles[valid]
                values = np.full(r.size, evidence)
            else:
                no_return[kind] += int(missing.sum())
                invalid += int(ranges.size - valid.sum() - missing.sum())
                # A free ray out to min(R, the beam's max range): the line's own (ROBOTLASER1),
                # else the laser's limit; the features stay in beam order.
                reach = min(no_return_range, line_max if line_max is not None else np.inf,
                            limit if limit is not None else np.inf)
                kept = valid | missing
                r = np.where(missing, reach, ranges)[kept]
                a = angles[kept]
                values = np.where(missing, 0.0, evidence)[kept]
                if missing.any():
                    reach_low, reach_high = min(reach_low, reach), max(reach_high, reach)
            points = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros(r.size)])
            yield Scan(points, values, pose, stamp, f"{name}:{line_number}")
        self.notes.extend(self._notes(limits, readings, no_return, invalid, reach_low, reach_high))

    def _where(self, limits: dict[str, tuple[float | None, list[float]]], no_return: dict[str, int]) -> str:
        """Which readings were no return, for the notes: each laser's limit and codes."""
        told = []
        several = sum(1 for count in no_return.values() if count) > 1
        for kind in LASER_RECORDS:
            limit, codes = limits[kind]
            if limit is None or not no_return[kind]:
                continue
            if len(codes) > 1:
                what = f"readings >= {limit:g} m: the laser's codes {codes[0]:g} to {codes[-1]:g} m"
            elif self.settings.no_return_code is not None:
                what = f"readings >= {limit:g} m, no_return_code"
            else:
                what = f"readings >= {limit:g} m"
            told.append(f"{kind} {what}" if several else what)
        return f" ({'; '.join(told)})" if told else ""

    def _notes(self, limits: dict[str, tuple[float | None, list[float]]], readings: int, no_return: dict[str, int],
               invalid: int, reach_low: float, reach_high: float) -> list[str]:
        notes = []
        where = self._where(limits, no_return)
        total = sum(no_return.values())
        if self.no_return_range is None:
            if total:
                notes.append(f"dropped {total} of {readings} readings as no return{where}")
        else:
            if total:
                where = where or " (infinite readings)"
                at = f"{reach_low:g} m" if reach_low == reach_high else f"{reach_low:g} to {reach_high:g} m"
                notes.append(
                    f"kept {total} of {readings} readings with no return{where} as free rays "
                    f"at {at} with evidence 0 (no_return_range={self.no_return_range:g})"
                )
            if invalid:
                notes.append(f"dropped {invalid} of {readings} readings <= 0 or NaN")
        notes.append(f"constant evidence {self.evidence} for laser readings (evidence=)")
        if self.skipped_lines:
            notes.append(Note.warn(f"skipped {self.skipped_lines} laser line(s) that do not parse"))
        if self.unknown:
            notes.append(Note.warn(f"ignored records of unknown type: {', '.join(sorted(self.unknown)[:5])}"))
        return notes


options_as_keywords(read_carmen)
options_as_keywords(CarmenScans)
