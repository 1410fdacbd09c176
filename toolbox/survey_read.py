"""Reading a survey's points tile by tile, each point decoded about once.

A tile needs the points of its core and its buffer. Of a COPC file only the octree nodes that
reach the box are decoded. A plain LAS/LAZ file has no spatial index, so a tile could only scan
all of it, and a file that reaches many tiles would be decoded once per tile. Such a file is
therefore *split* first, in one pass (``split_points``): its point records, as they are in the
file, go into scratch files by cell of a grid finer than the tiles (``chunk_cell_size``); a tile
then reads only the cells its box touches, and puts their points back in file order, so that it
holds exactly the points, in the order, that a scan of the file would have given it. This is
lastile's and lidR's ``catalog_retile`` step, done by the survey itself and removed after it.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import DataError

READ_CHUNK_POINTS = 1_000_000
INDEX = "index.json"
CELLS_PER_BOX = 16  # chunk cells across a tile's box: reading whole cells then takes at most (1 + 2/16)² = 1.27x its points


def chunk_cell_size(tile_size: float, buffer: float) -> float:
    """The chunk grid's cell (CRS units): the tile's size over a whole number, so that tile and
    chunk borders coincide, and about 1/16 of the tile's box."""
    m = max(1, int(np.ceil(CELLS_PER_BOX * tile_size / (tile_size + 2 * buffer))))
    return tile_size / m


def _cell_keys(x, y, cell: float) -> np.ndarray:
    ix = np.floor(x / cell).astype(np.int64)
    iy = np.floor(y / cell).astype(np.int64)
    return (ix << 32) ^ (iy & 0xFFFFFFFF)


def _key_name(key: int) -> str:
    ix, iy = int(key) >> 32, int(np.int64(key) & 0xFFFFFFFF)
    iy = iy - (1 << 32) if iy >= 1 << 31 else iy
    return f"{ix}_{iy}"


def split_done(folder: Path, source: Mapping[str, Any], cell: float, stats_cell: float | None = None) -> bool:
    """Whether ``folder`` holds a finished split of ``source`` (a SurveyFile as a dict) on ``cell``
    (and its cell statistics on ``stats_cell`` when asked for)."""
    try:
        idx = json.loads((Path(folder) / INDEX).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (idx.get("source") == [source["path"], source["size"], source["mtime_ns"]] and idx.get("cell") == cell
            and idx.get("done") is True
            and (stats_cell is None or (idx.get("stats_cell") == stats_cell and (Path(folder) / STATS).exists())))


RECORDS, POSITIONS, STATS = "records.bin", "positions.bin", "cells.npz"


@dataclass
class CellStats:
    """Per-cell point statistics of a survey on a north-up raster (``Algorithm.survey_cells``):
    cell borders on multiples of ``cell`` (CRS units), rows from ``north`` down, columns from
    ``west``; a point on a border belongs to the cell east and south of it, as rasterio's
    ``rowcol`` places it. ``count`` points, ``zmin`` / ``zmax`` their lowest and highest z (NaN
    where empty). The units are those a tile's points take (``PointCloud``)."""

    west: float
    north: float
    cell: float
    count: np.ndarray
    zmin: np.ndarray
    zmax: np.ndarray
    horizontal_unit_m: float = 1.0
    vertical_unit_m: float = 1.0

    @classmethod
    def empty(cls, west: float, north: float, cell: float, rows: int, cols: int, **units) -> "CellStats":
        return cls(west, north, cell, np.zeros((rows, cols), np.int64), np.full((rows, cols), np.inf),
                   np.full((rows, cols), -np.inf), **units)

    def add(self, x, y, z) -> None:
        """Count points in, growing the raster when they fall outside it (a header's bounds may lie)."""
        if len(x) == 0:
            return
        c0 = int(np.floor((x.min() - self.west) / self.cell))
        r0 = int(np.floor((self.north - y.max()) / self.cell))
        c1 = int(np.floor((x.max() - self.west) / self.cell))
        r1 = int(np.floor((self.north - y.min()) / self.cell))
        rows, cols = self.count.shape
        grow = (max(0, -r0), max(0, r1 - rows + 1), max(0, -c0), max(0, c1 - cols + 1))
        if any(grow):
            pad = ((grow[0], grow[1]), (grow[2], grow[3]))
            self.count = np.pad(self.count, pad)
            self.zmin = np.pad(self.zmin, pad, constant_values=np.inf)
            self.zmax = np.pad(self.zmax, pad, constant_values=-np.inf)
            self.west -= grow[2] * self.cell
            self.north += grow[0] * self.cell
        rows, cols = self.count.shape
        col = np.floor((x - self.west) / self.cell).astype(np.int64)
        row = np.floor((self.north - y) / self.cell).astype(np.int64)
        flat = row * cols + col
        self.count += np.bincount(flat, minlength=rows * cols).reshape(rows, cols)
        np.minimum.at(self.zmin.reshape(-1), flat, z)
        np.maximum.at(self.zmax.reshape(-1), flat, z)

    def finished(self) -> "CellStats":
        """NaN for the empty cells' heights."""
        empty = self.count == 0
        self.zmin[empty] = np.nan
        self.zmax[empty] = np.nan
        return self

    def save(self, path: Path) -> None:
        tmp = Path(str(path) + ".partial.npz")
        np.savez(tmp, west=self.west, north=self.north, cell=self.cell, count=self.count, zmin=self.zmin,
                 zmax=self.zmax, units=[self.horizontal_unit_m, self.vertical_unit_m])
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> "CellStats":
        with np.load(path) as f:
            hu, vu = (float(v) for v in f["units"])
            return cls(float(f["west"]), float(f["north"]), float(f["cell"]), f["count"], f["zmin"], f["zmax"],
                       hu, vu)

    @classmethod
    def merged(cls, parts: Sequence["CellStats"]) -> "CellStats":
        """One raster over all parts (the same cell; origins on its multiples): counts summed,
        heights the lowest and the highest; the units are the first part's."""
        cell = parts[0].cell
        west = min(p.west for p in parts)
        north = max(p.north for p in parts)
        cols = max(int(round((p.west - west) / cell)) + p.count.shape[1] for p in parts)
        rows = max(int(round((north - p.north) / cell)) + p.count.shape[0] for p in parts)
        out = cls.empty(west, north, cell, rows, cols, horizontal_unit_m=parts[0].horizontal_unit_m,
                        vertical_unit_m=parts[0].vertical_unit_m)
        for p in parts:
            r, c = int(round((north - p.north) / cell)), int(round((p.west - west) / cell))
            h, w = p.count.shape
            window = np.s_[r:r + h, c:c + w]
            out.count[window] += p.count
            out.zmin[window] = np.fmin(out.zmin[window], np.where(p.count > 0, p.zmin, np.inf))
            out.zmax[window] = np.fmax(out.zmax[window], np.where(p.count > 0, p.zmax, -np.inf))
        return out.finished()


def split_points(task: Mapping[str, Any]) -> dict:
    """One pass over a plain LAS/LAZ file (``task["file"]``, a SurveyFile as a dict): its point
    records, grouped by cell of ``task["cell"]``, appended to one scratch file in
    ``task["folder"]`` (``records.bin``: the raw records; ``positions.bin``: each one's position in
    the file), and where each cell's runs lie (``index.json``). One file, not one per cell: on
    the overlay file systems of containers an open costs about a millisecond. Never raises: a
    failure (a truncated or corrupt file) is returned with its reason and leaves no folder; the
    tiles that need the file then read it directly and fail with the same reason."""
    import laspy

    from .io.points import _decode_errors

    t0 = time.perf_counter()
    f, folder, cell = task["file"], Path(task["folder"]), float(task["cell"])
    stats_cell = task.get("stats_cell")
    base = {"tile": task["name"], "pid": os.getpid(), "file": f["path"]}
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    runs: dict[str, list] = {}
    seen = 0
    stats = None
    try:
        with laspy.open(f["path"]) as reader, open(folder / RECORDS, "wb") as rec, open(folder / POSITIONS, "wb") as pos:
            if stats_cell:
                stats = _file_stats(f, reader.header, float(stats_cell), task.get("crs"))
            for chunk in reader.chunk_iterator(READ_CHUNK_POINTS):
                if stats is not None:  # the algorithm's whole-survey summary, from this one decode
                    stats.add(np.asarray(chunk.x), np.asarray(chunk.y), np.asarray(chunk.z))
                keys = _cell_keys(np.asarray(chunk.x), np.asarray(chunk.y), cell)
                order = np.argsort(keys, kind="stable")
                cells, starts = np.unique(keys[order], return_index=True)
                ends = np.r_[starts[1:], len(order)]
                chunk.array[order].tofile(rec)  # the chunk's records, cell after cell
                (order + seen).astype(np.int64).tofile(pos)
                for key, a, b in zip(cells, starts, ends):
                    runs.setdefault(_key_name(key), []).append([seen + int(a), int(b - a)])
                seen += len(chunk)
        if seen != f["count"]:
            raise DataError(f"input {f['path']!r} is truncated: the header promises {f['count']} points, the file "
                            f"holds {seen}; re-download or re-export it")
    except (DataError, *_decode_errors()) as exc:
        shutil.rmtree(folder, ignore_errors=True)
        error = str(exc) if isinstance(exc, DataError) else (
            f"input {f['path']!r} is truncated or corrupt after {seen} points ({' '.join(str(exc).split())[:120]}); "
            "repair or re-download it")
        return {**base, "status": "failed", "error": error, "seconds": round(time.perf_counter() - t0, 3)}
    if stats is not None:
        stats.finished().save(folder / STATS)
    index = {"source": [f["path"], f["size"], f["mtime_ns"]], "cell": cell, "n_points": seen, "cells": runs,
             "stats_cell": stats_cell, "done": True}
    tmp = folder / (INDEX + ".partial")
    tmp.write_text(json.dumps(index), encoding="utf-8")
    os.replace(tmp, folder / INDEX)
    return {**base, "status": "done", "n_decoded_points": seen, "n_cells": len(runs),
            "seconds": round(time.perf_counter() - t0, 3)}


def _file_stats(f: Mapping[str, Any], header, cell: float, crs_wkt) -> CellStats:
    """An empty CellStats over a file's header bounds, in the units its tiles' points take."""
    from .io.points import PointCloud, _apply_crs, parse_crs

    empty = np.empty(0)
    pc = _apply_crs(PointCloud(x=empty, y=empty, z=empty), parse_crs(crs_wkt) if crs_wkt else None, header)
    west = np.floor(f["minx"] / cell) * cell
    north = (np.floor(f["maxy"] / cell) + 1) * cell
    cols = int(np.floor((f["maxx"] - west) / cell)) + 1
    rows = int(np.floor((north - f["miny"]) / cell)) + 1
    return CellStats.empty(float(west), float(north), cell, max(rows, 1), max(cols, 1),
                           horizontal_unit_m=pc.horizontal_unit_m, vertical_unit_m=pc.vertical_unit_m)


def _split_record(reader, folder: Path, box) -> tuple[Any, int]:
    """The records of a split file in the cells that reach ``box``, in file order, and how many
    were read."""
    import laspy

    idx = json.loads((folder / INDEX).read_text(encoding="utf-8"))
    cell = float(idx["cell"])
    bx0, by0, bx1, by1 = box
    hdr = reader.header
    runs = []
    for ix in range(int(np.floor(bx0 / cell)), int(np.floor(bx1 / cell)) + 1):
        for iy in range(int(np.floor(by0 / cell)), int(np.floor(by1 / cell)) + 1):
            runs.extend(idx["cells"].get(f"{ix}_{iy}", ()))
    if not runs:
        return laspy.ScaleAwarePointRecord.empty(header=hdr), 0
    runs.sort()
    merged = [list(runs[0])]
    for a, n in runs[1:]:  # a chunk's cells lie one after the other: read neighbours in one go
        if a == merged[-1][0] + merged[-1][1]:
            merged[-1][1] += n
        else:
            merged.append([a, n])
    dtype = hdr.point_format.dtype()
    size = dtype.itemsize
    with open(folder / RECORDS, "rb") as rec, open(folder / POSITIONS, "rb") as pos:
        raw, where = [], []
        for a, n in merged:
            rec.seek(a * size)
            raw.append(np.fromfile(rec, np.uint8, n * size))
            pos.seek(a * 8)
            where.append(np.fromfile(pos, np.int64, n))
    # records as rows of bytes: numpy gathers those as plain copies, a structured array field by field
    rows = np.concatenate(raw).reshape(-1, size)
    rows = rows[np.argsort(np.concatenate(where), kind="stable")]
    array = rows.view(dtype).reshape(-1)
    return laspy.ScaleAwarePointRecord(array, hdr.point_format, hdr.scales, hdr.offsets), len(array)


def _without_copc_records(header):
    """A copy of a COPC file's header for the tile's outputs: a tile's points are no octree, and
    laspy writes no COPC records."""
    import copy

    out = copy.deepcopy(header)
    for name in ("vlrs", "evlrs"):
        records = getattr(out, name, None)
        if records:
            kept = [v for v in records if getattr(v, "user_id", "") != "copc"]
            records.clear()
            records.extend(kept)
    return out


def read_tile(files: Sequence, tile, buffer: float, crs=None, dims=None, chunk_points: int = READ_CHUNK_POINTS,
              splits: Mapping[str, str] | None = None):
    """The points of the tile and its buffer from ``files`` (SurveyFile), in chunks: memory holds
    what the box keeps plus one chunk. A COPC file gives only the octree nodes that reach the box;
    a file in ``splits`` (path -> folder of ``split_points``) only the cells that reach it; any
    other is scanned. Returns (PointCloud, mask of the points in the core, points decoded from
    the files, points read). ``dims``: the dimensions to keep besides x, y, z (None: all those
    every file has)."""
    import laspy

    from .io.points import PointCloud, _apply_crs, _decode_errors

    bx0, by0, bx1, by1 = box = tile.box(buffer)
    xs, ys, zs, parts = [], [], [], []
    header, names = None, None
    decoded = read = 0
    for f in files:
        seen = 0
        folder = (splits or {}).get(f.path)
        try:
            with (laspy.CopcReader.open(f.path) if f.copc else laspy.open(f.path)) as reader:
                hdr = reader.header
                file_names = [n for n in hdr.point_format.dimension_names if n not in ("X", "Y", "Z")]
                if header is None:
                    header = _without_copc_records(hdr) if f.copc else hdr
                names = file_names if names is None else [n for n in names if n in file_names]
                keep_names = file_names if dims is None else [n for n in file_names if n in dims]
                if f.copc:  # only the octree nodes that reach the box are decoded
                    chunks = [reader.query(bounds=laspy.Bounds(mins=np.array([bx0, by0]), maxs=np.array([bx1, by1])))]
                elif folder is not None:
                    record, n = _split_record(reader, Path(folder), box)
                    chunks, read = [record], read + n
                else:
                    chunks = reader.chunk_iterator(chunk_points)
                for chunk in chunks:
                    seen += len(chunk)
                    x = np.asarray(chunk.x)
                    y = np.asarray(chunk.y)
                    m = (x >= bx0) & (x < bx1) & (y >= by0) & (y < by1)
                    if not m.any():
                        continue
                    xs.append(x[m])
                    ys.append(y[m])
                    zs.append(np.asarray(chunk.z)[m])
                    parts.append({n: np.asarray(chunk[n])[m] for n in keep_names})
        except _decode_errors() as exc:
            raise DataError(f"input {f.path!r} is truncated or corrupt after {seen} points "
                            f"({' '.join(str(exc).split())[:120]}); repair or re-download it") from None
        if folder is not None:
            continue
        decoded += seen
        read += seen
        if not f.copc and seen != f.count:
            raise DataError(f"input {f.path!r} is truncated: the header promises {f.count} points, the file holds "
                            f"{seen}; re-download or re-export it")
    keep = [n for n in (names or []) if dims is None or n in dims]
    cat = (lambda arrs: np.concatenate(arrs)) if xs else (lambda arrs: np.empty(0))
    fields = {n: np.concatenate([p[n] for p in parts]) for n in keep} if parts else {}
    pc = PointCloud(x=cat(xs), y=cat(ys), z=cat(zs), fields=fields, source=f"tile {tile.name}", header=header)
    _apply_crs(pc, crs, header)
    core = (pc.x >= tile.x0) & (pc.x < tile.x1) & (pc.y >= tile.y0) & (pc.y < tile.y1)
    return pc, core, decoded, read
