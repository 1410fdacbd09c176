"""QGIS styles: find a ``.qml`` by name in the style directories, fill in data-dependent values,
write it beside a raster, or embed it in a GeoPackage's ``layer_styles`` table."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np


def find_style(name: str, style_dirs) -> Path | None:
    for d in style_dirs:
        p = Path(d) / f"{name}.qml"
        if p.is_file():
            return p
    return None


def render_style(template: str, values: np.ndarray | None = None) -> str:
    """Replace ``@@MIN@@``, ``@@Q25@@``, ``@@Q50@@``, ``@@Q75@@``, ``@@MAX@@`` with the 2nd, 25th,
    50th, 75th and 98th percentiles of the finite values (a stretch that ignores outliers)."""
    if "@@" not in template:
        return template
    if values is None or not np.isfinite(values).any():
        q = [0.0, 0.25, 0.5, 0.75, 1.0]
    else:
        v = values[np.isfinite(values)]
        q = list(np.percentile(v, [2, 25, 50, 75, 98]))
        if q[4] <= q[0]:
            q = [q[0] + d for d in (0.0, 0.25, 0.5, 0.75, 1.0)]
    for token, value in zip(("MIN", "Q25", "Q50", "Q75", "MAX"), q):
        template = template.replace(f"@@{token}@@", f"{value:.3f}")
    return template


def write_raster_style(raster_path: Path, raster, style_dirs, overwrite: bool = True) -> Path | None:
    """Write ``<raster stem>.qml`` beside the raster (QGIS loads it as the default style)."""
    from .atomic import atomic_path

    style = find_style(raster.style, style_dirs)
    if style is None:
        return None
    band = raster.bands()[0].astype(np.float64)
    band = np.where(raster.valid_mask(), band, np.nan)
    qml = render_style(style.read_text(encoding="utf-8"), band)
    out = raster_path.with_suffix(".qml")
    with atomic_path(out, overwrite=overwrite) as tmp:
        tmp.write_text(qml, encoding="utf-8")
    return out


LAYER_STYLES_DDL = """
CREATE TABLE IF NOT EXISTS layer_styles (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    f_table_catalog TEXT(256),
    f_table_schema TEXT(256),
    f_table_name TEXT(256),
    f_geometry_column TEXT(256),
    styleName TEXT(30),
    styleQML TEXT,
    styleSLD TEXT,
    useAsDefault BOOLEAN,
    description TEXT,
    owner TEXT(30),
    ui TEXT(30),
    update_time DATETIME DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ','now'))
)"""


def embed_layer_styles(gpkg: Path, styles: dict[str, str]) -> None:
    """Embed ``{layer name: QML text}`` as each layer's default style, the way QGIS saves it.

    QGIS looks a layer's default style up with ``f_table_schema = '' AND f_table_name = <layer>
    AND f_geometry_column = <geometry column> ORDER BY useAsDefault DESC, update_time DESC``,
    so the geometry column is read from ``gpkg_geometry_columns`` rather than assumed.
    """
    if not styles:
        return
    con = sqlite3.connect(gpkg)
    try:
        cur = con.cursor()
        geom_cols = dict(cur.execute("SELECT table_name, column_name FROM gpkg_geometry_columns").fetchall())
        cur.execute(LAYER_STYLES_DDL)
        registered = cur.execute("SELECT 1 FROM gpkg_contents WHERE table_name = 'layer_styles'").fetchone()
        if not registered:
            cur.execute(
                "INSERT INTO gpkg_contents (table_name, data_type, identifier, description, last_change) "
                "VALUES ('layer_styles', 'attributes', 'layer_styles', 'QGIS layer styles', "
                "strftime('%Y-%m-%dT%H:%M:%fZ','now'))"
            )
        for layer, qml in styles.items():
            geom = geom_cols.get(layer, "")
            cur.execute("DELETE FROM layer_styles WHERE f_table_name = ? AND f_geometry_column = ?", (layer, geom))
            cur.execute(
                "INSERT INTO layer_styles (f_table_catalog, f_table_schema, f_table_name, f_geometry_column, "
                "styleName, styleQML, styleSLD, useAsDefault, description, owner, ui) "
                "VALUES ('', '', ?, ?, ?, ?, '', 1, ?, '', '')",
                (layer, geom, layer, qml, f"default style of {layer} (lidar-toolbox)"),
            )
        con.commit()
    finally:
        con.close()
