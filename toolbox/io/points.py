"""Point clouds: LAS 1.2–1.4 / LAZ through laspy (lazrs backend), and the ASCII ``X Y Z [label]``
format of the ISPRS filter test.

Coordinates stay in the file's CRS and units; ``horizontal_unit_m`` and ``vertical_unit_m`` say
how many metres one unit is, so that algorithms whose parameters are in metres can convert them
(``pc.to_units(1.0)``) and outputs stay in the input's CRS.
"""

from __future__ import annotations

import logging
import threading
import os
import warnings
from collections.abc import MutableMapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from ..errors import DataError, UsageError
from .atomic import atomic_path

log = logging.getLogger(__name__)

LAS_EXTENSIONS = (".las", ".laz")
ASCII_EXTENSIONS = (".txt", ".xyz", ".csv", ".asc", ".pts")
_CRS_VLRS = {"GeoKeyDirectoryVlr", "GeoDoubleParamsVlr", "GeoAsciiParamsVlr", "WktCoordinateSystemVlr"}
# EPSG unit codes of the GeoTIFF VerticalUnitsGeoKey (4099) -> metres per unit
_GEOTIFF_UNITS = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0}


# Held while a writer has changed dimensions swapped into a source record (see _reuse_record),
# and while a dimension is decoded from a record: outputs are written in background threads.
RECORD_LOCK = threading.RLock()


class LazyFields(MutableMapping):
    """Per-point attributes backed by the file's laspy point record: a dimension is decoded the
    first time it is read, and the record is reused as-is when the cloud is written back, so
    untouched dimensions cost nothing either way. Assigned values override the record.

    A record read with a decompression selection (``read_points(dims=...)``) holds only the
    selected dimensions; reading any other one, or writing the cloud, first reads the whole file
    again (once, logged), so a partial read is never visible as missing or zeroed data."""

    def __init__(self, record, names, overrides=None, selected=None, source=None, index=None):
        self.record = record
        self._names = list(names)
        self._cache: dict[str, np.ndarray] = {}
        self.overrides: dict[str, np.ndarray] = dict(overrides or {})
        self.selected = None if selected is None else frozenset(selected)  # None: the record is complete
        self._source = source  # _FullRead of the file, for completing a partial record
        self._index = index  # integer positions of this record's points in the file

    def complete(self) -> None:
        """Make the record whole (read the file again without a selection) if it is partial."""
        if self.selected is None:
            return
        full = self._source.record()
        self.record = full if self._index is None else full[self._index]
        self.selected = None

    def __getitem__(self, name):
        if name in self.overrides:
            return self.overrides[name]
        if name in self._cache:
            return self._cache[name]
        if name not in self._names:
            raise KeyError(name)
        with RECORD_LOCK:  # a background writer may have the record's dimensions swapped
            if self.selected is not None and name not in self.selected:
                log.info("%s: %r was not among the dimensions decompressed; reading the whole file",
                         self._source.path, name)
                self.complete()
            value = np.asarray(self.record[name]).copy()
        self._cache[name] = value
        return value

    def __setitem__(self, name, value):
        self.overrides[name] = value

    def __delitem__(self, name):
        if name in self.overrides and name not in self._names:
            del self.overrides[name]
        else:
            raise KeyError(f"{name}: dimensions of the file cannot be removed")

    def __iter__(self):
        yield from self._names
        yield from (n for n in self.overrides if n not in self._names)

    def __len__(self):
        return len(self._names) + sum(1 for n in self.overrides if n not in self._names)

    def __contains__(self, name):
        return name in self.overrides or name in self._names

    def subset(self, idx) -> "LazyFields":
        pos = None
        if self.selected is not None:  # remember where these points sit in the file
            here = np.flatnonzero(idx) if np.asarray(idx).dtype == bool else np.asarray(idx)
            pos = here if self._index is None else self._index[here]
        sub = LazyFields(self.record[idx], self._names, {k: v[idx] for k, v in self.overrides.items()},
                         self.selected, self._source, pos)
        sub._cache = {k: v[idx] for k, v in self._cache.items()}
        return sub

    def with_overrides(self, new: dict) -> "LazyFields":
        out = LazyFields(self.record, self._names, {**self.overrides, **new}, self.selected, self._source,
                         self._index)
        out._cache = self._cache
        return out


class _FullRead:
    """The whole point record of a file, read on first need (completes partial reads)."""

    def __init__(self, path: Path):
        self.path = path
        self._record = None

    def record(self):
        if self._record is None:
            self._record = _read_las_data(self.path).points
        return self._record


# laspy's decompression layers (LAS 1.4 point formats 6-10) that hold each dimension; x, y and
# the return numbers are always decoded
def _selection_for(dims, extra_names):
    import laspy

    DS = laspy.DecompressionSelection
    layer = {"z": DS.Z, "classification": DS.CLASSIFICATION, "intensity": DS.INTENSITY,
             "scan_angle": DS.SCAN_ANGLE, "user_data": DS.USER_DATA, "point_source_id": DS.POINT_SOURCE_ID,
             "gps_time": DS.GPS_TIME, "red": DS.RGB, "green": DS.RGB, "blue": DS.RGB, "nir": DS.NIR,
             "synthetic": DS.FLAGS, "key_point": DS.FLAGS, "withheld": DS.FLAGS, "overlap": DS.FLAGS,
             "scan_direction_flag": DS.FLAGS, "edge_of_flight_line": DS.FLAGS}
    sel = DS.XY_RETURNS_CHANNEL | DS.Z
    for d in dims:
        if d in extra_names:
            sel |= DS.ALL_EXTRA_BYTES
        else:
            sel |= layer.get(d, DS(0))
    return sel


@dataclass
class PointCloud:
    """A point cloud as plain arrays.

    ``fields`` holds every per-point attribute except x, y, z under its laspy name
    (classification, return_number, number_of_returns, intensity, gps_time, red, ..., and any
    extra dimension). ``header`` is the laspy header of the file it came from, kept as the
    template for writing (point format, scales, offsets, VLRs).
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    crs: object | None = None  # pyproj.CRS
    source: str = ""
    header: object | None = None  # laspy.LasHeader
    horizontal_unit_m: float = 1.0
    vertical_unit_m: float = 1.0
    #: free metadata; ``creation_date`` (datetime.date) fixes the LAS header date (reproducible files)
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.x = np.ascontiguousarray(self.x, dtype=np.float64)
        self.y = np.ascontiguousarray(self.y, dtype=np.float64)
        self.z = np.ascontiguousarray(self.z, dtype=np.float64)
        n = len(self.x)
        if len(self.y) != n or len(self.z) != n:
            raise ValueError("x, y, z must have the same length")
        eager = self.fields.overrides if isinstance(self.fields, LazyFields) else self.fields
        for k, v in eager.items():
            if len(v) != n:
                raise ValueError(f"field {k!r} has {len(v)} values for {n} points")

    def __len__(self) -> int:
        return len(self.x)

    @property
    def xyz(self) -> np.ndarray:
        return np.column_stack([self.x, self.y, self.z])

    @property
    def classification(self) -> np.ndarray | None:
        return self.fields.get("classification")

    def bounds(self) -> tuple[float, float, float, float]:
        return float(self.x.min()), float(self.y.min()), float(self.x.max()), float(self.y.max())

    def subset(self, mask_or_index) -> "PointCloud":
        idx = mask_or_index
        fields = self.fields.subset(idx) if isinstance(self.fields, LazyFields) else \
            {k: v[idx] for k, v in self.fields.items()}
        out = replace(self, x=self.x[idx], y=self.y[idx], z=self.z[idx], fields=fields, meta=dict(self.meta))
        src = self.meta.get("_xyz_source")
        if src is not None and isinstance(fields, LazyFields) and _xyz_untouched(self, src):
            out.meta["_xyz_source"] = (out.x, out.y, out.z, fields.record)
        else:
            out.meta.pop("_xyz_source", None)
        return out

    def with_fields(self, **new_fields: np.ndarray) -> "PointCloud":
        if isinstance(self.fields, LazyFields):
            return replace(self, fields=self.fields.with_overrides(new_fields))
        f = dict(self.fields)
        f.update(new_fields)
        return replace(self, fields=f)

    def to_units(self, metres: float, vertical: bool = False) -> float:
        """Convert a length in metres to this cloud's (horizontal or vertical) units."""
        return metres / (self.vertical_unit_m if vertical else self.horizontal_unit_m)

    def classes_with(self, decided, released=()) -> np.ndarray:
        """The input's classification (1 where the cloud has none) with a run's decisions:
        ``decided`` is [(class, mask)], applied in order; a point whose input class is one of
        ``released`` (classes the run decides for the whole cloud) and that no decision takes
        becomes 1 (unclassified). Every other point keeps its class."""
        given = self.classification
        cls = np.ones(len(self), np.uint8) if given is None else np.asarray(given).astype(np.uint8, copy=True)
        if released:
            cls[np.isin(cls, released)] = 1
        for value, mask in decided:
            cls[mask] = value
        return cls

    def require_points(self, what: str = "this algorithm", minimum: int = 1) -> None:
        if len(self) < minimum:
            raise DataError(
                f"input {self.source or 'point cloud'!r} has {len(self)} points; {what} needs at least {minimum}"
            )


# --------------------------------------------------------------------------------------------
# CRS and units
# --------------------------------------------------------------------------------------------

def parse_crs(text: str):
    """Parse a user CRS (``EPSG:28992``, WKT, PROJ string) or raise a UsageError."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        return CRS.from_user_input(text)
    except CRSError:
        raise UsageError(f"--crs {text!r} is not a CRS pyproj knows; give e.g. EPSG:28992") from None


def crs_units(crs) -> tuple[float, float | None]:
    """(metres per horizontal unit, metres per vertical unit or None when the CRS has no Z axis)."""
    if crs is None:
        return 1.0, None
    horiz, vert = crs, None
    if crs.is_compound and crs.sub_crs_list:
        horiz = crs.sub_crs_list[0]
        if len(crs.sub_crs_list) > 1:
            vert = crs.sub_crs_list[1]
    if horiz.is_geographic:
        raise DataError(
            f"CRS {crs.name!r} is geographic (degrees); reproject the points to a projected CRS "
            "(e.g. UTM) or pass --crs with the projected CRS they are really in"
        )
    if not (horiz.is_projected or horiz.is_engineering):
        # geocentric (EPSG:4978) or vertical only: no plan axes in metres or feet to work in
        kind = "geocentric (earth-centred X, Y, Z)" if horiz.is_geocentric else "not a projected CRS"
        raise DataError(
            f"CRS {crs.name!r} is {kind}; reproject the points to a projected CRS (e.g. UTM) or pass --crs "
            "with the projected CRS they are really in"
        )
    h = 1.0
    if horiz.axis_info:
        h = float(horiz.axis_info[0].unit_conversion_factor or 1.0)
    v = None
    if vert is not None and vert.axis_info:
        v = float(vert.axis_info[0].unit_conversion_factor or 1.0)
    return h, v


def _geotiff_vertical_unit(header) -> float | None:
    for vlr in header.vlrs:
        keys = getattr(vlr, "geo_keys", None)
        if keys:
            for k in keys:
                if k.id == 4099 and k.value_offset in _GEOTIFF_UNITS:
                    return _GEOTIFF_UNITS[k.value_offset]
    return None


def _apply_crs(pc: PointCloud, crs, header=None) -> PointCloud:
    h, v = crs_units(crs)
    if v is None and header is not None:
        v = _geotiff_vertical_unit(header)
    if v is None:
        # Files in feet almost always have heights in the same feet (ASPRS practice).
        v = h
    pc.crs, pc.horizontal_unit_m, pc.vertical_unit_m = crs, h, v
    return pc


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------

def point_format_of(path: str | os.PathLike) -> str:
    """'las' or 'ascii' by extension; UsageError for anything else."""
    ext = Path(path).suffix.lower()
    if ext in LAS_EXTENSIONS:
        return "las"
    if ext in ASCII_EXTENSIONS:
        return "ascii"
    raise UsageError(
        f"input {str(path)!r} is not a point cloud file (expected .las, .laz or ASCII .txt/.xyz)"
    )


def _check_exists(path: Path) -> None:
    if not path.exists():
        raise DataError(f"input {str(path)!r} does not exist; check the path")
    if path.is_dir():
        raise UsageError(f"input {str(path)!r} is a folder; give the point cloud files in it")


def check_las_header(hdr, path) -> None:
    """Refuse a header whose scales or offsets are zero, NaN or infinite: every coordinate read
    through it would be wrong (all at the offset, or NaN), and nothing in the points says so."""
    where = str(path)
    for what, values in (("scale factors", hdr.scales), ("offsets", hdr.offsets)):
        v = np.asarray(values, dtype=np.float64)
        bad = ~np.isfinite(v) | ((v == 0) if what == "scale factors" else np.zeros(len(v), bool))
        if bad.any():
            shown = ", ".join(f"{a}={b:g}" for a, b in zip("xyz", v))
            raise DataError(f"input {where!r}: the LAS header's {what} are {shown}; no coordinate can be read "
                            "through them: repair the header (e.g. las2las -rescale / -reoffset) or re-export the file")


def _header_gives_finite_coordinates(hdr) -> bool:
    """Whether every coordinate a record can hold (a 32-bit integer times the scale plus the
    offset) is finite, so that decoded points need no check."""
    sc, off = np.asarray(hdr.scales, np.float64), np.asarray(hdr.offsets, np.float64)
    with np.errstate(over="ignore"):
        return bool(np.isfinite(np.abs(sc) * 2.0**31 + np.abs(off)).all())


def drop_non_finite(pc: PointCloud, refuse_when_none_left: bool = True) -> PointCloud:
    """The cloud without points whose x, y or z is NaN or infinite, with a warning that counts them;
    the count is kept in ``pc.meta['n_dropped_non_finite']`` for the run report."""
    ok = np.isfinite(pc.x) & np.isfinite(pc.y) & np.isfinite(pc.z)
    n_bad = int(len(ok) - np.count_nonzero(ok))
    if n_bad == 0:
        return pc
    if n_bad == len(ok) and refuse_when_none_left:
        raise DataError(f"input {pc.source!r}: none of its {n_bad} points has finite x, y and z; check the file")
    log.warning("%s: %d of %d points have a NaN or infinite x, y or z; they were dropped", pc.source, n_bad, len(ok))
    out = pc.subset(ok)
    out.meta["n_dropped_non_finite"] = n_bad
    return out


def read_points(path: str | os.PathLike, crs=None, dims=None) -> PointCloud:
    """Read a LAS/LAZ or ASCII point cloud. ``crs`` (text or pyproj CRS) sets or overrides the CRS.

    ``dims``: the dimensions the caller will read besides x, y, z. LAZ in the LAS 1.4 point
    formats (6-10) is then decompressed for those layers only (a 1.9 M-point file: 0.30 s instead
    of 0.52 s); other dimensions stay available, at the cost of reading the file again."""
    path = Path(path)
    _check_exists(path)
    user_crs = parse_crs(crs) if isinstance(crs, str) else crs
    if point_format_of(path) == "ascii":
        pc = drop_non_finite(_read_ascii(path))
        _warn_without_crs(path, user_crs, len(pc))
        return _apply_crs(pc, user_crs)
    selection = None
    if dims is not None and path.suffix.lower() == ".laz":
        import laspy

        with laspy.open(path) as reader:
            fmt = reader.header.point_format
        if fmt.id >= 6:
            selection = _selection_for(set(dims), set(fmt.extra_dimension_names))
            if selection == laspy.DecompressionSelection.all():
                selection = None
    las = _read_las_data(path, selection)
    hdr = las.header
    check_las_header(hdr, path)
    names = [n for n in las.point_format.dimension_names if n not in ("X", "Y", "Z")]
    if selection is None:
        fields = LazyFields(las.points, names)
    else:
        always = {"return_number", "number_of_returns", "scanner_channel"}  # decoded with x, y
        fields = LazyFields(las.points, names, selected={*always, *dims}, source=_FullRead(path))
    file_crs = None
    if user_crs is None:
        try:
            file_crs = _header_crs(hdr)
        except Exception as exc:  # malformed CRS VLRs: keep the points, say so
            log.warning("%s: could not parse the CRS VLRs (%s); pass --crs", path, exc)
    pc = PointCloud(
        x=np.asarray(las.x), y=np.asarray(las.y), z=np.asarray(las.z),
        fields=fields, source=str(path), header=hdr,
    )
    pc.meta["_xyz_source"] = (pc.x, pc.y, pc.z, las.points)
    if not _header_gives_finite_coordinates(hdr):  # (else a pass over every point would find nothing)
        pc = drop_non_finite(pc)
    crs_final = user_crs if user_crs is not None else file_crs
    _warn_without_crs(path, crs_final, len(pc))
    return _apply_crs(pc, crs_final, hdr)


def _warn_without_crs(path, crs, n_points: int) -> None:
    if crs is None and n_points:  # (an empty cloud is refused anyway: one line is enough)
        log.warning("%s has no CRS; its outputs will have none: pass --crs (e.g. --crs EPSG:28992) to set it", path)


def _decode_errors() -> tuple:
    """What laspy and its LAZ backends raise on a damaged file: lazrs's errors are RuntimeErrors,
    LASzip's (the `laszip` wheel, which laspy prefers when it is installed) are not."""
    import laspy

    errors = [laspy.errors.LaspyException, ValueError, EOFError, OSError, RuntimeError]
    try:
        from laszip import LaszipError
    except ImportError:
        pass
    else:
        errors.append(LaszipError)
    return tuple(errors)


def _read_las_data(path: Path, selection=None):
    import laspy

    try:
        with (laspy.open(path) if selection is None else laspy.open(path, decompression_selection=selection)) as reader:
            expected = reader.header.point_count
            las = reader.read()
    except laspy.errors.LaspyException as exc:
        msg = str(exc)
        if "signature" in msg.lower():
            raise DataError(f"input {str(path)!r} is not a LAS/LAZ file (bad file signature); check the file") from None
        raise DataError(f"input {str(path)!r} could not be read as LAS/LAZ ({_short(msg)}); the file may be truncated or corrupt") from None
    except _decode_errors() as exc:
        raise DataError(f"input {str(path)!r} could not be read as LAS/LAZ ({_short(str(exc))}); the file may be truncated or corrupt") from None
    if len(las.points) != expected:
        raise DataError(
            f"input {str(path)!r} is truncated: the header promises {expected} points, the file holds "
            f"{len(las.points)}; re-download or re-export it"
        )
    return las


def iter_points(path: str | os.PathLike, chunk_points: int = 1_000_000, crs=None) -> Iterator[PointCloud]:
    """Read a LAS/LAZ file in chunks of at most ``chunk_points`` (bounded memory)."""
    import laspy

    path = Path(path)
    _check_exists(path)
    if point_format_of(path) == "ascii":
        yield read_points(path, crs=crs)
        return
    user_crs = parse_crs(crs) if isinstance(crs, str) else crs
    try:
        reader = laspy.open(path)
    except laspy.errors.LaspyException as exc:
        raise DataError(f"input {str(path)!r} is not a readable LAS/LAZ file ({_short(str(exc))})") from None
    with reader:
        hdr = reader.header
        check_las_header(hdr, path)
        finite = _header_gives_finite_coordinates(hdr)
        crs_final = user_crs if user_crs is not None else _safe_parse_crs(hdr)
        seen = 0
        try:
            for chunk in reader.chunk_iterator(chunk_points):
                seen += len(chunk)
                fields = {n: np.asarray(chunk[n]).copy() for n in chunk.point_format.dimension_names if n not in ("X", "Y", "Z")}
                pc = PointCloud(
                    x=np.asarray(chunk.x), y=np.asarray(chunk.y), z=np.asarray(chunk.z),
                    fields=fields, source=str(path), header=hdr,
                )
                yield _apply_crs(pc if finite else drop_non_finite(pc, refuse_when_none_left=False), crs_final, hdr)
        except _decode_errors() as exc:
            raise DataError(f"input {str(path)!r} is truncated or corrupt after {seen} points ({_short(str(exc))})") from None
        if seen != hdr.point_count:
            raise DataError(f"input {str(path)!r} is truncated: the header promises {hdr.point_count} points, the file holds {seen}")


def _safe_parse_crs(hdr):
    try:
        return _header_crs(hdr)
    except Exception:
        return None


_CRS_CACHE: dict = {}


def _header_crs(hdr):
    """``hdr.parse_crs()``, remembered by the bytes of the file's projection records: PROJ takes
    28 ms to parse Autzen's ESRI-style WKT, once on reading and again on writing the classified
    copy, and the tiles of a batch share one CRS."""
    records = list(hdr.vlrs) + list(hdr.evlrs or [])
    try:
        key = tuple((type(v).__name__, v.record_data_bytes()) for v in records if v.user_id == "LASF_Projection")
    except Exception:  # a record laspy cannot serialise: parse without remembering
        return hdr.parse_crs()
    if key not in _CRS_CACHE:
        if len(_CRS_CACHE) >= 64:
            _CRS_CACHE.clear()
        _CRS_CACHE[key] = hdr.parse_crs()
    return _CRS_CACHE[key]


def _read_ascii(path: Path) -> PointCloud:
    """ASCII ``X Y Z [label] [more columns]``, whitespace or comma separated, '#' comments."""
    try:
        with open(path, "r", encoding="utf-8", errors="replace") as fh:
            first = ""
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    first = line
                    break
        delim = "," if "," in first else None
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported below
            data = np.loadtxt(path, delimiter=delim, comments="#", ndmin=2, dtype=np.float64)
    except ValueError as exc:
        hint = ""
        if first and not _numbers_only(first, delim):
            hint = f"; its first line {first.strip()[:40]!r} looks like a header row: remove it or start it with '#'"
        raise DataError(f"input {str(path)!r} is not an ASCII 'X Y Z [label]' file ({_short(str(exc))}){hint}") from None
    if data.size == 0:
        return PointCloud(x=np.empty(0), y=np.empty(0), z=np.empty(0), source=str(path))
    if data.shape[1] < 3:
        raise DataError(f"input {str(path)!r} has {data.shape[1]} columns; an ASCII point file needs X Y Z [label]")
    fields: dict[str, np.ndarray] = {}
    if data.shape[1] == 4:
        # a label that is not a number cannot be kept as one: its point goes with the non-finite ones
        bad_label = ~np.isfinite(data[:, 3])
        data[bad_label, 2] = np.nan
        fields["label"] = np.nan_to_num(data[:, 3]).astype(np.int32)  # ISPRS filter test: 0 bare earth, 1 object
    else:
        for j in range(3, data.shape[1]):
            fields[f"column_{j + 1}"] = data[:, j]
    return PointCloud(x=data[:, 0], y=data[:, 1], z=data[:, 2], fields=fields, source=str(path))


def _numbers_only(line: str, delim) -> bool:
    for token in (line.split(delim) if delim else line.split()):
        try:
            float(token)
        except ValueError:
            return False
    return True


def _short(msg: str) -> str:
    return " ".join(msg.split())[:160]


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------

def write_points(pc: PointCloud, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write LAS/LAZ (by extension), atomically.

    Every dimension of the source file is kept; new fields become classification, return
    numbers etc. when they are standard dimensions of the point format, and extra bytes
    dimensions otherwise. Clouds that did not come from LAS are written as LAS 1.4 point
    format 6 with a WKT CRS.
    """
    path = Path(path)
    if path.suffix.lower() not in LAS_EXTENSIONS:
        raise UsageError(f"output {str(path)!r}: points are written as .las or .laz")
    src = pc.meta.get("_xyz_source")
    if src is None or not _xyz_untouched(pc, src):  # coordinates decoded from a file are finite
        n_bad = len(pc) - int(np.count_nonzero(np.isfinite(pc.x) & np.isfinite(pc.y) & np.isfinite(pc.z)))
        if n_bad:
            raise DataError(f"output {str(path)!r}: {n_bad} of {len(pc)} points have a NaN or infinite coordinate; "
                            "nothing was written (the algorithm that made them has a bug: please report it)")
    with RECORD_LOCK:
        return _write_points_locked(pc, path, overwrite)


def _write_points_locked(pc: PointCloud, path: Path, overwrite: bool) -> Path:
    import laspy

    header = _header_for(pc)
    las, restore = _reuse_record(pc, header)
    if las is None:
        std = set(header.point_format.dimension_names)
        extra = [laspy.ExtraBytesParams(name=n, type=_extra_type(v)) for n, v in pc.fields.items() if n not in std]
        if extra:  # declared before the points exist, so the record array is allocated once
            header.add_extra_dims(extra)
        las = laspy.LasData(header, points=laspy.ScaleAwarePointRecord.zeros(len(pc), header=header))
        las.x, las.y, las.z = pc.x, pc.y, pc.z
        for name, values in pc.fields.items():
            las[name] = values
    # (bounds, counts per return and the GPS time range are filled in by laspy as it writes)
    try:
        with atomic_path(path, overwrite) as tmp:
            las.write(tmp, laz_backend=_laz_backend(len(pc)) if path.suffix.lower() == ".laz" else None)
    finally:
        if restore is not None:
            restore()
    return path


def _xyz_untouched(pc: PointCloud, src) -> bool:
    """Whether x, y, z are still the arrays decoded from the record, unmodified (the same objects,
    and a sample of values equal to the record's: catches edits in place)."""
    if not (pc.x is src[0] and pc.y is src[1] and pc.z is src[2]):
        return False
    rec = src[3]
    n = len(rec)
    if n == 0:
        return True
    i = np.unique(np.linspace(0, n - 1, min(n, 997)).astype(np.int64))
    sample = rec[i]
    return (np.array_equal(np.asarray(sample.x), pc.x[i]) and np.array_equal(np.asarray(sample.y), pc.y[i])
            and np.array_equal(np.asarray(sample.z), pc.z[i]))


def _reuse_record(pc: PointCloud, header):
    """(LasData on the source's own point record, a function restoring that record) — untouched
    dimensions are neither decoded nor encoded again, and the record is not copied: changed
    dimensions are written into it for the write and put back by ``restore()`` (a copy of a 10 M
    point record cost 0.6 s). (None, None) when the record cannot serve (other point format, new
    dimensions)."""
    import laspy

    f = pc.fields
    if not isinstance(f, LazyFields) or len(f.record) != len(pc):
        return None, None
    f.complete()  # a partially decompressed record would write zeros
    rec_fmt = f.record.point_format
    if rec_fmt.id != header.point_format.id or any(n not in rec_fmt.dimension_names for n in f.overrides):
        return None, None
    header.point_format = rec_fmt  # same id, and the record's extra bytes
    header.scales, header.offsets = f.record.scales, f.record.offsets
    record = laspy.ScaleAwarePointRecord(f.record.array, rec_fmt, f.record.scales, f.record.offsets)
    las = laspy.LasData(header, points=record)
    src = pc.meta.get("_xyz_source")
    changed = {}
    if src is None or src[3] is not f.record or not _xyz_untouched(pc, src):
        changed.update({n: np.array(record.array[n]) for n in ("X", "Y", "Z")})
        las.x, las.y, las.z = pc.x, pc.y, pc.z
    for name, values in f.overrides.items():
        changed.setdefault(name, np.array(record[name]))
        las[name] = values

    def restore():
        for name, values in changed.items():
            if name in ("X", "Y", "Z"):
                record.array[name] = values
            else:
                record[name] = values

    return las, restore


LAZ_CHUNK_POINTS = 50_000  # laspy's LAZ chunk size: the unit of parallel compression


def _laz_backend(n_points: int | None = None):
    """lazrs, compressing chunks on all cores when the parallel build is there and the cloud has
    more than one chunk (a single chunk gains nothing from handing it to a thread pool; on AHN3's
    43 k points the serial backend's medians of 15 runs were 54-55 ms against 54-68)."""
    import laspy

    if n_points is not None and n_points <= LAZ_CHUNK_POINTS:
        return laspy.LazBackend.Lazrs
    return laspy.LazBackend.LazrsParallel if laspy.LazBackend.LazrsParallel.is_available() else laspy.LazBackend.Lazrs


def _extra_type(values: np.ndarray):
    dt = np.asarray(values).dtype
    if dt == np.bool_:
        return np.uint8
    return dt


def _header_for(pc: PointCloud):
    import laspy

    src = pc.header
    cls = pc.fields.get("classification")
    needs_wide_class = cls is not None and len(cls) and int(np.max(cls)) > 31
    if src is not None:
        fmt_id = src.point_format.id
        version = str(src.version)
        if needs_wide_class and fmt_id < 6:
            # classes above 31 need the LAS 1.4 formats; keep RGB / NIR if the source had them
            fmt_id = {0: 6, 1: 6, 2: 7, 3: 7, 4: 9, 5: 10}[fmt_id]
            version = "1.4"
        header = laspy.LasHeader(version=version, point_format=fmt_id)
        header.scales = src.scales
        header.offsets = src.offsets
        # keep the source's VLRs; CRS VLRs are rewritten only when the CRS changed (--crs)
        rewrite = pc.crs is not None and not _same_crs(_safe_parse_crs(src), pc.crs)
        drop = {"ExtraBytesVlr"} | (_CRS_VLRS if rewrite else set())
        for vlr in src.vlrs:
            if type(vlr).__name__ not in drop:
                header.vlrs.append(vlr)
        if rewrite:
            _add_crs(header, pc.crs)
        header.system_identifier = src.system_identifier
        header.generating_software = "lidar-toolbox"
        return header
    header = laspy.LasHeader(version="1.4", point_format=6)
    if "creation_date" in pc.meta:
        header.creation_date = pc.meta["creation_date"]
    if len(pc):
        header.offsets = [np.floor(pc.x.min()), np.floor(pc.y.min()), np.floor(pc.z.min())]
    header.scales = [0.001, 0.001, 0.001]
    header.generating_software = "lidar-toolbox"
    if pc.crs is not None:
        _add_crs(header, pc.crs)
    return header


def _same_crs(a, b) -> bool:
    if a is None or b is None:
        return a is b
    try:
        return a == b or a.to_wkt() == b.to_wkt()
    except Exception:
        return False


def _add_crs(header, crs) -> None:
    import laspy

    try:
        header.add_crs(crs)
        return
    except Exception as exc:  # laspy only writes CRSs with an EPSG code: write the WKT ourselves
        log.debug("laspy add_crs failed (%s); writing a WKT VLR", exc)
    header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(crs.to_wkt()))
    if header.version.minor >= 4:
        header.global_encoding.wkt = True
