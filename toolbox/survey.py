"""Survey runs: one algorithm over many LAS/LAZ files taken as ONE survey, cut into tiles.

``toolbox run ALG FILES... --tile-size-m S`` (or :func:`run_survey`):

1. a catalog from the files' headers only (bounds, point counts, CRS; files in different CRSs are
   refused), with a spatial index of the files;
2. tiles of ``S`` on a fixed grid (multiples of ``S`` in the CRS, so that a survey run again, or
   grown, cuts the same tiles), named by their south-west corner; tiles no file reaches are left
   out;
3. each tile is read with a buffer (``--buffer-m``, by default what the algorithm declares with
   ``Algorithm.tile_buffer_m``) from every file that reaches it, in chunks: memory holds one tile
   and its buffer, never a file or the survey. A plain file that several tiles read is first
   split by cell, in one pass, so that each point is decoded once (``survey_read``); of a COPC
   file only the octree nodes that reach the tile are decoded;
4. the algorithm runs on each tile in a worker (a local process pool, or the workers of a
   dask.distributed cluster); the worker drops what lies in the buffer (rasters cropped to the
   tile's cells, vector features kept by the tile whose core holds them, lines clipped to it,
   points outside the core) and writes the tile's results;
5. when every tile is done, the host merges: rasters into one Cloud Optimized GeoTIFF (streamed
   through a VRT, never the whole mosaic in memory), vector layers into one GeoPackage (lines
   cut at tile borders joined, ids renumbered, references followed: ``Output.merge``), point
   outputs stay one LAZ per tile (``OUT/<output>/<tile>.laz``), listed in ``OUT/<output>.vpc``
   (a virtual point cloud: one layer in QGIS). A ``.vpc`` is also read as the files it lists.

The output folder holds ``survey.json``, the manifest: the run's settings and each tile's state.
A rerun with the same settings skips finished tiles (a run killed half-way goes on where it
stopped); a tile whose worker died is retried; a tile that fails (its data, or a bug) is
reported with its reason while the others complete, and nothing is merged until all are done.
The host knows no algorithm: everything above comes from the algorithm's declarations.
"""

from __future__ import annotations

import glob
import json
import logging
import os
import resource
import shutil
import socket
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from . import kernels, progress
from .algorithm import Algorithm, LayerMerge
from .errors import DataError, NothingFound, ToolboxError, UsageError
from .io.vpc import is_vpc, read_vpc, write_vpc
from .survey_exec import LocalPool, _run_dask, _run_local
from .survey_read import STATS, CellStats, chunk_cell_size, read_tile, split_done, split_points

log = logging.getLogger(__name__)

MANIFEST = "survey.json"
TILE_DIR = ".tiles"
CHUNK_DIR = "chunks"  # in TILE_DIR: the plain files split by cell (survey_read), removed after the merge
SURVEY_EXTENSIONS = (".las", ".laz")


# --------------------------------------------------------------------------------------------
# Catalog
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SurveyFile:
    """What the header of one file says (no point is read)."""

    path: str
    minx: float
    miny: float
    maxx: float
    maxy: float
    count: int
    size: int
    mtime_ns: int
    copc: bool = False  # a Cloud Optimized Point Cloud: read by bounds through its octree


@dataclass
class Catalog:
    files: list[SurveyFile]
    crs: Any  # pyproj CRS or None
    horizontal_unit_m: float = 1.0

    def __post_init__(self):
        from shapely import STRtree, box

        self._tree = STRtree([box(f.minx, f.miny, f.maxx, f.maxy) for f in self.files])

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        return (min(f.minx for f in self.files), min(f.miny for f in self.files),
                max(f.maxx for f in self.files), max(f.maxy for f in self.files))

    @property
    def n_points(self) -> int:
        return sum(f.count for f in self.files)

    def files_in(self, box_xy) -> list[SurveyFile]:
        """The files whose header bounds reach the box (x0, y0, x1, y1)."""
        from shapely import box

        hits = self._tree.query(box(*box_xy), predicate="intersects")
        return [self.files[i] for i in sorted(hits)]


def expand_survey_inputs(items: Sequence[str]) -> list[str]:
    """Files, folders (their .las/.laz files), glob patterns and virtual point clouds (``.vpc``: the
    files they list), as one list of files."""
    out: list[str] = []
    for item in items:
        item = str(item)
        p = Path(item)
        if p.is_dir():
            found = sorted(str(q) for q in p.iterdir() if q.is_file() and q.suffix.lower() in SURVEY_EXTENSIONS)
            if not found:
                raise UsageError(f"folder {item!r} holds no .las or .laz file")
            out.extend(found)
        elif any(ch in item for ch in "*?["):
            found = sorted(f for f in glob.glob(item, recursive=True) if Path(f).suffix.lower() in SURVEY_EXTENSIONS)
            if not found:
                raise UsageError(f"pattern {item!r} matches no .las or .laz file")
            out.extend(found)
        elif is_vpc(item) and p.exists():  # a virtual point cloud: the files it lists
            out.extend(v.path for v in read_vpc(item))
        else:
            if not p.exists():
                raise DataError(f"input {item!r} does not exist; check the path")
            if p.suffix.lower() not in SURVEY_EXTENSIONS:
                raise UsageError(f"input {item!r}: a survey run reads LAS/LAZ files (their headers give the "
                                 "bounds) or a .vpc listing them; convert it to LAZ first")
            out.append(item)
    seen, unique = set(), []
    for f in out:
        key = os.path.realpath(f)
        if key not in seen:
            seen.add(key)
            unique.append(f)
    if not unique:
        raise UsageError("a survey run needs at least one LAS/LAZ file")
    return unique


def listed_crs(items: Sequence[str]) -> dict:
    """The CRS that the virtual point clouds among ``items`` give their files (path -> text)."""
    return {v.path: v.crs for item in items if is_vpc(item) and Path(item).exists() for v in read_vpc(item) if v.crs}


def build_catalog(paths: Sequence[str], crs=None, listed: Mapping[str, str] | None = None) -> Catalog:
    """Read every file's header (bounds, count, CRS). Files in different CRSs are an error, unless
    ``crs`` (text or pyproj CRS) says what they all are in; a file whose header has no CRS takes
    the one its ``.vpc`` lists for it (``listed``: path -> CRS text)."""
    import laspy

    from .io.points import _header_crs, check_las_header, crs_units, parse_crs

    user_crs = parse_crs(crs) if isinstance(crs, str) else crs
    files, crss = [], []
    for path in paths:
        try:
            with laspy.open(path) as reader:
                hdr = reader.header
                check_las_header(hdr, path)
                mins, maxs, count = hdr.mins, hdr.maxs, int(hdr.point_count)
                if count and not (np.isfinite(mins[:2]).all() and np.isfinite(maxs[:2]).all()):
                    raise DataError(f"input {path!r}: the LAS header's bounds are not finite, so the survey cannot "
                                    "place it; repair the header (e.g. lasinfo -repair_bb) or re-export the file")
                copc = any(v.user_id == "copc" and v.record_id == 1 for v in hdr.vlrs)
                file_crs = None
                if user_crs is None:
                    try:
                        file_crs = _header_crs(hdr)
                    except Exception:  # malformed CRS records: as if it had none (said below)
                        file_crs = None
                    if file_crs is None and (listed or {}).get(path):
                        file_crs = parse_crs(listed[path])
        except (laspy.errors.LaspyException, OSError, ValueError) as exc:
            raise DataError(f"input {path!r} is not a readable LAS/LAZ file ({' '.join(str(exc).split())[:120]}); "
                            "repair or remove it from the survey") from None
        st = os.stat(path)
        files.append(SurveyFile(str(Path(path).resolve()), float(mins[0]), float(mins[1]), float(maxs[0]),
                                float(maxs[1]), count, st.st_size, st.st_mtime_ns, copc))
        crss.append(file_crs)
    if user_crs is not None:
        survey_crs = user_crs
    else:
        survey_crs = crss[0]
        for path, c in zip(paths, crss):
            if not _same_crs(c, survey_crs):
                raise DataError(
                    f"input {path!r} is in {_crs_name(c)} but {paths[0]!r} is in {_crs_name(survey_crs)}; "
                    "a survey is in one CRS: reproject the files to one (e.g. pdal translate, las2las), or pass "
                    "--crs if the headers are wrong")
    hu = crs_units(survey_crs)[0] if survey_crs is not None else 1.0
    if survey_crs is None:
        log.warning("the survey's files have no CRS; its outputs will have none: pass --crs (e.g. --crs EPSG:28992) "
                    "to set it")
    empty = [f.path for f in files if f.count == 0]
    if len(empty) == len(files):
        raise DataError(f"the survey's {len(files)} file(s) hold no point; check the inputs")
    return Catalog([f for f in files if f.count > 0], survey_crs, hu)


def _same_crs(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a == b


def _crs_name(c) -> str:
    if c is None:
        return "no CRS"
    code = c.to_epsg(min_confidence=90)
    return f"EPSG:{code}" if code else repr(c.name)


# --------------------------------------------------------------------------------------------
# Tiles
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Tile:
    """A tile's core, in the CRS's units: [x0, x1) x [y0, y1)."""

    ix: int
    iy: int
    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def name(self) -> str:
        return f"{_num(self.x0)}_{_num(self.y0)}"

    def box(self, buffer: float = 0.0) -> tuple[float, float, float, float]:
        return (self.x0 - buffer, self.y0 - buffer, self.x1 + buffer, self.y1 + buffer)


def _num(v: float) -> str:
    return f"{v:.0f}" if float(v).is_integer() else f"{v:g}"


def plan_tiles(catalog: Catalog, tile_size: float) -> list[Tile]:
    """Tiles of ``tile_size`` (CRS units) on the grid of its multiples that a file reaches."""
    x0, y0, x1, y1 = catalog.bounds
    i0, i1 = int(np.floor(x0 / tile_size)), int(np.floor(x1 / tile_size))
    j0, j1 = int(np.floor(y0 / tile_size)), int(np.floor(y1 / tile_size))
    n = (i1 - i0 + 1) * (j1 - j0 + 1)
    if n > 1_000_000:
        raise UsageError(f"--tile-size-m: {n:,} tiles over the survey; use larger tiles")
    tiles = []
    for j in range(j0, j1 + 1):
        for i in range(i0, i1 + 1):
            t = Tile(i, j, i * tile_size, j * tile_size, (i + 1) * tile_size, (j + 1) * tile_size)
            # a tile only touched on its far edges holds no point of its half-open core
            if any(f.minx < t.x1 and f.maxx >= t.x0 and f.miny < t.y1 and f.maxy >= t.y0 for f in catalog.files_in(t.box())):
                tiles.append(t)
    return tiles


# --------------------------------------------------------------------------------------------
# Cutting a tile's results to its core
# --------------------------------------------------------------------------------------------

def crop_raster(r, tile: Tile):
    """The cells of ``r`` whose centres lie in the tile's core (a Raster; None if none)."""
    from affine import Affine

    from .io.rasters import Raster

    t = r.transform
    if t.b != 0 or t.d != 0 or t.e >= 0:
        raise DataError("a survey run merges north-up rasters only; this algorithm's raster is rotated")
    rows, cols = r.shape
    c0 = max(int(np.ceil((tile.x0 - t.c) / t.a - 0.5)), 0)
    c1 = min(int(np.ceil((tile.x1 - t.c) / t.a - 0.5)), cols)
    r0 = max(int(np.floor((t.f - tile.y1) / -t.e + 0.5)), 0)
    r1 = min(int(np.floor((t.f - tile.y0) / -t.e + 0.5)), rows)
    if c1 <= c0 or r1 <= r0:
        return None
    data = r.data[..., r0:r1, c0:c1]
    shifted = Affine(t.a, 0.0, t.c + c0 * t.a, 0.0, t.e, t.f + r0 * t.e)
    return Raster(np.ascontiguousarray(data), shifted, crs=r.crs, nodata=r.nodata,
                  style=r.style, source=r.source, description=r.description)


def clip_polyline(coords: np.ndarray, box) -> list[tuple[np.ndarray, bool, bool]]:
    """Pieces of a polyline (n x 2 or n x 3; z interpolated) inside a closed box, each with
    whether its start and its end were cut by the box (the line goes on outside)."""
    x0, y0, x1, y1 = box
    pieces, cur, cut_start = [], None, False
    for i in range(len(coords) - 1):
        p, q = coords[i], coords[i + 1]
        d = q - p
        t0, t1 = 0.0, 1.0
        ok = True
        for num, den in ((p[0] - x0, -d[0]), (x1 - p[0], d[0]), (p[1] - y0, -d[1]), (y1 - p[1], d[1])):
            if den == 0:
                if num < 0:
                    ok = False
                    break
                continue
            t = num / den
            if den < 0:
                t0 = max(t0, t)
            else:
                t1 = min(t1, t)
        if not ok or t0 > t1:
            if cur is not None:
                pieces.append((np.array(cur), cut_start, True))
                cur = None
            continue
        a, b = p + t0 * d, p + t1 * d
        if cur is None or t0 > 0:
            if cur is not None:
                pieces.append((np.array(cur), cut_start, True))
            cur, cut_start = [a, b], t0 > 0
        else:
            cur.append(b)
        if t1 < 1:
            pieces.append((np.array(cur), cut_start, True))
            cur = None
    if cur is not None:
        pieces.append((np.array(cur), cut_start, False))
    return [(c, s, e) for c, s, e in pieces if len(c) >= 2 and np.hypot(*(c[-1, :2] - c[0, :2])) > 0]


def cut_layer(gdf, tile: Tile, dissolve: bool = False):
    """The features of a layer this tile owns: points in its core, polygons whose representative
    point is in it (with ``dissolve``: polygons clipped to it), lines clipped to it (columns
    ``_piece``: the feature's row, ``_cut0`` / ``_cut1``: whether the piece's start / end was cut
    at the core's border; a clipped polygon's ``_cut0``: whether it was)."""
    import geopandas as gpd
    from shapely.geometry import LineString, box

    x0, y0, x1, y1 = tile.box()
    core = box(x0, y0, x1, y1)

    def inside(x, y):
        return (x >= x0) & (x < x1) & (y >= y0) & (y < y1)

    rows, geoms, pieces, cuts0, cuts1 = [], [], [], [], []
    for i, g in enumerate(gdf.geometry):
        if g is None or g.is_empty:
            continue
        kind = g.geom_type
        if kind in ("LineString", "MultiLineString"):
            parts = [g] if kind == "LineString" else list(g.geoms)
            for part in parts:
                for coords, c0, c1 in clip_polyline(np.asarray(part.coords), (x0, y0, x1, y1)):
                    rows.append(i)
                    geoms.append(LineString(coords))
                    pieces.append(i)
                    cuts0.append(c0)
                    cuts1.append(c1)
            continue
        if dissolve and kind in ("Polygon", "MultiPolygon") and not core.contains(g):
            part = g.intersection(core)
            for piece in getattr(part, "geoms", [part]):
                if piece.geom_type == "Polygon" and piece.area > 0:
                    rows.append(i)
                    geoms.append(piece)
                    pieces.append(i)
                    cuts0.append(True)
                    cuts1.append(False)
            continue
        p = g if kind == "Point" else g.representative_point()
        if inside(p.x, p.y):
            rows.append(i)
            geoms.append(g)
            pieces.append(i)
            cuts0.append(False)
            cuts1.append(False)
    out = gdf.drop(columns=gdf.geometry.name).iloc[rows].reset_index(drop=True)
    out = gpd.GeoDataFrame(out, geometry=gpd.GeoSeries(geoms, crs=gdf.crs), crs=gdf.crs)
    out["_piece"] = np.asarray(pieces, np.int64)
    out["_cut0"] = np.asarray(cuts0, bool)
    out["_cut1"] = np.asarray(cuts1, bool)
    return out


# --------------------------------------------------------------------------------------------
# One tile, in a worker
# --------------------------------------------------------------------------------------------

def _peak_rss_mb() -> float:
    """This process's own peak resident memory. VmHWM, not ru_maxrss: ru_maxrss survives fork
    and exec, so a run started by a process that once held 9 GB reported 9 GB itself."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return round(int(line.split()[1]) / 1024.0, 1)  # kB
    except (OSError, ValueError, IndexError):
        pass
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)  # KiB on Linux


def _task_points(task: Mapping[str, Any], tile: Tile):
    """The points of a task's tile and buffer (``read_tile`` on the task's files, splits, CRS)."""
    from .io.points import parse_crs

    crs = parse_crs(task["crs"]) if task.get("crs") else None
    return read_tile([SurveyFile(**f) for f in task["files"]], tile, task["buffer"], crs=crs, dims=task.get("dims"),
                     splits=task.get("splits"))


def run_tile(task: Mapping[str, Any]) -> dict:
    """Run the algorithm on one tile and write the tile's results; never raises (a failure is
    returned with its reason). ``task`` is a plain dict, so that a local process and a Dask
    worker on another machine run the same thing."""
    t0 = time.perf_counter()
    name = Tile(**task["tile"]).name
    base = {"tile": name, "pid": os.getpid(), "host": socket.gethostname()}
    try:
        progress.set_quiet(True)
        kernels.set_arch(task.get("arch"))
        from .memory import tune_allocator
        from .registry import rediscover
        from .runner import Context, _as_result

        tune_allocator()
        reg = rediscover(task.get("entry_points"))
        alg = reg.get(task["algorithm"])
        tile = Tile(**task["tile"])
        pc, core, decoded, read = _task_points(task, tile)
        stats = {"n_points": int(len(pc)), "n_core_points": int(core.sum()), "n_decoded_points": decoded,
                 "n_read_points": read,
                 "read_s": round(time.perf_counter() - t0, 3)}
        if not core.any():
            return {**base, "status": "empty", "stats": stats, "outputs": {}, "layer_types": {},
                    "peak_rss_mb": _peak_rss_mb(), "seconds": round(time.perf_counter() - t0, 3)}
        ctx = Context(reg, alg.id, quiet=True, requested=frozenset(task["requested"]))
        t1 = time.perf_counter()
        result = _as_result(alg.run({task["input"]: pc}, dict(task["params"]), ctx), alg)
        stats["compute_s"] = round(time.perf_counter() - t1, 3)
        stats.update({k: v for k, v in {**ctx.stats, **result.stats}.items() if isinstance(v, (int, float, str, bool))})
        written, layer_types = _write_tile_outputs(alg, result.outputs, task, tile, core)
        return {**base, "status": "done", "stats": stats, "outputs": written, "layer_types": layer_types,
                "peak_rss_mb": _peak_rss_mb(), "seconds": round(time.perf_counter() - t0, 3)}
    except NothingFound as exc:  # a tile without buildings, without ground: as a tile without points
        return {**base, "status": "empty", "reason": str(exc), "stats": {}, "outputs": {}, "layer_types": {},
                "peak_rss_mb": _peak_rss_mb(), "seconds": round(time.perf_counter() - t0, 3)}
    except ToolboxError as exc:
        error = str(exc)
    except MemoryError:
        error = "ran out of memory; use a smaller --tile-size-m or fewer --workers"
    except Exception as exc:  # a plugin's bug on one tile must not stop the others
        error = f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"
    return {**base, "status": "failed", "error": error, "stats": {}, "outputs": {}, "layer_types": {},
            "peak_rss_mb": _peak_rss_mb(), "seconds": round(time.perf_counter() - t0, 3)}


def _write_tile_outputs(alg: Algorithm, outputs: Mapping[str, Any], task, tile: Tile, core) -> tuple[dict, dict]:
    from .io.points import write_points
    from .io.rasters import write_raster
    from .io.vectors import write_vectors

    kinds = {o.name: o.kind for o in alg.outputs}
    tile_dir = Path(task["tile_dir"]) / tile.name
    tile_dir.mkdir(parents=True, exist_ok=True)
    written, layer_types = {}, {}
    for name, value in outputs.items():
        if value is None or name not in task["outputs"]:
            continue
        kind = kinds[name]
        if kind == "raster":
            part = crop_raster(value, tile)
            if part is None:
                continue
            path = tile_dir / f"{name}.tif"
            write_raster(part, path, overwrite=True)
        elif kind == "vector":
            layers = {}
            rules = next((o.merge for o in alg.outputs if o.name == name), None) or {}
            for layer, gdf in value.items():
                layers[layer] = cut_layer(gdf, tile, dissolve=bool(rules.get(layer) and rules[layer].dissolve))
                gtype = gdf.attrs.get("geometry_type") or (gdf.geom_type.iloc[0] if len(gdf) else "Unknown")
                layer_types[f"{name}:{layer}"] = gtype
                if len(layers[layer]) == 0:
                    layers[layer].attrs["geometry_type"] = gtype
            path = tile_dir / f"{name}.gpkg"
            write_vectors(layers, path, overwrite=True)
        elif kind == "points":
            folder = Path(task["outputs"][name])
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / f"{tile.name}.laz"
            if len(value) == len(core):  # the input's points, with their new classes
                kept = value.subset(core)
            else:  # points the algorithm made (cell centroids, fitted points): by where they lie
                kept = value.subset((value.x >= tile.x0) & (value.x < tile.x1) & (value.y >= tile.y0) &
                                    (value.y < tile.y1))
            write_points(kept, path, overwrite=True)
        elif kind == "json":
            path = tile_dir / f"{name}.json"
            from .runner import _json_default

            tmp = path.with_suffix(".json.partial")
            tmp.write_text(json.dumps(value, default=_json_default), encoding="utf-8")
            os.replace(tmp, path)
        else:  # images are pictures of one run; a survey has no single picture to give
            continue
        written[name] = str(path)
    return written, layer_types


# --------------------------------------------------------------------------------------------
# Merging
# --------------------------------------------------------------------------------------------

def merge_rasters(paths: Sequence[Path], out: Path, style_name: str | None, style_dirs, overwrite: bool) -> dict:
    """Per-tile rasters (same cell size and CRS, no overlap) into one COG, streamed through a VRT."""
    import rasterio
    from rasterio.shutil import copy as rio_copy

    from .io.atomic import atomic_path
    from .io.rasters import Raster

    metas = []
    for p in paths:
        with rasterio.open(p) as ds:
            metas.append((str(Path(p).resolve()), ds.transform, ds.width, ds.height, ds.count, ds.dtypes[0], ds.nodata, ds.crs))
    a = metas[0][1].a
    e = metas[0][1].e
    if any(abs(m[1].a - a) > 1e-9 * abs(a) or abs(m[1].e - e) > 1e-9 * abs(e) for m in metas):
        raise DataError("the tiles' rasters have different cell sizes; the algorithm's raster grid must not depend on "
                        "the tile")
    west = min(m[1].c for m in metas)
    north = max(m[1].f for m in metas)
    east = max(m[1].c + m[2] * a for m in metas)
    south = min(m[1].f + m[3] * e for m in metas)
    cols, rows = int(round((east - west) / a)), int(round((south - north) / e))
    count, dtype, nodata, crs = metas[0][4], metas[0][5], metas[0][6], metas[0][7]
    gdal_type = {"float32": "Float32", "float64": "Float64", "uint8": "Byte", "int16": "Int16", "uint16": "UInt16",
                 "int32": "Int32", "uint32": "UInt32"}[dtype]
    bands = []
    for b in range(1, count + 1):
        sources = []
        for path, t, w, h, *_ in metas:
            xoff, yoff = (t.c - west) / a, (t.f - north) / e
            sources.append(f'<SimpleSource><SourceFilename relativeToVRT="0">{_xml(path)}</SourceFilename>'
                           f'<SourceBand>{b}</SourceBand><SrcRect xOff="0" yOff="0" xSize="{w}" ySize="{h}"/>'
                           f'<DstRect xOff="{xoff:.6f}" yOff="{yoff:.6f}" xSize="{w}" ySize="{h}"/></SimpleSource>')
        nd = "" if nodata is None else f"<NoDataValue>{'nan' if np.isnan(nodata) else repr(float(nodata))}</NoDataValue>"
        bands.append(f'<VRTRasterBand dataType="{gdal_type}" band="{b}">{nd}{"".join(sources)}</VRTRasterBand>')
    srs = f"<SRS>{_xml(crs.to_wkt())}</SRS>" if crs is not None else ""
    vrt = (f'<VRTDataset rasterXSize="{cols}" rasterYSize="{rows}">{srs}'
           f"<GeoTransform>{west!r}, {a!r}, 0.0, {north!r}, 0.0, {e!r}</GeoTransform>{''.join(bands)}</VRTDataset>")
    vrt_path = out.with_name(f".{out.stem}.mosaic.vrt")
    vrt_path.write_text(vrt, encoding="utf-8")
    try:
        predictor = 3 if np.dtype(dtype).kind == "f" else 2
        with atomic_path(out, overwrite) as tmp:
            with rasterio.open(vrt_path) as src:
                rio_copy(src, tmp, driver="COG", COMPRESS="DEFLATE", PREDICTOR=predictor, BLOCKSIZE=512,
                         OVERVIEWS="AUTO", RESAMPLING="AVERAGE" if count == 1 else "NEAREST", NUM_THREADS="ALL_CPUS")
            if style_name:  # (read from the file written: under a staged run its final name comes later)
                from .io.styles import write_raster_style

                with rasterio.open(tmp) as ds:  # the style's stretch from a reduced read, not the mosaic
                    k = max(1, int(np.ceil(max(ds.width, ds.height) / 2048)))
                    sample = ds.read(1, out_shape=(max(ds.height // k, 1), max(ds.width // k, 1)))
                write_raster_style(out, Raster(sample, None, nodata=nodata, style=style_name), style_dirs)
    finally:
        vrt_path.unlink(missing_ok=True)
    return {"width": cols, "height": rows, "cell_size": float(abs(a)), "tiles": len(metas)}


def _xml(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def merge_layers(per_tile: Sequence[tuple[str, dict]], rules: Mapping[str, LayerMerge] | None, layer_types: Mapping[str, str],
                 crs=None, horizontal_unit_m: float = 1.0) -> dict:
    """``[(tile, {layer: cut GeoDataFrame})]`` into ``{layer: GeoDataFrame}``: pieces of lines
    joined where rules say so, ids renumbered over the survey, references followed."""
    import geopandas as gpd
    import pandas as pd

    rules = dict(rules or {})
    names = list(dict.fromkeys(n for _, layers in per_tile for n in layers))
    # layers holding ids first, so that the layers referring to them can follow
    order = sorted(names, key=lambda n: 0 if rules.get(n) and rules[n].id_field else 1)
    id_maps: dict[str, dict] = {}
    merged = {}
    for name in order:
        rule = rules.get(name, LayerMerge())
        frames = []
        for tile, layers in per_tile:
            g = layers.get(name)
            if g is not None and len(g):
                frames.append(g.assign(_tile=tile))
        if not frames:
            empty = gpd.GeoDataFrame({}, geometry=gpd.GeoSeries([], crs=crs), crs=crs)
            empty.attrs["geometry_type"] = layer_types.get(name, "Unknown")
            merged[name] = empty
            continue
        df = gpd.GeoDataFrame(pd.concat(frames, ignore_index=True), geometry=frames[0].geometry.name, crs=frames[0].crs)
        if rule.join and df.geom_type.isin(["LineString"]).all():
            df = _join_pieces(df, rule)
        elif rule.dissolve and df.geom_type.isin(["Polygon"]).all():
            df = _dissolve_pieces(df, rule, horizontal_unit_m)
        else:
            df["_members"] = [[(t, p)] for t, p in zip(df["_tile"], df["_piece"])]
        # a deterministic order, whatever order the tiles finished in
        first = np.array([g.coords[0][:2] if g.geom_type in ("LineString", "Point") else g.representative_point().coords[0]
                          for g in df.geometry])
        idx = np.lexsort((first[:, 1].round(3), first[:, 0].round(3)))
        df = df.iloc[idx].reset_index(drop=True)
        if rule.id_field and rule.id_field in df.columns:
            id_map = {}
            for new, members in enumerate(df["_members"]):
                olds = df["_old_ids"].iat[new] if "_old_ids" in df.columns else [df[rule.id_field].iat[new]] * len(members)
                for (tile, _), old in zip(members, olds):
                    id_map.setdefault((tile, int(old)), new)
            id_maps[name] = id_map
            df[rule.id_field] = np.arange(len(df), dtype=np.int64)
        for fld, target in rule.refs.items():
            if fld in df.columns and target in id_maps:
                df[fld] = _follow_refs(df[fld], df["_members"], id_maps[target])
        df = df.drop(columns=[c for c in df.columns if str(c).startswith("_")])
        df.attrs["geometry_type"] = layer_types.get(name, "Unknown")
        merged[name] = df
    return {n: merged[n] for n in names}


def _follow_refs(values, members, id_map):
    out = []
    for v, mem in zip(values, members):
        tile = mem[0][0]
        if isinstance(v, str):
            ids = [id_map.get((tile, int(s))) for s in v.split(",") if s.strip() != ""]
            out.append(",".join(str(i) for i in sorted(i for i in ids if i is not None)))
        else:
            out.append(-1 if v is None or (isinstance(v, float) and np.isnan(v)) else id_map.get((tile, int(v)), -1))
    return out


def _dissolve_pieces(df, rule: LayerMerge, horizontal_unit_m: float):
    """Clipped polygons (``_cut0``) of different tiles that meet at a core border become one
    feature, their union; the others stay as they are."""
    import geopandas as gpd
    import shapely
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    geoms = df.geometry.to_numpy()
    tiles = df["_tile"].to_numpy()
    cut = np.flatnonzero(df["_cut0"].to_numpy(bool))
    a, b = shapely.STRtree(geoms[cut]).query(geoms[cut], predicate="dwithin", distance=rule.join_tolerance_m)
    keep = (a < b) & (tiles[cut[a]] != tiles[cut[b]])
    n = len(df)
    graph = coo_matrix((np.ones(int(keep.sum())), (cut[a[keep]], cut[b[keep]])), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    areas = shapely.area(geoms)
    rows = []
    for g in np.unique(group):
        members = np.flatnonzero(group == g)
        union = _union_closed(geoms[members], rule.join_tolerance_m) if len(members) > 1 else geoms[members[0]]
        for part in getattr(union, "geoms", [union]):  # pieces that still do not meet stay apart
            own = [m for m in members if len(members) == 1 or geoms[m].intersects(part)] or list(members)
            rows.append(_dissolved_row(df, rule, own, part, horizontal_unit_m, areas))
    return gpd.GeoDataFrame(rows, geometry="geometry", crs=df.crs)


def _dissolved_row(df, rule: LayerMerge, members, union, horizontal_unit_m: float, areas) -> dict:
    """One dissolved feature: the largest piece's fields, those ``rule.combine`` names combined."""
    base = members[int(np.argmax(areas[members]))]
    return _merged_row(df, rule, members, base, union, {"area_m2": round(float(union.area) * horizontal_unit_m ** 2, 2)},
                       combine=bool(df["_cut0"].iat[base]))  # a whole feature keeps its own fields


def _merged_row(df, rule: LayerMerge, members, base: int, geometry, measured: Mapping[str, float],
                combine: bool = True) -> dict:
    """The row of a feature merged from pieces ``members``: the ``base`` piece's fields, those
    ``rule.combine`` names from the pieces (``min`` / ``max`` / ``sum``) or ``measured`` on the
    merged geometry (``length``, ``area_m2``), and the bookkeeping the ids' renumbering follows."""
    tiles = df["_tile"].to_numpy()
    row = df.iloc[base].drop(labels=[df.geometry.name]).to_dict()
    for fld, how in (rule.combine.items() if combine else ()):
        if how in measured:
            row[fld] = measured[how]
        elif fld in df.columns and how in ("min", "max", "sum"):
            vals = df[fld].iloc[members].to_numpy(dtype=float)
            row[fld] = float({"min": np.nanmin, "max": np.nanmax, "sum": np.nansum}[how](vals)) \
                if np.isfinite(vals).any() else np.nan
    row["_members"] = [(tiles[i], int(df["_piece"].iat[i])) for i in members]
    if rule.id_field and rule.id_field in df.columns:
        row["_old_ids"] = [int(df[rule.id_field].iat[i]) for i in members]
    row["geometry"] = geometry
    return row


def _union_closed(pieces, gap: float):
    """The union of polygon pieces; where they do not touch, closed over the gaps of up to ``gap``
    that made them neighbours (each tile drew its piece from part of the object, so their borders
    may miss by that much), square corners kept."""
    import shapely

    union = shapely.union_all(pieces)
    if union.geom_type == "Polygon":
        return union
    return shapely.buffer(shapely.union_all(shapely.buffer(pieces, gap, join_style="mitre")), -gap,
                          join_style="mitre")


def _join_pieces(df, rule: LayerMerge):
    """Join line pieces whose cut ends meet (mutual nearest within the tolerance, from different
    tiles, going on in the same direction)."""
    import geopandas as gpd
    from scipy.spatial import cKDTree
    from shapely.geometry import LineString

    coords = [np.asarray(g.coords) for g in df.geometry]
    tiles = df["_tile"].to_numpy()
    # ends meet in 3D where the lines have heights: wires stacked over one another stay apart
    dim = 3 if all(c.shape[1] == 3 for c in coords) else 2
    # every cut end: (piece, 0 = start / 1 = end)
    ends, pts, dirs = [], [], []
    for i, c in enumerate(coords):
        for which, cut in ((0, df["_cut0"].iat[i]), (1, df["_cut1"].iat[i])):
            if not cut:
                continue
            p, q = (c[0], c[1]) if which == 0 else (c[-1], c[-2])
            d = (p - q)[:2]  # pointing out of the piece, across the border
            ends.append((i, which))
            pts.append(p[:dim])
            dirs.append(d / max(np.hypot(*d), 1e-12))
    partner: dict = {}
    if ends:
        pts, dirs = np.asarray(pts), np.asarray(dirs)
        tree = cKDTree(pts)
        pairs = []
        for k, (i, _) in enumerate(ends):
            for m in tree.query_ball_point(pts[k], rule.join_tolerance_m):
                # from another tile, the other piece going on the opposite way
                if m > k and tiles[ends[m][0]] != tiles[i] and float(dirs[k] @ dirs[m]) < -0.95:
                    pairs.append((float(np.linalg.norm(pts[m] - pts[k])), k, m))
        # closest first, each end once: lines that coincide in plan (wires stacked over one another
        # in a 2D layer) meet a tile border at one point, and every piece still finds a partner
        free = np.ones(len(ends), bool)
        for _, k, m in sorted(pairs):
            if free[k] and free[m]:
                free[k] = free[m] = False
                partner[ends[k]] = ends[m]
                partner[ends[m]] = ends[k]
    rows, seen = [], set()
    lengths = np.array([np.hypot(*np.diff(c[:, :2], axis=0).T).sum() for c in coords])
    for start in range(len(coords)):
        if start in seen:
            continue
        # walk to one free end of the chain
        i, came_in = start, 0
        visited = {start}
        while (i, came_in) in partner:
            j, w = partner[(i, came_in)]
            if j in visited:
                break
            visited.add(j)
            i, came_in = j, 1 - w
        # from there, collect the chain in order
        chain, i, enter = [], i, came_in
        while True:
            chain.append((i, enter))
            seen.add(i)
            out_end = 1 - enter
            nxt = partner.get((i, out_end))
            if nxt is None or nxt[0] in seen:
                break
            i, enter = nxt
        parts = [coords[i] if enter == 0 else coords[i][::-1] for i, enter in chain]
        line = parts[0]
        for p in parts[1:]:
            mid = (line[-1] + p[0]) / 2
            line = np.vstack([line[:-1], mid[None, :], p[1:]])
        members = [i for i, _ in chain]
        base = members[int(np.argmax(lengths[members]))]
        rows.append(_merged_row(df, rule, members, base, LineString(line),
                                {"length": float(np.hypot(*np.diff(line[:, :2], axis=0).T).sum())}))
    return gpd.GeoDataFrame(rows, geometry="geometry", crs=df.crs)


# --------------------------------------------------------------------------------------------
# The survey run
# --------------------------------------------------------------------------------------------

def remove_leftovers(folders) -> int:
    """Remove the temporary files (``.NAME.*.partial*``) that a run killed mid-write left in its
    folders (the tiles' folders included); returns how many."""
    n = 0
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            continue
        for p in list(folder.rglob(".*.partial*")):
            try:
                if p.is_dir():
                    shutil.rmtree(p)
                else:
                    p.unlink()
                n += 1
            except OSError:
                pass
    if n:
        log.info("removed %d temporary files an earlier, interrupted run left", n)
    return n


def _write_json_atomic(path: Path, data) -> None:
    tmp = path.with_name(f".{path.name}.partial")
    tmp.write_text(json.dumps(data, indent=1, default=str), encoding="utf-8")
    os.replace(tmp, path)


def run_survey(algorithm_id: str, inputs: Sequence[str], output_dir, params: Mapping[str, Any] | None = None, *,
               tile_size_m: float, buffer_m: float | None = None, workers: int | None = None, scheduler=None,
               outputs: Mapping[str, str] | None = None, overwrite: bool = False, crs: str | None = None,
               reg=None) -> dict:
    """Run one algorithm over ``inputs`` (files, folders, globs) as one survey, tile by tile:
    ``plan_survey`` (catalog, tiles, manifest, tasks), ``execute_survey`` (the tiles on a local pool
    or a Dask cluster), ``merge_survey`` (the tiles' outputs into the survey's), as lidR's catalog
    engine separates them.

    ``scheduler``: a dask.distributed address (``tcp://host:8786``) or Client; otherwise a local
    pool of ``workers`` processes (default: all cores). Returns the report (as ``--json`` prints);
    ``report["n_failed"]`` says whether any tile failed (then nothing is merged).
    """
    from .registry import registry

    t_start = time.perf_counter()
    reg = reg or registry()
    plan = plan_survey(reg.get(algorithm_id), inputs, output_dir, params, tile_size_m=tile_size_m, buffer_m=buffer_m,
                       outputs=outputs, overwrite=overwrite, crs=crs, entry_points=reg.entry_points)
    t_tiles = time.perf_counter()
    execution = execute_survey(plan, workers=workers, scheduler=scheduler)
    t_merge = time.perf_counter()
    failed, written = merge_survey(plan, reg.style_dirs)
    t_end = time.perf_counter()
    return survey_report(plan, execution, failed, written, {
        "catalog": round(t_tiles - t_start, 3), "tiles": round(t_merge - t_tiles, 3),
        "merge": round(t_end - t_merge, 3), "total": round(t_end - t_start, 3)})


@dataclass
class SurveyPlan:
    """What ``plan_survey`` decided: the tiles to run (``tasks``) and where everything goes."""

    alg: Any
    values: dict  # the validated parameters
    crs_given: Any
    out: Path
    wanted: list  # the outputs written
    paths: dict  # output name -> path
    catalog: Any
    tiles: list
    skipped: list  # tiles an earlier run finished
    tasks: list  # one per tile to run
    state: dict  # the manifest
    manifest_path: Path
    tile_size_m: float
    buffer_m: float  # used
    buffer_declared_m: float | None
    splits: list  # plain files to split before the tiles run (``split_points`` tasks)
    summaries: list  # tiles whose ``Algorithm.survey_summary`` gives the survey's values (``run_summary`` tasks)
    #: the split pass's per-cell statistics that give the survey's values instead (``Algorithm.survey_cells``):
    #: one file per input, or None
    cell_stats: list | None = None


def plan_survey(alg, inputs: Sequence[str], output_dir, params: Mapping[str, Any] | None, *, tile_size_m: float,
                buffer_m: float | None, outputs: Mapping[str, str] | None, overwrite: bool, crs,
                entry_points) -> SurveyPlan:
    """Check the request, read the catalog from the headers, cut the tiles, resume or start the
    manifest, and describe each tile still to run as a task (plain data, for any worker)."""
    from .io.atomic import check_writable

    values = alg.validate_params(params or {})
    point_inputs = [i for i in alg.inputs if not i.optional]
    if len(point_inputs) != 1 or point_inputs[0].kind != "points" or point_inputs[0].multiple:
        raise UsageError(f"{alg.id} cannot run as a survey (--tile-size-m): that needs an algorithm with one point "
                         "cloud input")
    spec = point_inputs[0]
    if not (tile_size_m > 0 and np.isfinite(tile_size_m)):
        raise UsageError(f"--tile-size-m {tile_size_m}: give a positive size in metres, e.g. 500")
    if buffer_m is not None and not (buffer_m >= 0 and np.isfinite(buffer_m)):
        raise UsageError(f"--buffer-m {buffer_m}: give a size in metres, 0 or more")
    named, kinds, wanted, out, paths = _survey_outputs(alg, output_dir, outputs)

    files = expand_survey_inputs(inputs)
    catalog = build_catalog(files, crs, listed_crs(inputs))
    from .io.atomic import make_folder

    make_folder(out)  # (once the inputs are known to be readable: a refused run makes nothing)
    hu = catalog.horizontal_unit_m
    declared = alg.buffer_m(values)
    buffer_used_m = float(buffer_m if buffer_m is not None else (declared or 0.0))
    if buffer_m is None and declared is None:
        log.warning("%s declares no tile buffer; tiles see no point beyond their border (set --buffer-m)", alg.id)
    tiles = plan_tiles(catalog, tile_size_m / hu)
    settings = {
        "algorithm": alg.id, "version": alg.version, "parameters": values, "tile_size_m": tile_size_m,
        "buffer_m": buffer_used_m, "crs": catalog.crs.to_wkt() if catalog.crs is not None else None,
        "files": [[f.path, f.size, f.mtime_ns] for f in catalog.files],
        "outputs": sorted(paths), "output_paths": {k: str(v) for k, v in sorted(paths.items())},
    }
    manifest_path = out / MANIFEST
    tile_dir = out / TILE_DIR
    state = None
    if manifest_path.exists():
        try:
            state = json.loads(manifest_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            state = None
        if state is not None and json.loads(json.dumps(state.get("settings"), default=str)) != \
                json.loads(json.dumps(settings, default=str)):
            if not overwrite:
                raise UsageError(f"{str(out)!r} holds a survey run with other settings ({_what_differs(state.get('settings') or {}, settings)}); "
                                 "pass --overwrite to start it again, or choose another folder")
            state = None
    if state is None:
        for o in wanted:  # a fresh run: finished outputs of an earlier one must not be mistaken for its own
            p = paths[o.name]
            if o.kind != "points":
                check_writable(p, overwrite)
        if tile_dir.exists():
            import shutil

            shutil.rmtree(tile_dir)
        state = {"settings": settings, "tiles": {}, "merged": False}
    state["settings"] = settings
    tile_dir.mkdir(exist_ok=True)
    remove_leftovers([out, tile_dir, *{paths[o.name] for o in wanted if o.kind == "points"}])

    def done_before(t: Tile) -> bool:
        rec = state["tiles"].get(t.name)
        if not rec or rec.get("status") not in ("done", "empty"):
            return False
        return all(Path(p).exists() for p in rec.get("outputs", {}).values())

    skipped = [t for t in tiles if done_before(t)]
    todo = [t for t in tiles if not done_before(t)]
    dims = None if any(o.kind == "points" for o in wanted) else spec.dims
    base_task = {
        "algorithm": alg.id, "params": values, "input": spec.name, "buffer": buffer_used_m / hu,
        "crs": catalog.crs.to_wkt() if catalog.crs is not None else None, "dims": list(dims) if dims is not None else None,
        "tile_dir": str(tile_dir.resolve()), "requested": sorted(n for n in named if n in kinds),
        "outputs": {o.name: str(paths[o.name].resolve()) for o in wanted}, "arch": kernels.requested_arch(),
        "entry_points": entry_points,
    }
    tasks = []
    for t in todo:
        box = t.box(buffer_used_m / hu)
        tasks.append({**base_task, "name": t.name, "tile": asdict(t), "files": [asdict(f) for f in catalog.files_in(box)]})
    # the survey's values from the split pass where every input is split (one decode), else from
    # each tile's own read
    from_cells = (alg.survey_cells is not None and alg.survey_cell_summary is not None and bool(tasks)
                  and "survey_values" not in state and not any(f.copc for f in catalog.files))
    stats_cell = alg.survey_cells(values, hu) if from_cells else None
    summaries = [] if from_cells else plan_summaries(alg, catalog, tiles, tasks, state, base_task,
                                                     buffer_used_m / hu, spec)
    splits, cell_stats = plan_splits(catalog, tasks + summaries, tile_dir / CHUNK_DIR,
                                     chunk_cell_size(tile_size_m / hu, buffer_used_m / hu), stats_cell,
                                     base_task["crs"])
    if skipped:
        log.info("%d of %d tiles were done by an earlier run; skipping them", len(skipped), len(tiles))

    return SurveyPlan(alg, values, crs, out, wanted, paths, catalog, tiles, skipped, tasks, state, manifest_path,
                      tile_size_m, buffer_used_m, declared, splits, summaries, cell_stats)


def plan_summaries(alg, catalog: Catalog, tiles, tasks: list[dict], state: dict, base_task: dict, buffer: float,
                   spec) -> list[dict]:
    """The ``run_summary`` tasks (one per tile) of an algorithm that takes values from its whole
    input (``Algorithm.survey_summary``); none when an earlier run of the same survey found them
    (its values are given to the tasks instead)."""
    if alg.survey_summary is None or not tasks:
        return []
    if "survey_values" in state:
        for task in tasks:
            task["params"] = {**task["params"], **(state["survey_values"] or {})}
        return []
    # every tile's share, the finished ones' too: the values must be those of the whole survey
    return [{**base_task, "name": f"summary {t.name}", "tile": asdict(t),
             "files": [asdict(f) for f in catalog.files_in(t.box(buffer))],
             "dims": list(spec.dims or ())}  # x, y, z and what the input declares
            for t in tiles]


def plan_splits(catalog: Catalog, tasks: list[dict], folder: Path, cell: float, stats_cell: float | None = None,
                crs_wkt: str | None = None) -> tuple[list[dict], list[Path] | None]:
    """The plain (not COPC) files that more than one tile reads are split once (survey_read),
    rather than scanned by every tile: each tile task names the folders it reads them from.
    With ``stats_cell`` every file is split, and gives its ``CellStats`` on that cell on the way.
    Returns the ``split_points`` tasks not done by an earlier run, and the statistics' files."""
    users: dict[str, int] = {}
    for task in tasks:
        for f in task["files"]:
            if not f["copc"]:
                users[f["path"]] = users.get(f["path"], 0) + 1
    least = 0 if stats_cell else 1
    folders = {f.path: folder / f"{i:05d}" for i, f in enumerate(catalog.files)
               if not f.copc and users.get(f.path, 0) > least}
    for task in tasks:
        task["splits"] = {f["path"]: str(folders[f["path"]]) for f in task["files"] if f["path"] in folders}
    splits = []
    for f in catalog.files:
        if f.path in folders and not split_done(folders[f.path], asdict(f), cell, stats_cell):
            splits.append({"name": f"split {Path(f.path).name}", "file": asdict(f), "folder": str(folders[f.path]),
                           "cell": cell, "stats_cell": stats_cell, "crs": crs_wkt})
    return splits, ([folders[f.path] / STATS for f in catalog.files] if stats_cell else None)


def _survey_outputs(alg, output_dir, outputs: Mapping[str, str] | None):
    """The outputs a survey run writes and their paths (a folder, with named outputs where the
    user put them); a picture of one run or a file as the folder is refused."""
    named = dict(outputs or {})
    kinds = {o.name: o.kind for o in alg.outputs}
    for n in named:
        if n not in kinds:
            raise UsageError(f"{alg.id} has no output {n!r}; its outputs: {', '.join(sorted(kinds))}")
        if kinds[n] == "image":
            raise UsageError(f"{alg.id}'s {n!r} is a picture of one run; a survey run does not make it (drop it)")
    wanted = [o for o in alg.outputs if o.kind != "image" and (not o.optional or o.name in named)]
    out = Path(output_dir)
    if out.suffix.lower() in (".tif", ".gpkg", ".laz", ".las", ".json"):
        raise UsageError(f"-o {str(out)!r}: a survey run writes into a folder (its outputs and survey.json); give a "
                         "folder")
    if out.exists() and not out.is_dir():
        raise UsageError(f"-o {str(out)!r} is a file; a survey run writes into a folder")
    paths = {}
    for o in wanted:
        if o.name in named:
            paths[o.name] = Path(named[o.name])
        else:
            paths[o.name] = out / (o.name if o.kind == "points" else o.name + o.extension)
    return named, kinds, wanted, out, paths


def execute_survey(plan: SurveyPlan, *, workers: int | None = None, scheduler=None) -> dict:
    """Run the plan's tasks (a local pool of ``workers`` or the Dask ``scheduler``), recording each
    tile's result in the manifest as it comes; a progress bar on a terminal."""
    alg, state, manifest_path, tiles, skipped, tasks = (plan.alg, plan.state, plan.manifest_path, plan.tiles,
                                                        plan.skipped, plan.tasks)
    worker_peaks: dict = {}
    counts = {"done": 0, "failed": 0, "empty": 0}
    running: set = set()
    bar = progress.bar(total=len(tiles), desc=f"{alg.id} survey", unit="tile", leave=True)
    bar.update(len(skipped))

    def on_start(name):
        running.add(name)
        bar.set_postfix_str(f"done {counts['done'] + counts['empty']}, failed {counts['failed']}, running {len(running)}")

    def on_result(res: dict):
        running.discard(res["tile"])
        prev = state["tiles"].get(res["tile"], {})
        res = dict(res)
        res["attempts"] = prev.get("attempts", 0) + 1
        state["tiles"][res["tile"]] = res
        counts[res["status"]] += 1
        if res.get("pid") is not None:
            key = f"{res.get('host')}:{res['pid']}"
            worker_peaks[key] = max(worker_peaks.get(key, 0.0), res.get("peak_rss_mb", 0.0))
        if res["status"] == "failed":
            log.error("tile %s: %s", res["tile"], res.get("error"))
        state["merged"] = False
        _write_json_atomic(manifest_path, state)
        bar.set_postfix_str(f"done {counts['done'] + counts['empty']}, failed {counts['failed']}, running {len(running)}")
        bar.update(1)

    _write_json_atomic(manifest_path, state)
    cluster = None
    n_workers = max(1, min(workers or os.cpu_count() or 1, max(len(tasks), len(plan.splits), len(plan.summaries))))
    with LocalPool(n_workers) as pools:  # one pool for the three phases: its workers start once
        t0 = time.perf_counter()
        split = _split_files(plan, n_workers, scheduler, pools)
        t_split = time.perf_counter() - t0
        _survey_values(plan, n_workers, scheduler, pools)
        t_values = time.perf_counter() - t0 - t_split
        if tasks:
            if scheduler is not None:
                cluster = _run_dask(tasks, scheduler, on_result, on_start, fn=run_tile)
                n_workers = cluster["n_workers"]
            else:
                n_workers = max(1, min(n_workers, len(tasks)))
                _run_local(tasks, n_workers, on_result, on_start, fn=run_tile, pools=pools)
        elif scheduler is None:
            n_workers = None
    bar.close()

    return {"scheduler": cluster["address"] if cluster else None, "workers": n_workers,
            "worker_peak_rss_mb": worker_peaks, "split": {**split, "seconds": round(t_split, 3)},
            "survey_values_s": round(t_values, 3)}


def _survey_values(plan: SurveyPlan, workers: int, scheduler, pools) -> None:
    """Phase two: the algorithm's values from the whole survey (``Algorithm.survey_summary`` of
    every tile, summed, through ``survey_values``), given to every tile and kept in the manifest.
    If a tile's summary fails (its data), the tiles keep their own values: that tile fails too,
    and nothing is merged."""
    if plan.cell_stats is not None:
        _survey_values_from_cells(plan)
        return
    if not plan.summaries:
        return
    results: list[dict] = []
    if scheduler is not None:
        _run_dask(plan.summaries, scheduler, results.append, fn=run_summary)
    else:
        _run_local(plan.summaries, max(1, min(workers, len(plan.summaries))), results.append, fn=run_summary,
                   pools=pools)
    if any(r.get("status") != "done" for r in results) or len(results) != len(plan.summaries):
        log.warning("the survey's %s values could not be computed (a tile's data failed); each tile takes its own",
                    plan.alg.id)
        return
    sums: dict = {}
    for r in sorted(results, key=lambda r: r["tile"]):  # integers: the order does not matter, but keep one
        for k, v in r["sums"].items():
            sums[k] = sums.get(k, 0) + v
    _give_survey_values(plan, sums, "the tiles' summaries")


def _survey_values_from_cells(plan: SurveyPlan) -> None:
    """The survey's values from the split pass's per-cell statistics (``Algorithm.survey_cells``);
    if a file could not be split, the tiles keep their own values (those reading it fail)."""
    if not plan.cell_stats:  # the algorithm has no value to find for these parameters
        return
    missing = [p for p in plan.cell_stats if not Path(p).exists()]
    if missing:
        log.warning("the survey's %s values could not be computed (%d files not split); each tile takes its own",
                    plan.alg.id, len(missing))
        return
    stats = CellStats.merged([CellStats.load(p) for p in plan.cell_stats])
    _give_survey_values(plan, dict(plan.alg.survey_cell_summary(stats, plan.values)), "the split pass")


def _give_survey_values(plan: SurveyPlan, sums: dict, source: str) -> None:
    values = dict(plan.alg.survey_values(sums, plan.values, plan.catalog.horizontal_unit_m)) if sums else {}
    plan.state["survey_values"] = values
    plan.state["survey_sums"] = sums
    plan.state["survey_values_from"] = source
    _write_json_atomic(plan.manifest_path, plan.state)
    for task in plan.tasks:
        task["params"] = {**task["params"], **values}


def run_summary(task: Mapping[str, Any]) -> dict:
    """One tile's ``Algorithm.survey_summary`` (its core's share of the survey's values); never
    raises."""
    name = task["name"]
    try:
        progress.set_quiet(True)
        from .registry import rediscover

        alg = rediscover(task.get("entry_points")).get(task["algorithm"])
        tile = Tile(**task["tile"])
        pc, _, _, _ = _task_points(task, tile)
        sums = alg.survey_summary(pc, (tile.x0, tile.y0, tile.x1, tile.y1), dict(task["params"]))
        return {"tile": name, "status": "done", "sums": dict(sums)}
    except Exception as exc:  # its tile fails the same way, and says so
        return {"tile": name, "status": "failed", "error": f"{type(exc).__name__}: {' '.join(str(exc).split())[:200]}"}


def _split_files(plan: SurveyPlan, workers: int, scheduler, pools) -> dict:
    """Phase one: the plan's plain files split by cell, on the same pool or cluster as the tiles.
    A file that fails to split is read directly by its tiles (which then fail with its reason)."""
    results: list[dict] = []
    if plan.splits:
        bar = progress.bar(total=len(plan.splits), desc="splitting files", unit="file", leave=False)

        def on_result(res):
            results.append(res)
            bar.update(1)

        if scheduler is not None:
            _run_dask(plan.splits, scheduler, on_result, fn=split_points)
        else:
            _run_local(plan.splits, max(1, min(workers, len(plan.splits))), on_result, fn=split_points, pools=pools)
        bar.close()
    failed = {r["file"] for r in results if r.get("status") != "done" and "file" in r}
    failed |= {t["file"]["path"] for t in plan.splits if t["name"] in {r["tile"] for r in results if "file" not in r}}
    for path in failed:
        log.warning("%s could not be split (%s); its tiles read it whole",
                    path, next((r.get("error") for r in results if r.get("file") == path), "its worker died"))
    for task in plan.tasks + plan.summaries:
        task["splits"] = {p: d for p, d in task.get("splits", {}).items() if p not in failed}
    done = [r for r in results if r.get("status") == "done"]
    return {"n_files": len(done), "n_decoded_points": sum(r["n_decoded_points"] for r in done)}


def merge_survey(plan: SurveyPlan, style_dirs) -> tuple[list, dict]:
    """The tiles' outputs merged into the survey's when no tile failed (all together, or none);
    returns (the failed tiles, the outputs written)."""
    alg, wanted, paths, tiles, state, catalog = plan.alg, plan.wanted, plan.paths, plan.tiles, plan.state, plan.catalog
    manifest_path = plan.manifest_path
    failed = [{"tile": n, "error": r.get("error")} for n, r in sorted(state["tiles"].items())
              if r.get("status") == "failed" and n in {t.name for t in tiles}]
    written = {}
    if not failed:
        from .io.atomic import staged_outputs

        with staged_outputs() as staging:  # the merged outputs appear together, or none of them
            written = _merge_outputs(alg, wanted, paths, tiles, state, catalog, style_dirs, overwrite=True)
            staging.commit()
        state["merged"] = True
        _write_json_atomic(manifest_path, state)
        shutil.rmtree(manifest_path.parent / TILE_DIR / CHUNK_DIR, ignore_errors=True)
    return failed, written


def survey_report(plan: SurveyPlan, execution: dict, failed: list, written: dict, timings: dict) -> dict:
    """The run's report (as ``--json`` prints)."""
    alg, values, catalog, tiles, state, crs = plan.alg, plan.values, plan.catalog, plan.tiles, plan.state, plan.crs_given
    recs = [state["tiles"][t.name] for t in tiles if t.name in state["tiles"]]
    return {
        "algorithm": alg.id, "plugin": alg.plugin, "version": alg.version,
        # an auto parameter is chosen by each tile (its value is in the tile's stats in the manifest)
        "parameters": {k: ("auto" if v is None and alg.parameter(k).allow_auto else v) for k, v in values.items()},
        "survey": {"n_files": len(catalog.files), "n_points": catalog.n_points, "bounds": catalog.bounds,
                   "crs": _crs_name(catalog.crs), "crs_given": crs if crs is None or isinstance(crs, str) else
                   _crs_name(crs), "tile_size_m": plan.tile_size_m, "buffer_m": plan.buffer_m,
                   "buffer_declared_m": plan.buffer_declared_m},
        "survey_values": state.get("survey_values"), "survey_values_from": state.get("survey_values_from"),
        "n_tiles": len(tiles), "n_done": sum(r.get("status") in ("done", "empty") for r in recs),
        "n_skipped": len(plan.skipped), "n_empty": sum(r.get("status") == "empty" for r in recs), "n_failed": len(failed),
        "failed": failed, "outputs": written, "manifest": str(plan.manifest_path),
        "execution": {**execution, "driver_peak_rss_mb": _peak_rss_mb()},
        "timings_s": timings,
    }


def _what_differs(old: Mapping, new: Mapping) -> str:
    keys = [k for k in new if json.dumps(old.get(k), default=str) != json.dumps(new.get(k), default=str)]
    return ", ".join(keys) + " differ" if keys else "other settings"


def _merge_outputs(alg: Algorithm, wanted, paths, tiles, state, catalog, style_dirs, overwrite: bool) -> dict:
    from .io.vectors import read_vectors, write_vectors

    written = {}
    recs = [(t.name, state["tiles"][t.name]) for t in tiles if state["tiles"].get(t.name, {}).get("status") == "done"]
    for o in wanted:
        parts = [(name, r["outputs"][o.name]) for name, r in recs if o.name in r.get("outputs", {})]
        target = paths[o.name]
        if o.kind == "raster":
            if not parts:
                raise DataError(f"no tile gave a {o.name!r} raster; the survey holds no data for it")
            info = merge_rasters([Path(p) for _, p in parts], target, o.style, style_dirs, overwrite)
            written[o.name] = {"path": str(target), "kind": "raster", **info}
        elif o.kind == "vector":
            per_tile = [(name, read_vectors(p)) for name, p in parts]
            types = {}
            for _, r in recs:
                for key, gtype in r.get("layer_types", {}).items():
                    out_name, layer = key.split(":", 1)
                    if out_name == o.name:
                        types.setdefault(layer, gtype)
            layers = merge_layers(per_tile, o.merge, types, crs=catalog.crs,
                                  horizontal_unit_m=catalog.horizontal_unit_m)
            if not layers:
                import geopandas as gpd

                layers = {n: gpd.GeoDataFrame({}, geometry=gpd.GeoSeries([], crs=catalog.crs), crs=catalog.crs)
                          for n in types}
                for n, g in layers.items():
                    g.attrs["geometry_type"] = types[n]
            write_vectors(layers, target, style_dirs=style_dirs, overwrite=overwrite)
            written[o.name] = {"path": str(target), "kind": "vector", "layers": {n: int(len(g)) for n, g in layers.items()}}
        elif o.kind == "points":
            # one layer in QGIS (and one input to PDAL's wrench or a later survey): the tiles' files as a .vpc
            vpc = write_vpc(Path(target).with_suffix(".vpc"), [p for _, p in parts], overwrite=True) if parts else None
            written[o.name] = {"path": str(target), "kind": "points", "files": len(parts), "vpc": str(vpc) if vpc else None,
                               "n_points": sum(int(state["tiles"][n]["stats"].get("n_core_points", 0)) for n, _ in parts)}
        elif o.kind == "json":
            data = {name: json.loads(Path(p).read_text(encoding="utf-8")) for name, p in parts}
            _write_json_atomic(target, {"tiles": data})
            written[o.name] = {"path": str(target), "kind": "json", "tiles": len(data)}
    return written


def split_file(path, out_dir, nx: int, ny: int, overlap: float = 0.0) -> list[Path]:
    """Write one LAS/LAZ file as ``nx`` x ``ny`` files of equal extent (as a survey is delivered),
    each keeping every dimension and the header's CRS; ``overlap`` (CRS units) widens each file
    so that neighbours share points, as flight strips do. Returns the files written."""
    from .io.points import read_points, write_points

    pc = read_points(path)
    x0, y0, x1, y1 = pc.bounds()
    xs = np.linspace(x0, x1, nx + 1)
    ys = np.linspace(y0, y1, ny + 1)
    xs[-1] = ys[-1] = np.inf
    out_dir = Path(out_dir)
    written = []
    for j in range(ny):
        for i in range(nx):
            m = (pc.x >= xs[i] - overlap) & (pc.x < xs[i + 1] + overlap) & \
                (pc.y >= ys[j] - overlap) & (pc.y < ys[j + 1] + overlap)
            p = out_dir / f"{Path(path).stem}_{i}_{j}{Path(path).suffix}"
            write_points(pc.subset(m), p, overwrite=True)
            written.append(p)
    return written
