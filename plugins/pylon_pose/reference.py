"""Numpy reference of the rendered-similarity A_s (Serebro 2017, METHODS.md §4); ``kernels`` holds
its taichi twin and the tests prove them equal, score for score.

Both take the same integer-exact route so that they can agree to the last vote:
- a model segment's end points are projected by a 3 x 4 matrix P = K·[R|t]·M in float64, in one
  fixed order of operations, and cut to 1/16 pixel (fixed point): a GPU that fuses a multiply and
  an add changes the last bit of a float64, which moves the cut only for a value within about
  1e-12 of a 1/16 pixel boundary (in float32 some poses scored differently on CUDA);
- its direction bin (0..179 degrees, undirected) is found by integer cross products against a
  table of bin boundaries (``direction_table``), not by atan2, whose last bit differs between
  libraries;
- the cells it crosses (k x k pixels) are walked with integer Bresenham steps, and every cell inside
  the grid adds the photo's smoothed descriptor b[cell_row, cell_col, bin] to the pose's score."""

from __future__ import annotations

import numpy as np

SUBPIXEL = 16  # fixed point: 1/16 pixel
BOUNDARY_SCALE = 1 << 20
MAX_STEPS = 4096  # cells walked per segment at most (a segment longer than that is off any sane pose)
NEAR = 1e-3  # a segment end this close to the camera plane (or behind it) drops the segment


def direction_table(bins: int = 180) -> np.ndarray:
    """Integer vectors of the bin boundaries i·180°/bins, i = 0..bins-1 (int64, shape (bins, 2))."""
    a = np.radians(np.arange(bins) * 180.0 / bins)
    return np.column_stack([np.round(np.cos(a) * BOUNDARY_SCALE), np.round(np.sin(a) * BOUNDARY_SCALE)]).astype(np.int64)


def direction_bin(dx, dy, table: np.ndarray):
    """Undirected direction bin of integer vectors (dx, dy) (arrays of int64): binary search on the
    sign of the cross product with the boundaries; (0, 0) falls in the last bin."""
    dx, dy = np.asarray(dx, np.int64).copy(), np.asarray(dy, np.int64).copy()
    flip = (dy < 0) | ((dy == 0) & (dx < 0))
    dx[flip], dy[flip] = -dx[flip], -dy[flip]
    lo = np.zeros(dx.shape, np.int64)
    hi = np.full(dx.shape, len(table), np.int64)
    while np.any(hi - lo > 1):
        mid = (lo + hi) // 2  # < len(table) while hi - lo > 1
        act = hi - lo > 1
        ccw = table[mid, 0] * dy - table[mid, 1] * dx >= 0
        lo = np.where(act & ccw, mid, lo)
        hi = np.where(act & ~ccw, mid, hi)
    return lo


def walk_cells(c0x: int, c0y: int, c1x: int, c1y: int):
    """Integer Bresenham cells from (c0x, c0y) to (c1x, c1y), both ends included: step i of n goes to
    c0 + floor((2·i·d + n) / (2·n)), i.e. the nearest cell, ties upwards."""
    dx, dy = c1x - c0x, c1y - c0y
    n = max(abs(dx), abs(dy))
    if n == 0:
        return np.array([c0x]), np.array([c0y])
    i = np.arange(n + 1, dtype=np.int64)
    return c0x + (2 * i * dx + n) // (2 * n), c0y + (2 * i * dy + n) // (2 * n)


def cells_inside(c0x: int, c0y: int, c1x: int, c1y: int, rows: int, cols: int):
    """``walk_cells`` kept to the grid of ``rows`` x ``cols`` cells: (rows, cols) indices."""
    cx, cy = walk_cells(c0x, c0y, c1x, c1y)
    inside = (cx >= 0) & (cx < cols) & (cy >= 0) & (cy < rows)
    return cy[inside], cx[inside]


def project_fixed(P: np.ndarray, xyz: np.ndarray):
    """Fixed-point pixel coordinates (int64, 1/16 px) of model points under each 3 x 4 matrix, and
    whether each lies in front of the camera. P: (N, 3, 4), xyz: (M, 3), both taken as float64 ->
    (u, v, ok), each (N, M)."""
    P = np.asarray(P, np.float64)
    x, y, z = (np.asarray(xyz, np.float64)[None, :, k] for k in range(3))

    def row(r):
        v = P[:, r, 0:1] * x
        v = v + P[:, r, 1:2] * y
        v = v + P[:, r, 2:3] * z
        return v + P[:, r, 3:4]

    pu, pv, pw = row(0), row(1), row(2)
    ok = pw > NEAR
    w = np.where(ok, pw, 1.0)
    u = pu / w * SUBPIXEL
    v = pv / w * SUBPIXEL
    ok &= (np.abs(u) < 1e9) & (np.abs(v) < 1e9)
    u = np.where(ok, u, 0.0)
    v = np.where(ok, v, 0.0)
    return np.floor(u).astype(np.int64), np.floor(v).astype(np.int64), ok


def similarity(b: np.ndarray, P: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, cell_px: int,
               table: np.ndarray) -> np.ndarray:
    """Score of each pose: for every model segment (ends ``seg_a[m]``, ``seg_b[m]``, model
    coordinates) projected by ``P[n]``, the sum of b[row, col, bin] over the cells it crosses.
    b: (rows, cols, bins) int32. Returns int64 (N,)."""
    rows, cols, _ = b.shape
    ua, va, oka = project_fixed(P, seg_a)
    ub, vb, okb = project_fixed(P, seg_b)
    ok = oka & okb
    per_cell = SUBPIXEL * cell_px
    d = direction_bin(ub - ua, vb - va, table)
    score = np.zeros(len(P), np.int64)
    for n, m in zip(*np.nonzero(ok)):
        c0x, c0y = ua[n, m] // per_cell, va[n, m] // per_cell
        c1x, c1y = ub[n, m] // per_cell, vb[n, m] // per_cell
        if max(abs(c1x - c0x), abs(c1y - c0y)) > MAX_STEPS:
            continue
        r, c = cells_inside(int(c0x), int(c0y), int(c1x), int(c1y), rows, cols)
        score[n] += int(b[r, c, d[n, m]].sum())
    return score


def occupancy(segments: np.ndarray, shape: tuple[int, int], cell_px: int, table: np.ndarray) -> np.ndarray:
    """The method's a[cell][d]: 1 where a photo segment of direction bin d crosses the cell.
    segments: (S, 4) pixel coordinates x0, y0, x1, y1 (undistorted); shape: (rows, cols) of cells."""
    rows, cols = shape
    a = np.zeros((rows, cols, len(table)), np.uint8)
    if not len(segments):
        return a
    s = np.floor(np.asarray(segments, np.float64) * SUBPIXEL).astype(np.int64)
    d = direction_bin(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1], table)
    per_cell = SUBPIXEL * cell_px
    for (x0, y0, x1, y1), k in zip(s // per_cell, d):
        r, c = cells_inside(int(x0), int(y0), int(x1), int(y1), rows, cols)
        a[r, c, k] = 1
    return a
