"""Rasters: GeoTIFF through rasterio, written as Cloud Optimized GeoTIFF (tiled, DEFLATE,
overviews) with a QGIS ``.qml`` sidecar so that QGIS opens them styled."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import DataError, UsageError
from .atomic import atomic_path

RASTER_EXTENSIONS = (".tif", ".tiff")


@dataclass
class Raster:
    """A georeferenced grid. ``data`` is (rows, cols) or (bands, rows, cols); ``transform`` an
    ``affine.Affine`` (north-up: the first row is the northern edge); ``nodata`` the fill value
    (NaN allowed for float data); ``style`` the QGIS style name used when it is written."""

    data: np.ndarray
    transform: object
    crs: object | None = None
    nodata: float | None = None
    style: str | None = None
    source: str = ""
    description: str = ""

    @property
    def cell_size(self) -> float:
        return float(abs(self.transform.a))

    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape[-2:]

    def bands(self) -> np.ndarray:
        return self.data if self.data.ndim == 3 else self.data[np.newaxis]

    def valid_mask(self) -> np.ndarray:
        band = self.bands()[0]
        if self.nodata is None:
            return np.isfinite(band) if band.dtype.kind == "f" else np.ones(band.shape, bool)
        if isinstance(self.nodata, float) and np.isnan(self.nodata):
            return ~np.isnan(band)
        return band != self.nodata


def read_raster(path: str | os.PathLike) -> Raster:
    import rasterio
    from rasterio.errors import RasterioIOError

    path = Path(path)
    if not path.exists():
        raise DataError(f"input {str(path)!r} does not exist; check the path")
    try:
        with rasterio.open(path) as ds:
            data = ds.read()
            if data.shape[0] == 1:
                data = data[0]
            return Raster(data=data, transform=ds.transform, crs=ds.crs, nodata=ds.nodata, source=str(path))
    except RasterioIOError as exc:
        raise DataError(f"input {str(path)!r} is not a readable raster ({' '.join(str(exc).split())[:160]})") from None


def write_raster(r: Raster, path: str | os.PathLike, style_dirs=(), overwrite: bool = False) -> Path:
    """Write a Cloud Optimized GeoTIFF atomically, plus ``<name>.qml`` when a style is found."""
    import rasterio
    from rasterio.io import MemoryFile
    from rasterio.shutil import copy as rio_copy

    path = Path(path)
    if path.suffix.lower() not in RASTER_EXTENSIONS:
        raise UsageError(f"output {str(path)!r}: rasters are written as GeoTIFF (.tif)")
    bands = r.bands()
    count, rows, cols = bands.shape
    if rows == 0 or cols == 0:
        raise DataError(f"output {str(path)!r} would be an empty raster; check the input extent")
    profile = {
        "driver": "GTiff", "height": rows, "width": cols, "count": count,
        "dtype": bands.dtype.name, "transform": r.transform,
        "crs": _rio_crs(r.crs), "nodata": r.nodata,
    }
    predictor = 3 if bands.dtype.kind == "f" else 2
    with atomic_path(path, overwrite) as tmp:
        with MemoryFile() as mem:
            with mem.open(**profile) as ds:
                ds.write(bands)
                if r.description:
                    ds.update_tags(DESCRIPTION=r.description)
            with mem.open() as src:
                rio_copy(src, tmp, driver="COG", COMPRESS="DEFLATE", PREDICTOR=predictor,
                         BLOCKSIZE=512, OVERVIEWS="AUTO", RESAMPLING="AVERAGE" if count == 1 else "NEAREST",
                         NUM_THREADS="ALL_CPUS")
    if r.style:
        from .styles import write_raster_style

        write_raster_style(path, r, style_dirs, overwrite=True)
    return path


def _rio_crs(crs):
    if crs is None:
        return None
    from rasterio.crs import CRS as RioCRS

    if isinstance(crs, RioCRS):
        return crs
    return RioCRS.from_wkt(crs.to_wkt())
