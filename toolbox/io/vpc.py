"""Virtual point clouds (``.vpc``): a STAC ItemCollection listing point cloud files, as PDAL's
wrench (``build_vpc``) writes them and QGIS (3.32 and later) opens as one layer.

One STAC Item per file (STAC 1.0.0 with the pointcloud and projection extensions): the file in
``assets`` (``href`` relative to the ``.vpc``, ``./name.laz``), its point count (``pc:count``), its
bounds in its own CRS (``proj:bbox``, ``proj:geometry``) and in WGS 84 (``bbox``, ``geometry``),
and its CRS (``proj:wkt2``, or ``proj:epsg``).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from ..errors import DataError
from .atomic import atomic_path

STAC_VERSION = "1.0.0"
PDAL_TYPES = {"i": "signed", "u": "unsigned", "f": "floating"}  # pc:schemas types, as PDAL names them
EXTENSIONS = ["https://stac-extensions.github.io/pointcloud/v1.0.0/schema.json",
              "https://stac-extensions.github.io/projection/v1.1.0/schema.json"]


@dataclass(frozen=True)
class VpcItem:
    path: str  # resolved against the .vpc's folder
    count: int | None
    bbox: tuple | None  # (minx, miny, minz, maxx, maxy, maxz) in the file's CRS
    crs: str | None  # WKT2 or "EPSG:n"


def is_vpc(path) -> bool:
    return str(path).lower().endswith(".vpc")


def read_vpc(path) -> list[VpcItem]:
    """The files a ``.vpc`` lists, in its order; a file it names that does not exist, or a
    document that is no ItemCollection, is a one-line error."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise DataError(f"input {str(path)!r} is not a readable virtual point cloud ({' '.join(str(exc).split())[:100]}); "
                        "rebuild it (pdal_wrench build_vpc, or QGIS 'Build virtual point cloud')") from None
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection" or not isinstance(doc.get("features"), list):
        raise DataError(f"input {str(path)!r} is not a virtual point cloud (a STAC FeatureCollection of point cloud "
                        "items); rebuild it with pdal_wrench build_vpc")
    items = []
    for i, feat in enumerate(doc["features"]):
        assets = feat.get("assets") if isinstance(feat, dict) else None
        if not isinstance(assets, dict) or not assets:
            raise DataError(f"input {str(path)!r}: item {i} has no assets (the file it stands for); rebuild the .vpc")
        data = next((a for a in assets.values() if "data" in (a.get("roles") or [])), next(iter(assets.values())))
        href = str(data.get("href", ""))
        if "://" in href:
            raise DataError(f"input {str(path)!r}: item {i} points to {href!r}; a survey reads local files: download "
                            "them and build the .vpc over the copies")
        target = Path(href) if Path(href).is_absolute() else (path.parent / href)
        target = Path(os.path.normpath(target))
        if not target.exists():
            raise DataError(f"input {str(path)!r} lists {href!r}, which does not exist at {str(target)!r}; fetch the "
                            "file or rebuild the .vpc")
        props = feat.get("properties") or {}
        crs = props.get("proj:wkt2") or (f"EPSG:{props['proj:epsg']}" if props.get("proj:epsg") else None)
        bbox = props.get("proj:bbox")
        items.append(VpcItem(str(target), props.get("pc:count"), tuple(bbox) if bbox and len(bbox) == 6 else None,
                             crs or None))
    if not items:
        raise DataError(f"input {str(path)!r} lists no file; rebuild it over the survey's files")
    return items


def _wgs84(bbox, crs):
    """The 2D bounds as a WGS 84 polygon and bbox (densified edges), or None without a CRS."""
    if crs is None:
        return None
    from pyproj import Transformer

    try:
        tr = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        x0, y0, x1, y1 = tr.transform_bounds(bbox[0], bbox[1], bbox[3], bbox[4], densify_pts=21)
    except Exception:  # a CRS PROJ cannot take to WGS 84 (engineering, local): no geographic bounds
        return None
    return [x0, y0, bbox[2], x1, y1, bbox[5]], _polygon(x0, y0, x1, y1)


def _polygon(x0, y0, x1, y1) -> dict:
    return {"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]}


def _item(las_path: Path, vpc_dir: Path) -> dict:
    import laspy

    from .points import _safe_parse_crs

    with laspy.open(las_path) as reader:
        hdr = reader.header
        crs = _safe_parse_crs(hdr)
        mins, maxs = hdr.mins, hdr.maxs
        dtype = hdr.point_format.dtype()
        schema = [{"name": n, "type": PDAL_TYPES.get(dtype[n].kind, "unsigned"), "size": dtype[n].itemsize}
                  for n in hdr.point_format.dimension_names if n in dtype.names]
        date = hdr.creation_date
    bbox = [float(mins[0]), float(mins[1]), float(mins[2]), float(maxs[0]), float(maxs[1]), float(maxs[2])]
    geo = _wgs84(bbox, crs)
    href = "./" + Path(os.path.relpath(las_path, vpc_dir)).as_posix()
    props = {"datetime": f"{date.isoformat()}T00:00:00Z" if date else "1970-01-01T00:00:00Z",
             "pc:count": int(hdr.point_count), "pc:type": "lidar", "pc:encoding": "?", "pc:schemas": schema,
             "proj:wkt2": crs.to_wkt() if crs is not None else "", "proj:bbox": bbox,
             "proj:geometry": _polygon(bbox[0], bbox[1], bbox[3], bbox[4])}
    return {"type": "Feature", "stac_version": STAC_VERSION, "stac_extensions": EXTENSIONS, "id": las_path.stem,
            "geometry": geo[1] if geo else props["proj:geometry"], "bbox": geo[0] if geo else bbox,
            "properties": props, "links": [], "assets": {"data": {"href": href, "roles": ["data"]}}}


def write_vpc(path, files: Sequence, overwrite: bool = False) -> Path:
    """Write ``path`` (a ``.vpc``) listing the LAS/LAZ ``files`` (paths), their hrefs relative to it."""
    path = Path(path)
    vpc_dir = path.resolve().parent
    doc = {"type": "FeatureCollection", "features": [_item(Path(f).resolve(), vpc_dir) for f in files]}
    with atomic_path(path, overwrite=overwrite) as tmp:
        Path(tmp).write_text(json.dumps(doc, separators=(",", ":")) + "\n", encoding="utf-8")
    return path
