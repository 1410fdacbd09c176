"""Rasters: GeoTIFF through rasterio, written as Cloud Optimized GeoTIFF (tiled, DEFLATE,
overviews) with a QGIS ``.qml`` sidecar so that QGIS opens them styled."""

from __future__ import annotations

import os
import uuid
from dataclasses import dataclass, field
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
    _filled: tuple | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def cell_size(self) -> float:
        return float(abs(self.transform.a))

    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape[-2:]

    def bands(self) -> np.ndarray:
        return self.data if self.data.ndim == 3 else self.data[np.newaxis]

    def sample(self, x, y) -> np.ndarray:
        """Bilinear value of band 1 at points x, y (cell centres; north-up grids). Nodata cells take
        the nearest valid value around them, so points at the data's edge still get a height."""
        t = self.transform
        z = self._filled_band()
        r = (t.f - y) / -t.e - 0.5
        c = (x - t.c) / t.a - 0.5
        rows, cols = z.shape
        r = np.clip(r, 0, rows - 1)
        c = np.clip(c, 0, cols - 1)
        r0 = np.minimum(r.astype(np.int64), max(rows - 2, 0))
        c0 = np.minimum(c.astype(np.int64), max(cols - 2, 0))
        fr, fc = r - r0, c - c0
        r1, c1 = np.minimum(r0 + 1, rows - 1), np.minimum(c0 + 1, cols - 1)
        return (z[r0, c0] * (1 - fr) * (1 - fc) + z[r0, c1] * (1 - fr) * fc
                + z[r1, c0] * fr * (1 - fc) + z[r1, c1] * fr * fc)

    def _filled_band(self) -> np.ndarray:
        """Band 1 as float64 with nodata filled from the nearest valid cell; kept while ``data`` is
        the same array (a search samples the same DEM thousands of times)."""
        from scipy import ndimage

        if self._filled is not None and self._filled[0] is self.data:
            return self._filled[1]
        z = np.where(self.valid_mask(), self.bands()[0].astype(np.float64), np.nan)
        if not np.isfinite(z).all():
            bad = ~np.isfinite(z)
            idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
            z = z[tuple(idx)]
        self._filled = (self.data, z)
        return z

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
    # 512-pixel tiles, or one (>= 128, the COG driver's least) just covering a small raster: a
    # 512 x 512 tile that is mostly padding cost 8 ms for a 52 x 52 DTM, more than all the rest
    block = int(min(512, max(128, 1 << int(np.ceil(np.log2(max(rows, cols)))))))
    with atomic_path(path, overwrite) as tmp:
        with MemoryFile() as mem:
            with mem.open(**profile) as ds:
                ds.write(bands)
                if r.description:
                    ds.update_tags(DESCRIPTION=r.description)
            with mem.open() as src:
                rio_copy(src, tmp, driver="COG", COMPRESS="DEFLATE", PREDICTOR=predictor,
                         BLOCKSIZE=block, OVERVIEWS="AUTO", RESAMPLING="AVERAGE" if count == 1 else "NEAREST",
                         NUM_THREADS="ALL_CPUS")
    if r.style:
        from .styles import write_raster_style

        write_raster_style(path, r, style_dirs, overwrite=overwrite)
    return path


def write_image(image, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write an 8-bit picture as PNG, atomically: a (rows, cols[, 3|4]) uint8 array, or a
    :class:`Raster` of uint8 bands, which is georeferenced: a world file (``.wld``) and GDAL's
    ``.png.aux.xml`` with the CRS go beside it, so that QGIS opens it in place over the map."""
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    path = Path(path)
    geo = image if isinstance(image, Raster) else None
    img = np.asarray(geo.data if geo is not None else image)
    if img.dtype != np.uint8:
        raise TypeError("image outputs must be uint8")
    if geo is not None:
        bands = img[np.newaxis] if img.ndim == 2 else img  # a Raster holds (bands, rows, cols)
    else:
        bands = img[np.newaxis] if img.ndim == 2 else np.moveaxis(img, -1, 0)
    sidecars = {".wld": path.with_suffix(".wld"), ".png.aux.xml": path.with_name(path.name + ".aux.xml")}
    with atomic_path(path, overwrite) as tmp:
        options = {}
        if geo is not None:
            options = {"transform": geo.transform, "crs": _rio_crs(geo.crs), "WORLDFILE": "YES"}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(tmp, "w", driver="PNG", width=bands.shape[2], height=bands.shape[1],
                               count=bands.shape[0], dtype="uint8", **options) as ds:
                ds.write(bands)
        # GDAL names the sidecars after the temporary file: they move in with the picture (and a
        # picture written without them must not pick up stale ones of an earlier run)
        from .atomic import current_staging

        staging = current_staging()
        moved = []
        try:
            for ext, final in sidecars.items():
                made = tmp.with_suffix(ext) if ext == ".wld" else tmp.with_name(tmp.name + ".aux.xml")
                if geo is not None and made.exists():
                    if staging is not None:  # renamed with the run's other files
                        staged = made.with_name(f".{final.name}.{uuid.uuid4().hex[:8]}.partial")
                        os.replace(made, staged)
                        staging.add(staged, final)
                    else:
                        os.replace(made, final)
                        moved.append(final)
                else:
                    made.unlink(missing_ok=True)
                    if staging is not None:
                        staging.remove_on_commit(final)
                    else:
                        final.unlink(missing_ok=True)
        except BaseException:
            for f in moved:
                f.unlink(missing_ok=True)
            raise
    return path


def _rio_crs(crs):
    if crs is None:
        return None
    from rasterio.crs import CRS as RioCRS

    if isinstance(crs, RioCRS):
        return crs
    # by its EPSG code when it carries one: GDAL then writes the GeoTIFF keys without identifying
    # the WKT against the PROJ database (5 ms instead of 10-15 ms per file). The code the CRS
    # itself carries, not one searched for: ``to_authority`` searches the whole database when
    # there is none, 150 ms for Autzen's ESRI-style Lambert (more than the rest of its DTM run)
    ident = crs.to_json_dict().get("id") or {}
    if ident.get("authority") == "EPSG":
        return RioCRS.from_epsg(int(ident["code"]))
    return RioCRS.from_wkt(crs.to_wkt())
