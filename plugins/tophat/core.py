"""Morphological top-hat filters.

``tophat_points`` is the point filter of Grigillo et al. (2015, METHODS.md §1): a binary raster
of occupied cells, opened with the 3x3 cross, top-hat = mask - opening (thin, line-like
structures survive), and in each top-hat cell fewer than ``max_points_per_cell`` points are
replaced by their centroid while denser cells (vegetation) are dropped.
``tophat_raster`` is the general binary / grey-level white top-hat of an image.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)


def structure(shape: str, size_cells: int) -> np.ndarray:
    if shape == "cross":
        s = np.zeros((size_cells, size_cells), bool)
        s[size_cells // 2, :] = True
        s[:, size_cells // 2] = True
        return s
    if shape == "disk":
        r = size_cells // 2
        yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
        return xx * xx + yy * yy <= r * r + 0.5
    return np.ones((size_cells, size_cells), bool)


def tophat_points(x, y, cell_size_m: float = 0.5, max_points_per_cell: int = 45, element=CROSS):
    """Returns (cx, cy, counts, cell_of_point, kept_cells): centroids of the kept top-hat cells,
    their point counts, each input point's flat cell index and the boolean of kept cells."""
    west = np.floor(x.min() / cell_size_m) * cell_size_m - cell_size_m
    south = np.floor(y.min() / cell_size_m) * cell_size_m - cell_size_m
    cols = int((x.max() - west) / cell_size_m) + 2
    rows = int((y.max() - south) / cell_size_m) + 2
    c = ((x - west) / cell_size_m).astype(np.int64)
    r = ((y - south) / cell_size_m).astype(np.int64)
    flat = r * cols + c
    counts = np.bincount(flat, minlength=rows * cols)
    mask = (counts > 0).reshape(rows, cols)
    opened = ndimage.binary_opening(mask, structure=element)
    top = (mask & ~opened).ravel()
    kept = top & (counts < max_points_per_cell)
    sel = np.flatnonzero(kept)
    n = counts[sel].astype(np.float64)
    sx = np.bincount(flat, weights=x, minlength=rows * cols)[sel]
    sy = np.bincount(flat, weights=y, minlength=rows * cols)[sel]
    return sx / n, sy / n, counts[sel], flat, kept


def tophat_raster(image: np.ndarray, mode: str = "grey", element: np.ndarray = CROSS, threshold: float = 0.0):
    """White top-hat (image - opening). ``mode="binary"`` thresholds first (value > threshold)."""
    if mode == "binary":
        mask = image > threshold
        return (mask & ~ndimage.binary_opening(mask, structure=element)).astype(np.uint8)
    img = np.nan_to_num(image.astype(np.float64), nan=np.nanmin(image) if np.isfinite(image).any() else 0.0)
    return ndimage.white_tophat(img, footprint=element).astype(np.float32)
