"""Bounds on every size and length a user can ask for, in one light module.

The library refuses values beyond these with an :class:`~occtool.errors.InputError`
naming its keyword; the command line reads the same numbers for its options' ranges
(importing this module costs nothing), so a flag is refused before any work starts.
Each bound sits far above any sensible use and far below what exhausts a machine;
the figures are from runs on the project's 2-core machine.
"""

from __future__ import annotations

#: Most pan angles a map is swept at (0.01 degree apart): memory grows by ~25 KB per angle
#: with 64 pieces (36,000 angles took 0.9 GB), so ten million would need 250 GB.
MAX_ANGLES = 36_000
#: Most linear pieces of a model (1,024 fitted 10,000 features in 6 s and 0.34 GB).
MAX_PIECES = 4096
#: Most footprint or background samples of the sensor model (a million: 0.25 GB, 5 s to fit).
MAX_BODY_SAMPLES = 1_000_000
#: Most rays `evaluate` traces (72,000 took 4.5 s and 0.1 GB, 720,000 took 42 s and 0.8 GB).
MAX_RAYS = 100_000
#: Most features a simulated scene registers (a million took 21 s and 0.26 GB).
MAX_FEATURES = 2_000_000
#: A coordinate farther than this from the sensor is no range measurement (1,000 km), and
#: squares of coordinates near 1e154 overflow to infinity in every range computation.
MAX_COORDINATE = 1e6
#: Largest robot dimension (radius, heights), metres: a robot is not bigger than a building,
#: and lengths near 1e154 overflow when squared.
MAX_ROBOT_SIZE = 100.0
#: Largest distance option (max range, focus range, background range, a simulated sensor's
#: range, a laser's no-return range), metres.
MAX_DISTANCE = 1e4
#: Smallest length a map file may hold (a cell, a falloff), metres: a micrometre. Distances up
#: to MAX_WORLD_COORDINATE over it stay finite (a falloff of 5e-324 m overflowed queries).
MIN_DISTANCE = 1e-6
#: Most bytes a compressed input may expand to; readers hold the text in memory, several
#: times over while parsing (the largest shared log expands to 9.5 MB).
MAX_DECOMPRESSED_BYTES = 2**30
#: Largest weight or slope bound of the fit (c_min, a_max, b_max, c_max, huber_delta): far
#: beyond any useful value, and small enough that the linear programmes stay finite.
MAX_WEIGHT = 1e6
#: Most least-squares refit sweeps (each one refits every piece).
MAX_SWEEPS = 1000
#: Most repetitions or scan splits of `compare-grid`.
MAX_REPEATS = 1000
#: Largest simulated range noise, metres per metre squared (the default is 0.01).
MAX_RANGE_NOISE = 10.0
#: Largest world coordinate (a pose's x, y, z or yaw, a world map's corner), metres
#: (radians): 100,000 km, beyond every frame on Earth (UTM northings reach 1e7 m, ECEF
#: coordinates 6.4e6 m) and far below where squares overflow.
MAX_WORLD_COORDINATE = 1e8
#: Largest ``world.occmap`` read, bytes: 750 times the Intel lab's map (44 KB). Reading a
#: map takes up to ~26 times its file's size (a 9.9 MB file of a million segments and
#: 200,000 region polygons grew the process by 256 MB: float64 end points and GEOS
#: vertices for a few bytes each), so a hostile file stays under ~0.9 GB.
MAX_MAP_BYTES = 32 * 2**20
#: The memory a run of ``occtool map`` may be estimated to need before it is refused
#: (``memory_limit=``, ``--memory-limit``): half of a robot computer's 8 GB. The Freiburg
#: campus, the largest shared log, needs about 0.6 GB.
DEFAULT_MEMORY_LIMIT = "4G"
#: Size suffixes of a memory limit (decimal, as ``free -h`` and vendors count: 4G is 4e9 bytes).
_SIZE_SUFFIXES = {"": 1, "K": 10**3, "M": 10**6, "G": 10**9, "T": 10**12}


def memory_bytes(value: int | float | str | None, keyword: str = "memory_limit") -> int | None:
    """Bytes of a memory limit: a number of bytes, or a text such as ``"500M"``, ``"8G"``,
    ``"1.5T"`` (decimal K, M, G, T; a trailing ``B`` allowed); ``None`` or ``"none"``: no
    limit. Anything else is an :class:`~occtool.errors.InputError` naming ``keyword``."""
    if value is None:
        return None
    if isinstance(value, bool):
        value = str(value)  # refused below: True is no size
    if isinstance(value, (int, float)):
        number, scale = float(value), 1
    else:
        if str(value).strip().lower() == "none":
            return None
        text = str(value).strip().upper().removesuffix("B").strip()
        suffix = text[-1:] if text[-1:] in _SIZE_SUFFIXES else ""
        try:
            number, scale = float(text[: len(text) - len(suffix)]), _SIZE_SUFFIXES[suffix]
        except ValueError:
            number, scale = float("nan"), 1
    if not (number > 0 and number * scale < 2**63):  # NaN and infinity fail too
        from occtool.errors import InputError

        raise InputError(f"{keyword} must be a size such as '500M' or '8G' (bytes; 'none': no limit), "
                         f"got {value!r}")
    return int(number * scale)


def release_free_memory() -> None:
    """Hand the C heap's free pages back to the system (glibc's ``malloc_trim``; nothing
    elsewhere). GEOS and numpy's small allocations leave the heap fragmented after a stage:
    on the Freiburg campus the process kept 66 MB after the world map's build and 57 MB
    after the navigation region's union that trimming returned."""
    import sys

    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (AttributeError, OSError):  # a C library without malloc_trim (musl)
        pass


class collector_paused:
    """A block in which Python's cyclic garbage collector does not run (``gc.disable``), for
    work that makes many container objects and frees them by their reference counts alone:
    a list a vertex of a polygon turned into GeoJSON. Each of the collector's full passes
    walks every tracked object of the process, and such work sets off more of them the more
    it makes: writing campus x10's navigation.geojson ran 23 of them over the run's ~500,000
    objects (8 s of CPU), the campus's 4 over ~90,000 (0.26 s). The collector is left as it
    was found (a block inside a paused one does not start it again)."""

    def __enter__(self) -> collector_paused:
        import gc

        self._was = gc.isenabled()
        gc.disable()
        return self

    def __exit__(self, *exc: object) -> None:
        import gc

        if self._was:
            gc.enable()

