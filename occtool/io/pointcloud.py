"""Read point-cloud files: plain ``x y z`` scans (OctoMap), PCD and PLY.

* ``xyz``: one point per line, ``x y z`` in metres in the sensor frame (OctoMap's
  ``scan.dat``; ``.dat``/``.xyz``, bz2/gzip too). OctoMap's plain log lines
  ``NODE x y z roll pitch yaw`` start a new scan taken at that sensor pose; the points
  after it are in the sensor's frame.
* ``pcd``: PCL's format, ``DATA ascii`` or ``binary`` (``binary_compressed`` is
  refused with a clear error). ``VIEWPOINT`` is the sensor pose in the cloud's frame:
  points are re-centred at it and turned by its yaw, and it becomes the pose.
  Bytes of zeros after the ``POINTS`` records of binary data (SC-A-LOAM's scans) are
  padding, ignored.
* ``ply``: ``ascii``, ``binary_little_endian`` or ``binary_big_endian``; the
  ``vertex`` element's ``x, y, z`` (and the evidence property, if any).
* KITTI ``.bin`` (read for :mod:`occtool.io.scans`): float32 ``x y z intensity`` records.

Evidence comes from the field named by ``evidence_field`` when the file has one,
else the constant ``evidence`` (0.9 by default). Points with a NaN coordinate or at
the origin are "no return" and dropped (counted in the notes); an evidence value
outside [0, 1] is an error unless ``skip_invalid``.
"""

from __future__ import annotations

import io
import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Note, Pose, RangeLog
from occtool.io.csv import open_text
from occtool.io.positions import Scan, build_log
from occtool.io.read_options import ReadOptions, as_read_options, options_as_keywords
from occtool.limits import MAX_COORDINATE

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}



def _points_and_evidence(values: dict[str, np.ndarray], evidence_field: str, constant: float, word: str,
                         notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """x, y, z as an (N, 3) array and the named evidence column, or the constant (noted)."""
    points = np.column_stack([values["x"], values["y"], values["z"]])
    if evidence_field in values:
        return points, values[evidence_field]
    notes.append(f"no '{evidence_field}' {word}: constant evidence {constant} (evidence=)")
    return points, np.full(points.shape[0], constant)

def _open_binary(path: str | os.PathLike[str]) -> io.BufferedIOBase:
    from occtool._files import open_input

    return open_input(path, "rb")  # type: ignore[return-value]


# --- numeric text with line numbers --------------------------------------------------------


XYZ_COLUMNS = (3, 4)  # x y z, and one more value (an intensity, ignored) at most


def _column_count_problem(count: int) -> str:
    """Why a line of ``count`` numbers is not an ``x y z`` point."""
    detail = f"has {count} values, expected x y z (3 or 4 numbers)"
    if count > 100:
        # BreezySLAM's MINES ParisTech logs (exp1.dat): time, telemetry, wheel ticks, 682 ranges.
        detail += (": it looks like a raw laser log (one scan of ranges per line, e.g. a Hokuyo URG "
                   "log as BreezySLAM's exp1.dat), not points; convert it to x y z points or CSV first")
    return detail


def _parse_numeric_lines(
    lines: list[str], first_line: int, name: str, skip_invalid: bool
) -> tuple[NDArray[np.float64], int]:
    """Parse whitespace-separated rows of 3 or 4 numbers, keeping the first three.

    Vectorised first; on failure a per-line pass names the bad line (or skips it).
    Returns the values and the count of skipped lines.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(lines, ndmin=2, dtype=np.float64, comments="#")
        if data.shape[1] in XYZ_COLUMNS or data.shape[0] == 0:
            return data[:, :3].reshape(-1, 3), 0
    except ValueError:
        pass
    rows, skipped = [], 0
    for k, line in enumerate(lines):
        text = line.split("#", 1)[0].split()
        if not text:
            continue
        try:
            if len(text) not in XYZ_COLUMNS:
                raise ValueError(_column_count_problem(len(text)))
            rows.append([float(v) for v in text[:3]])
        except ValueError as exc:
            if not skip_invalid:
                detail = str(exc) if "expected" in str(exc) else f"is not 3 or 4 numbers: {line.strip()[:60]!r}"
                raise InputError(f"{name}, line {first_line + k}: the line {detail}") from None
            skipped += 1
    return np.array(rows, dtype=np.float64).reshape(-1, 3), skipped


def _checked(
    points: NDArray[np.float64], evidence: NDArray[np.float64], name: str, skip_invalid: bool, counts: dict[str, int]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Drop no-return points (NaN, origin); refuse or drop bad evidence values."""
    finite = np.isfinite(points).all(axis=1)
    counts["nan"] += int((~finite).sum())
    points, evidence = points[finite], evidence[finite]
    origin = ~(np.abs(points) > 0.0).any(axis=1)
    counts["origin"] += int(origin.sum())
    points, evidence = points[~origin], evidence[~origin]
    far = ~(np.abs(points) <= MAX_COORDINATE).all(axis=1)
    if far.any():
        if not skip_invalid:
            i = int(np.argmax(far))
            raise InputError(f"{name}: point {i} lies at {tuple(float(v) for v in points[i])}, farther than "
                             f"{MAX_COORDINATE:g} m from the sensor: not range data (pass skip_invalid=True to drop such points)")
        counts["invalid"] += int(far.sum())
        points, evidence = points[~far], evidence[~far]
    bad = ~np.isfinite(evidence) | (evidence < 0.0) | (evidence > 1.0)
    if bad.any():
        if not skip_invalid:
            i = int(np.argmax(bad))
            raise InputError(
                f"{name}: point {i} has evidence {float(evidence[i])!r} outside [0, 1] "
                "(pass skip_invalid=True to drop such points)"
            )
        counts["invalid"] += int(bad.sum())
        points, evidence = points[~bad], evidence[~bad]
    return points, evidence


def _notes(counts: dict[str, int]) -> list[str]:
    notes = []
    if counts["nan"]:
        notes.append(f"dropped {counts['nan']} point(s) with NaN coordinates (no return)")
    if counts["origin"]:
        notes.append(f"dropped {counts['origin']} point(s) at the sensor origin (no return)")
    if counts["invalid"]:
        notes.append(Note.warn(f"skipped {counts['invalid']} point(s) with evidence outside [0, 1] or farther than "
                               f"{MAX_COORDINATE:g} m"))
    if counts.get("scans"):
        notes.append(Note.warn(f"dropped {counts['scans']} scan(s) whose NODE pose is not finite, with their points"))
    if counts.get("lines"):
        notes.append(Note.warn(f"skipped {counts['lines']} line(s) that do not parse"))
    return notes


def _rotation_rpy(roll: float, pitch: float) -> NDArray[np.float64]:
    """Rotation by pitch about y after roll about x: the tilt part of an OctoMap pose."""
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    return ry @ rx


# --- readers ---------------------------------------------------------------------------------


def _read_xyz(path: str | os.PathLike[str], name: str, constant: float, skip_invalid: bool,
              counts: dict[str, int]) -> tuple[list[Scan], list[str]]:
    with open_text(path) as handle:
        text = handle.read()
    lines = text.splitlines()
    if not any(line.strip() and not line.lstrip().startswith("#") for line in lines[:1000]):
        raise InputError(f"{name} is empty")
    notes: list[str] = []
    # OctoMap NODE lines split the file into scans; look for them line by line only if present.
    node_rows = [k for k, line in enumerate(lines) if line.startswith("NODE")] if "NODE" in text else []
    del text
    bounds = [(-1, None)] + [(k, lines[k]) for k in node_rows]
    scans = []
    for j, (start, node_line) in enumerate(bounds):
        stop = node_rows[j] if j < len(node_rows) else len(lines)
        body = lines[start + 1 : stop]
        pose = None
        tilt = None
        if node_line is not None:
            values = node_line.split()[1:]
            try:
                x, y, z, roll, pitch, yaw = (float(v) for v in values[:6])
                if len(values) < 6:
                    raise ValueError
            except ValueError:
                raise InputError(f"{name}, line {start + 1}: expected 'NODE x y z roll pitch yaw', got {node_line.strip()[:60]!r}") from None
            if not np.isfinite([x, y, z, roll, pitch, yaw]).all():
                if not skip_invalid:
                    raise InputError(
                        f"{name}, line {start + 1}: the scan's pose is not finite: {node_line.strip()[:60]!r} "
                        "(pass skip_invalid=True to drop such scans)")
                counts["scans"] = counts.get("scans", 0) + 1
                continue
            pose = Pose(x, y, z, yaw)
            if roll or pitch:
                tilt = _rotation_rpy(roll, pitch)
        if not any(line.strip() for line in body):
            continue
        data, skipped = _parse_numeric_lines(body, start + 2, name, skip_invalid)
        counts["lines"] += skipped
        points = data if tilt is None else data @ tilt.T
        evidence = np.full(points.shape[0], constant)
        points, evidence = _checked(points, evidence, name, skip_invalid, counts)
        scans.append(Scan(points, evidence, pose, None, name if pose is None else f"{name}:{start + 1}"))
    return scans, notes


def _pcd_header(handle: io.BufferedIOBase, name: str) -> dict[str, list[str]]:
    header: dict[str, list[str]] = {}
    for _ in range(64):
        raw = handle.readline()
        if not raw:
            break
        text = raw.decode("ascii", "replace").strip()
        if not text or text.startswith("#"):
            continue
        key, *values = text.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            return header
    raise InputError(f"{name}: PCD header without a DATA line")


def _read_pcd(path: str | os.PathLike[str], name: str, evidence_field: str, constant: float, skip_invalid: bool,
              counts: dict[str, int]) -> tuple[list[Scan], list[str]]:
    notes: list[str] = []
    with _open_binary(path) as handle:
        header = _pcd_header(handle, name)
        try:
            fields = header["FIELDS"]
            sizes = [int(v) for v in header["SIZE"]]
            types = header["TYPE"]
            field_counts = [int(v) for v in header.get("COUNT", ["1"] * len(fields))]
            width = int(header["WIDTH"][0])
            height = int(header.get("HEIGHT", ["1"])[0])
            points_count = int(header.get("POINTS", [str(width * height)])[0])
            viewpoint = [float(v) for v in header.get("VIEWPOINT", ["0", "0", "0", "1", "0", "0", "0"])]
        except (KeyError, ValueError, IndexError) as exc:
            raise InputError(f"{name}: PCD header is incomplete or malformed ({exc!r})") from None
        if not (len(fields) == len(sizes) == len(types) == len(field_counts)):
            raise InputError(f"{name}: PCD FIELDS, SIZE, TYPE and COUNT differ in length")
        if len(set(fields)) != len(fields):
            raise InputError(f"{name}: PCD FIELDS names a field twice ({' '.join(fields)})")
        if any(c < 1 for c in field_counts):
            raise InputError(f"{name}: PCD COUNT must be whole numbers >= 1, got {' '.join(header['COUNT'])}")
        if width < 0 or height < 0 or points_count < 0:
            raise InputError(f"{name}: PCD WIDTH, HEIGHT and POINTS must be >= 0, got {width}, {height}, {points_count}")
        if points_count != width * height:
            raise InputError(f"{name}: PCD POINTS {points_count} differs from WIDTH x HEIGHT = {width * height}")
        mode = header["DATA"][0].lower() if header["DATA"] else ""
        codes = []
        for f, size, kind in zip(fields, sizes, types):
            letter = {"F": "f", "I": "i", "U": "u"}.get(kind.upper())
            if letter is None or size not in (1, 2, 4, 8) or (letter == "f" and size not in (4, 8)):
                raise InputError(f"{name}: PCD field '{f}' has unsupported TYPE {kind} SIZE {size}")
            codes.append(f"<{letter}{size}")
        # Column (ascii) and byte (binary) offsets of each field's first element.
        columns: dict[str, tuple[int, str]] = {}
        offsets: dict[str, tuple[int, str]] = {}
        col, off = 0, 0
        for f, code, count in zip(fields, codes, field_counts):
            columns.setdefault(f, (col, code))
            offsets.setdefault(f, (off, code))
            col += count
            off += np.dtype(code).itemsize * count
        missing = [c for c in ("x", "y", "z") if c not in columns]
        if missing:
            raise InputError(f"{name}: PCD has no field {', '.join(missing)} (fields: {', '.join(fields)})")
        wanted = ["x", "y", "z"] + ([evidence_field] if evidence_field in columns else [])
        if mode == "ascii":
            lines = handle.read().decode("ascii", "replace").splitlines()
            usecols = [columns[w][0] for w in wanted]
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    data = np.loadtxt(lines, usecols=usecols, ndmin=2, dtype=np.float64)
            except ValueError as exc:
                raise InputError(f"{name}: PCD ascii data does not parse ({exc})") from None
            if data.shape[0] != points_count:
                raise InputError(f"{name}: PCD ascii data holds {data.shape[0]} points, the header says POINTS {points_count}")
            values = {w: data[:, k] for k, w in enumerate(wanted)}
        elif mode == "binary":
            stride = off
            raw = handle.read()  # bounded by the file (or the decompression limit), not by POINTS
            if len(raw) < points_count * stride:
                raise InputError(f"{name}: PCD binary data is truncated ({len(raw)} of {points_count * stride} bytes)")
            # Bytes beyond the points are an error unless they are zeros: SC-A-LOAM and
            # others save binary PCDs zero-padded after POINTS records.
            if len(raw) - points_count * stride >= stride > 0 and raw[points_count * stride:].strip(b"\0"):
                raise InputError(f"{name}: PCD binary data holds {len(raw) // stride} points, the header says "
                                 f"POINTS {points_count}")
            dtype = np.dtype({"names": wanted, "formats": [offsets[w][1] for w in wanted],
                              "offsets": [offsets[w][0] for w in wanted], "itemsize": stride})
            records = np.frombuffer(raw, dtype=dtype, count=points_count)
            values = {w: records[w].astype(np.float64) for w in wanted}
        elif mode == "binary_compressed":
            raise InputError(
                f"{name}: PCD 'binary_compressed' data is not supported; convert it to binary or ascii "
                "(e.g. pcl_convert_pcd_ascii_binary in.pcd out.pcd 1)"
            )
        else:
            raise InputError(f"{name}: unknown PCD DATA mode {mode!r}")
    points, evidence = _points_and_evidence(values, evidence_field, constant, "field", notes)
    pose = None
    tx, ty, tz, qw, qx, qy, qz = (viewpoint + [0.0] * 7)[:7]
    if (tx, ty, tz) != (0.0, 0.0, 0.0) or (qx, qy, qz) != (0.0, 0.0, 0.0):
        yaw = float(np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)))
        pose = Pose(tx, ty, tz, yaw)
        # Re-centre at the viewpoint and turn into its heading: the sensor-centred frame.
        c, s = np.cos(yaw), np.sin(yaw)
        shifted = points - [tx, ty, tz]
        points = np.column_stack([c * shifted[:, 0] + s * shifted[:, 1], -s * shifted[:, 0] + c * shifted[:, 1], shifted[:, 2]])
    points, evidence = _checked(points, evidence, name, skip_invalid, counts)
    return [Scan(points, evidence, pose, None, name)], notes


def _read_ply(path: str | os.PathLike[str], name: str, evidence_field: str, constant: float, skip_invalid: bool,
              counts: dict[str, int]) -> tuple[list[Scan], list[str]]:
    notes: list[str] = []
    with _open_binary(path) as handle:
        if handle.readline().strip() != b"ply":
            raise InputError(f"{name}: not a PLY file (no 'ply' first line)")
        fmt = None
        elements: list[tuple[str, int, list[tuple[str, str | None]]]] = []
        for _ in range(1000):
            raw = handle.readline()
            if not raw:
                raise InputError(f"{name}: PLY header without end_header")
            parts = raw.decode("ascii", "replace").split()
            if not parts or parts[0] in ("comment", "obj_info"):
                continue
            if parts[0] == "end_header":
                break
            try:
                if parts[0] == "format":
                    fmt = parts[1]
                elif parts[0] == "element":
                    if int(parts[2]) < 0:
                        raise ValueError
                    elements.append((parts[1], int(parts[2]), []))
                elif parts[0] == "property":
                    if parts[1] == "list":
                        elements[-1][2].append((parts[4], None))
                    else:
                        elements[-1][2].append((parts[2], _PLY_TYPES[parts[1]]))
            except (IndexError, KeyError, ValueError):
                raise InputError(f"{name}: PLY header line does not parse: {raw.decode('ascii', 'replace').strip()!r}") from None
        else:
            raise InputError(f"{name}: PLY header too long or without end_header")
        vertex_index = next((k for k, e in enumerate(elements) if e[0] == "vertex"), None)
        if vertex_index is None:
            raise InputError(f"{name}: PLY file has no vertex element")
        _, count, properties = elements[vertex_index]
        names = [p for p, _ in properties]
        for element_name, _, element_properties in elements:
            property_names = [p for p, _ in element_properties]
            if len(set(property_names)) != len(property_names):
                raise InputError(f"{name}: PLY element '{element_name}' names a property twice "
                                 f"({' '.join(property_names)})")
        missing = [c for c in ("x", "y", "z") if c not in names]
        if missing:
            raise InputError(f"{name}: PLY vertices have no property {', '.join(missing)}")
        for earlier in elements[:vertex_index] + [elements[vertex_index]]:
            if any(t is None for _, t in earlier[2]):
                raise InputError(f"{name}: PLY list properties before or in the vertex element are not supported")
        wanted = ["x", "y", "z"] + ([evidence_field] if evidence_field in names else [])
        if fmt == "ascii":
            skip_rows = sum(e[1] for e in elements[:vertex_index])
            text = handle.read().decode("ascii", "replace").splitlines()
            lines = text[skip_rows : skip_rows + count]
            if len(lines) < count:
                raise InputError(f"{name}: PLY has {len(lines)} vertex lines, the header says {count}")
            try:
                data = np.loadtxt(lines, usecols=[names.index(w) for w in wanted], ndmin=2, dtype=np.float64)
            except ValueError as exc:
                raise InputError(f"{name}: PLY vertex data does not parse ({exc})") from None
            values = {w: data[:, k] for k, w in enumerate(wanted)}
        elif fmt in ("binary_little_endian", "binary_big_endian"):
            order = "<" if fmt == "binary_little_endian" else ">"
            skip = sum(e[1] * sum(np.dtype(t).itemsize for _, t in e[2]) for e in elements[:vertex_index])
            if len(handle.read(skip)) < skip:
                raise InputError(f"{name}: PLY data is truncated before the vertices")
            dtype = np.dtype([(p, order + t) for p, t in properties])  # type: ignore[operator]
            raw = handle.read(count * dtype.itemsize) if count * dtype.itemsize < 2**31 else handle.read()
            if len(raw) < count * dtype.itemsize:
                raise InputError(f"{name}: PLY vertex data is truncated")
            records = np.frombuffer(raw, dtype=dtype, count=count)
            values = {w: records[w].astype(np.float64) for w in wanted}
        else:
            raise InputError(f"{name}: unknown PLY format {fmt!r}")
    points, evidence = _points_and_evidence(values, evidence_field, constant, "property", notes)
    points, evidence = _checked(points, evidence, name, skip_invalid, counts)
    return [Scan(points, evidence, None, None, name)], notes


#: KITTI's Velodyne ``.bin`` scans: float32 records of x, y, z and a reflectance, no header.
KITTI_BIN_FIELDS = 4


def _read_kitti_bin(path: str | os.PathLike[str], name: str, constant: float, skip_invalid: bool,
                    counts: dict[str, int]) -> tuple[list[Scan], list[str]]:
    with _open_binary(path) as handle:
        raw = handle.read()
    record = 4 * KITTI_BIN_FIELDS
    if len(raw) % record:
        raise InputError(f"{name}: a KITTI .bin scan holds float32 x y z intensity records of {record} bytes, "
                         f"and its {len(raw):,} bytes are not a whole number of them")
    data = np.frombuffer(raw, dtype="<f4").reshape(-1, KITTI_BIN_FIELDS)
    points = data[:, :3].astype(np.float64)
    evidence = np.full(points.shape[0], constant)
    points, evidence = _checked(points, evidence, name, skip_invalid, counts)
    return [Scan(points, evidence, None, None, name)], [f"constant evidence {constant} for KITTI .bin points (evidence=)"]


def pointcloud_scans(path: str | os.PathLike[str], settings: ReadOptions, format: str | None = None
                     ) -> tuple[list[Scan], list[str]]:
    """The scans of one ``xyz``, ``pcd``, ``ply`` or KITTI ``bin`` file (``format``, else ``settings.format``,
    else from the extension) and the notes of reading it (:func:`read_pointcloud` groups them;
    :mod:`occtool.io.scans` reads a folder of such files with this)."""
    name = str(path)
    format = format or settings.format
    if format is None:
        suffixes = [s.lower() for s in Path(name).suffixes if s.lower() not in (".gz", ".bz2")]
        format = {".pcd": "pcd", ".ply": "ply"}.get(suffixes[-1] if suffixes else "", "xyz")
    constant, skip_invalid = settings.constant_evidence, settings.skip_invalid
    counts = {"nan": 0, "origin": 0, "invalid": 0, "lines": 0}
    if format == "bin":
        scans, notes = _read_kitti_bin(path, name, constant, skip_invalid, counts)
    elif format == "xyz":
        scans, notes = _read_xyz(path, name, constant, skip_invalid, counts)
        notes.append(f"constant evidence {constant} for plain x y z points (evidence=)")
    elif format == "pcd":
        scans, notes = _read_pcd(path, name, settings.evidence_field, constant, skip_invalid, counts)
    elif format == "ply":
        scans, notes = _read_ply(path, name, settings.evidence_field, constant, skip_invalid, counts)
    else:
        raise InputError(f"unknown point-cloud format {format!r}: expected xyz, pcd or ply")
    notes.extend(_notes(counts))
    return scans, notes


def read_pointcloud(path: str | os.PathLike[str], options: ReadOptions | None = None, **keywords: Any) -> RangeLog:
    """Read an ``xyz``, ``pcd`` or ``ply`` point-cloud file into positions of features.

    Parameters
    ----------
    path
        The file.
    options, **keywords
        The reading options (:class:`~occtool.io.ReadOptions`, or its fields by name). A
        point cloud uses ``format`` (``"xyz"``, ``"pcd"`` or ``"ply"``; by default from the
        extension), ``evidence_field``, ``evidence``, ``position_tolerance``, ``group_by``
        and ``skip_invalid``.

    Raises
    ------
    InputError
        For a malformed header or data, naming the file (and line for ``xyz``).
    """
    settings = as_read_options(options, **keywords)
    name = str(path)
    scans, notes = pointcloud_scans(path, settings)
    if not any(s.points.shape[0] for s in scans):
        raise InputError(f"{name} holds no valid points")
    return build_log(scans, source=name, tolerance=settings.position_tolerance, group_by=settings.group_by,
                     notes=notes)


options_as_keywords(read_pointcloud)
