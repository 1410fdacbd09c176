"""Building outlines by the method's raster route (Borowiec, METHODS.md §3): a building mask on a
grid, its edge pixels (the mask minus its erosion), and the outline regularised to the building's
dominant direction (the strongest 2D Hough line of its edge pixels): the building's points are
rasterised again in a frame turned to that direction, where the grid's own edges give straight
walls and right angles, and the outline is turned back. Pure functions on arrays."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def mask_grid(x, y, cell: float, pad: int = 2):
    """(west, north, rows, cols) of a grid over the points with ``pad`` empty cells around."""
    west = np.floor(x.min() / cell) * cell - pad * cell
    north = np.ceil(y.max() / cell) * cell + pad * cell
    cols = int(np.ceil((x.max() - west) / cell)) + pad + 1
    rows = int(np.ceil((north - y.min()) / cell)) + pad + 1
    return west, north, rows, cols


def rasterise(x, y, west, north, rows, cols, cell) -> np.ndarray:
    m = np.zeros((rows, cols), bool)
    c = np.clip(((x - west) / cell).astype(np.int64), 0, cols - 1)
    r = np.clip(((north - y) / cell).astype(np.int64), 0, rows - 1)
    m[r, c] = True
    return m


def clean_mask(mask: np.ndarray, close_cells: int = 1) -> np.ndarray:
    """Gaps between scan lines closed, enclosed holes (courtyards stay: they touch no hole test
    unless enclosed by roof) filled."""
    if close_cells > 0:
        mask = ndimage.binary_closing(np.pad(mask, close_cells), iterations=close_cells)[
            close_cells:-close_cells, close_cells:-close_cells] | mask
    return ndimage.binary_fill_holes(mask)


def edge_pixels(mask: np.ndarray, erosions: int = 1) -> np.ndarray:
    """The method's edge image: the mask minus its erosion."""
    return mask & ~ndimage.binary_erosion(mask, iterations=erosions, border_value=0)


def dominant_direction(lines) -> float:
    """Direction (radians, 0..π/2: walls at right angles are one direction) of the strongest
    lines: the vote-weighted circular mean of their angles folded to 90°."""
    if not len(lines):
        return 0.0
    ang = np.array([a for a, _ in lines]) % (np.pi / 2)
    w = np.array([v for _, v in lines], float)
    # around the strongest line only: a wing at another angle, or a crown against the wall, would
    # pull a mean of all lines off every wall
    d = np.angle(np.exp(4j * (ang - ang[np.argmax(w)]))) / 4
    near = np.abs(d) <= np.radians(10.0)
    z = (w[near] * np.exp(4j * ang[near])).sum()
    return float(np.angle(z) / 4 % (np.pi / 2))


def refine_direction(x, y, direction: float, search_deg: float = 6.0, step_deg: float = 0.1,
                     min_fill: float = 0.8) -> float:
    """The direction within ``search_deg`` of ``direction`` whose turned bounding box of the points
    is smallest: walls bound a building's points, so its box is tightest along them. A small
    building's edge image has few pixels, and their grid staircase pulls its Hough lines towards
    the grid's own axes."""
    from scipy.spatial import ConvexHull

    pts = np.column_stack([x, y])
    if len(pts) >= 3:
        try:
            pts = pts[ConvexHull(pts).vertices]
        except Exception:  # collinear points: no hull, the box test still works on all of them
            pass
    cand = direction + np.radians(np.arange(-search_deg, search_deg + step_deg / 2, step_deg))
    c, s = np.cos(cand)[:, None], np.sin(cand)[:, None]
    u = c * pts[:, 0] + s * pts[:, 1]
    v = -s * pts[:, 0] + c * pts[:, 1]
    area = np.ptp(u, axis=1) * np.ptp(v, axis=1)
    # only a building that fills its box (a rectangle, nearly) is bounded by its walls this way;
    # a triangle or a crescent keeps the Hough direction
    from shapely.geometry import MultiPoint

    if MultiPoint(pts).convex_hull.area < min_fill * area.min():
        return float(direction % (np.pi / 2))
    return float(cand[np.argmin(area)] % (np.pi / 2))


def regular_outline(x, y, direction: float, cell: float, close_cells: int = 1, min_area: float = 0.0):
    """Outline polygon of points rasterised in a frame turned by ``direction``: walls along the
    direction and across it are straight, corners right-angled; returns a shapely (Multi)Polygon
    in the points' frame, or None."""
    import shapely
    from rasterio import features
    from shapely import affinity
    from shapely.geometry import shape

    c, s = np.cos(-direction), np.sin(-direction)
    u = c * x - s * y
    v = s * x + c * y
    west, north, rows, cols = mask_grid(u, v, cell)
    m = clean_mask(rasterise(u, v, west, north, rows, cols, cell), close_cells)
    # one-cell spurs and notches are noise at this size: an opening, then a closing
    square = np.ones((3, 3), bool)
    m = ndimage.binary_closing(ndimage.binary_opening(m, square), square)
    m = ndimage.binary_fill_holes(m)
    from affine import Affine

    t = Affine(cell, 0, west, 0, -cell, north)
    polys = [shape(g) for g, val in features.shapes(m.astype(np.uint8), mask=m, transform=t) if val == 1]
    polys = [p for p in polys if p.area >= min_area]
    if not polys:
        return None
    geom = shapely.union_all(polys)
    geom = shapely.simplify(geom, 0.5 * cell)
    # the outline runs along cell edges, outside the outermost points by half a cell on average;
    # a wall lies half a point spacing beyond them (as a Voronoi cell's edge)
    spacing = np.sqrt(geom.area / len(x)) if len(x) else 0.0
    geom = geom.buffer(-0.5 * max(cell - spacing, 0.0), join_style="mitre")
    if geom.is_empty:
        return None
    if stair_share(geom, 2.5 * cell) > 0.3:
        # walls that follow no direction (a curved facade): the grid would give them stairs, so
        # the outline is the points' own concave hull
        hull = shapely.concave_hull(shapely.MultiPoint(np.column_stack([u, v])), ratio=0.15)
        geom = shapely.simplify(hull, 0.5 * cell) if hull.area >= min_area else geom
    return affinity.rotate(geom, direction, origin=(0, 0), use_radians=True)


def stair_share(geom, short: float) -> float:
    """Share of an outline's length in edges shorter than ``short`` (a staircase)."""
    rings = [g.exterior for g in getattr(geom, "geoms", [geom])]
    total = stairs = 0.0
    for ring in rings:
        xy = np.asarray(ring.coords)
        seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        total += seg.sum()
        stairs += seg[seg < short].sum()
    return float(stairs / total) if total else 0.0


def iou(a, b) -> float:
    inter = a.intersection(b).area
    union = a.union(b).area
    return float(inter / union) if union > 0 else 0.0
