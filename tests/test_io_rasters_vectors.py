"""GeoTIFF (CRS, nodata, COG layout, overviews, sidecar style) and GeoPackage (several layers,
embedded styles that QGIS finds with its own query), and atomic writes."""

import sqlite3

import geopandas as gpd
import numpy as np
import pytest
import rasterio
from affine import Affine
from shapely.geometry import LineString, Point

from toolbox.io.atomic import atomic_path
from toolbox.io.points import parse_crs
from toolbox.io.rasters import Raster, read_raster, write_raster
from toolbox.io.vectors import read_vectors, write_vectors
from toolbox.registry import registry

STYLE_DIRS = registry().style_dirs


def test_geotiff_crs_nodata_overviews_and_style(tmp_path):
    rng = np.random.default_rng(0)
    data = (300 + rng.normal(0, 5, (1500, 1200))).astype(np.float32)
    data[:10, :10] = np.nan
    r = Raster(data, Affine(0.5, 0, 512000, 0, -0.5, 5404000), crs=parse_crs("EPSG:25832"), nodata=float("nan"), style="dtm")
    out = write_raster(r, tmp_path / "dtm.tif", STYLE_DIRS)
    with rasterio.open(out) as ds:
        assert ds.crs.to_epsg() == 25832
        assert np.isnan(ds.nodata)
        assert ds.transform == r.transform
        assert ds.block_shapes[0] == (512, 512)  # tiled
        assert ds.profile["compress"] == "deflate"
        assert len(ds.overviews(1)) >= 1
        assert ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"
        np.testing.assert_array_equal(ds.read(1), data)
    qml = (tmp_path / "dtm.qml").read_text()
    assert "singlebandpseudocolor" in qml and "@@" not in qml
    lo = float(np.nanpercentile(data, 2))
    assert f'value="{lo:.3f}"' in qml
    back = read_raster(out)
    assert back.cell_size == 0.5


def test_small_geotiff_is_one_tile_that_just_covers_it(tmp_path, caplog):
    """One 128-pixel tile (the smallest the COG driver takes without a warning) for a small
    raster, not a 512-pixel tile that is mostly padding."""
    data = np.arange(52 * 40, dtype=np.float32).reshape(40, 52)
    r = Raster(data, Affine(1.0, 0, 512000, 0, -1.0, 5404000), crs=parse_crs("EPSG:25832"), nodata=float("nan"))
    out = write_raster(r, tmp_path / "small.tif")
    with rasterio.open(out) as ds:
        assert ds.block_shapes[0] == (128, 128)
        assert ds.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"
        np.testing.assert_array_equal(ds.read(1), data)
    assert not [rec for rec in caplog.records if rec.levelname in ("WARNING", "ERROR")]


def test_geopackage_layers_with_styles_as_qgis_queries_them(tmp_path):
    crs = parse_crs("EPSG:25832")
    lines = gpd.GeoDataFrame({"votes": [10, 20]}, geometry=[LineString([(0, 0), (1, 1)]), LineString([(0, 1), (1, 0)])], crs=crs)
    pts = gpd.GeoDataFrame({"n_lines": [2]}, geometry=[Point(0.5, 0.5)], crs=crs)
    empty = gpd.GeoDataFrame({"id": np.array([], dtype=np.int64)}, geometry=gpd.GeoSeries([], crs=crs), crs=crs)
    empty.attrs["geometry_type"] = "LineString Z"
    out = write_vectors({"conductors": lines, "crossings": pts, "conductors_3d": empty}, tmp_path / "pl.gpkg", STYLE_DIRS)
    layers = read_vectors(out)
    assert set(layers) == {"conductors", "crossings", "conductors_3d"}
    assert layers["conductors"].crs.to_epsg() == 25832 and len(layers["conductors"]) == 2
    con = sqlite3.connect(out)
    geom_cols = dict(con.execute("SELECT table_name, column_name FROM gpkg_geometry_columns"))
    for layer in ("conductors", "crossings", "conductors_3d"):
        row = con.execute(
            "SELECT styleQML, useAsDefault FROM layer_styles WHERE f_table_schema = '' AND f_table_name = ? "
            "AND f_geometry_column = ? ORDER BY useAsDefault DESC, update_time DESC", (layer, geom_cols[layer])).fetchone()
        assert row is not None, layer
        assert row[1] == 1
        assert row[0] == (STYLE_DIRS[-1] / f"{layer}.qml").read_text()
    cols = [r[1] for r in con.execute("PRAGMA table_info(layer_styles)")]
    assert cols == ["id", "f_table_catalog", "f_table_schema", "f_table_name", "f_geometry_column", "styleName",
                    "styleQML", "styleSLD", "useAsDefault", "description", "owner", "ui", "update_time"]
    assert con.execute("SELECT data_type FROM gpkg_contents WHERE table_name='layer_styles'").fetchone() == ("attributes",)


def test_every_style_is_valid_qgis_xml():
    import xml.etree.ElementTree as ET

    for qml in STYLE_DIRS[-1].glob("*.qml"):
        root = ET.fromstring(qml.read_text().replace("@@", "0"))
        assert root.tag == "qgis" and root.get("version", "").startswith("3."), qml.name


def test_atomic_write_leaves_nothing_on_error(tmp_path):
    target = tmp_path / "out.tif"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half a file")
            raise RuntimeError("crash in the middle of writing")
    assert list(tmp_path.iterdir()) == []


def test_raster_writer_failing_midway_leaves_nothing(tmp_path, monkeypatch):
    import rasterio.shutil

    def broken_copy(src, dst, **kw):
        open(dst, "wb").write(b"partial")
        raise OSError("disk full")

    monkeypatch.setattr(rasterio.shutil, "copy", broken_copy)
    r = Raster(np.zeros((10, 10), np.float32), Affine(1, 0, 0, 0, -1, 10))
    with pytest.raises(OSError):
        write_raster(r, tmp_path / "x.tif")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("user_setting", [None, "FULL"])
def test_geopackage_commits_skip_fsync_unless_the_user_asks(tmp_path, user_setting):
    """SQLite's per-commit sync is off for our (atomically renamed) GeoPackages; a user's own
    OGR_SQLITE_SYNCHRONOUS wins. Checked in a fresh process (GDAL's options are process-wide)."""
    import os
    import subprocess
    import sys

    code = ("import geopandas as gpd, pyogrio; from shapely.geometry import Point; "
            "from toolbox.io.vectors import write_vectors, read_vectors; "
            f"write_vectors({{'p': gpd.GeoDataFrame({{'a': [1]}}, geometry=[Point(0, 0)], crs='EPSG:28992')}}, "
            f"{str(tmp_path / 'v.gpkg')!r}); "
            f"assert len(read_vectors({str(tmp_path / 'v.gpkg')!r})['p']) == 1; "
            "print('SYNC', pyogrio.get_gdal_config_option('OGR_SQLITE_SYNCHRONOUS'))")
    env = {k: v for k, v in os.environ.items() if k != "OGR_SQLITE_SYNCHRONOUS"}
    if user_setting:
        env["OGR_SQLITE_SYNCHRONOUS"] = user_setting
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert f"SYNC {user_setting or False}" in r.stdout  # (pyogrio reads OFF back as False)
