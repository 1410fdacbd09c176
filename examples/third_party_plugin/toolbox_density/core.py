"""Point density on a grid: a pure function on arrays."""

from __future__ import annotations

import numpy as np


def density_grid(x: np.ndarray, y: np.ndarray, cell_size: float, bounds=None):
    """Count points per cell and divide by the cell area.

    Returns (density (rows, cols) float32 in points per square unit, (west, north) of the grid).
    Row 0 is the northern edge (north-up, as GeoTIFFs are).
    """
    if bounds is None:
        bounds = (x.min(), y.min(), x.max(), y.max())
    west, south, east, north = bounds
    west = np.floor(west / cell_size) * cell_size
    north = np.ceil(north / cell_size) * cell_size
    cols = max(int(np.ceil((east - west) / cell_size)), 1)
    rows = max(int(np.ceil((north - south) / cell_size)), 1)
    c = np.clip(((x - west) / cell_size).astype(np.int64), 0, cols - 1)
    r = np.clip(((north - y) / cell_size).astype(np.int64), 0, rows - 1)
    counts = np.bincount(r * cols + c, minlength=rows * cols).reshape(rows, cols)
    return (counts / (cell_size * cell_size)).astype(np.float32), (west, north)
