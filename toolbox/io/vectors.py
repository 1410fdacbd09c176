"""Vectors: GeoPackage through geopandas/pyogrio, several layers per file, each with its QGIS
style embedded so that QGIS opens it styled."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

from ..errors import DataError, UsageError
from .atomic import atomic_path
from .styles import embed_layer_styles, find_style, render_style

VECTOR_EXTENSIONS = (".gpkg",)


def write_vectors(layers: dict, path: str | os.PathLike, style_dirs=(), overwrite: bool = False) -> Path:
    """Write ``{layer name: GeoDataFrame}`` into one GeoPackage, atomically, styles embedded.

    Empty layers are written too (with their geometry type) so that the file's layout does not
    depend on what was found.
    """
    import geopandas as gpd

    path = Path(path)
    if path.suffix.lower() not in VECTOR_EXTENSIONS:
        raise UsageError(f"output {str(path)!r}: vectors are written as GeoPackage (.gpkg)")
    if not layers:
        raise DataError(f"output {str(path)!r}: no layer to write")
    _no_sqlite_fsync()
    styles = {}
    with atomic_path(path, overwrite) as tmp:
        for name, gdf in layers.items():
            if not isinstance(gdf, gpd.GeoDataFrame):
                raise TypeError(f"layer {name!r} is a {type(gdf).__name__}, not a GeoDataFrame")
            kwargs = {}
            if len(gdf) == 0:
                gtype = gdf.attrs.get("geometry_type", "Unknown")
                kwargs["geometry_type"] = gtype
            with warnings.catch_warnings():
                # a cloud without a CRS gives layers without one: the reading step already said
                # so (and how to set it); pyogrio's warning per layer would only repeat it
                warnings.filterwarnings("ignore", message="'crs' was not provided")
                gdf.to_file(tmp, layer=name, driver="GPKG", engine="pyogrio", **kwargs)
            style = find_style(name, style_dirs)
            if style is not None:
                styles[name] = render_style(style.read_text(encoding="utf-8"))
        embed_layer_styles(tmp, styles)
    return path


def _no_sqlite_fsync() -> None:
    """GeoPackage is SQLite, which syncs the file to disk at every commit (a few per layer: 70-80
    ms for the four small power-line layers on the CI machine, 41-49 ms without). The file is
    written under a temporary name and renamed when complete, as every output here, so those
    syncs protect nothing that matters: off, unless the user set OGR_SQLITE_SYNCHRONOUS."""
    import pyogrio

    if pyogrio.get_gdal_config_option("OGR_SQLITE_SYNCHRONOUS") is None:
        pyogrio.set_gdal_config_options({"OGR_SQLITE_SYNCHRONOUS": "OFF"})


def read_vectors(path: str | os.PathLike) -> dict:
    import geopandas as gpd
    import pyogrio

    path = Path(path)
    if not path.exists():
        raise DataError(f"input {str(path)!r} does not exist; check the path")
    try:
        names = [row[0] for row in pyogrio.list_layers(path)]
    except Exception as exc:
        raise DataError(f"input {str(path)!r} is not a readable vector file ({' '.join(str(exc).split())[:160]})") from None
    return {n: gpd.read_file(path, layer=n, engine="pyogrio") for n in names if n != "layer_styles"}
