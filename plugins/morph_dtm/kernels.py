"""Taichi kernels of the DTM's per-point passes: per-cell moments (scatter) and bilinear sampling
of a grid at the points (gather), in parallel. ``core.cell_moments`` and ``core.Sampler`` are
their numpy references (the tests compare them)."""

import numpy as np

from .core import MOMENTS

_k = None


def _build(ti):
    @ti.kernel
    def moments(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
                z: ti.types.ndarray(dtype=ti.f64, ndim=1), west: ti.f64, north: ti.f64, cell: ti.f64,
                out: ti.types.ndarray(dtype=ti.f64, ndim=3)):
        rows = out.shape[1]
        cols = out.shape[2]
        for i in range(x.shape[0]):
            c = ti.min(ti.max(ti.cast((x[i] - west) / cell, ti.i32), 0), cols - 1)
            r = ti.min(ti.max(ti.cast((north - y[i]) / cell, ti.i32), 0), rows - 1)
            dx = x[i] - (west + (ti.cast(c, ti.f64) + 0.5) * cell)
            dy = y[i] - (north - (ti.cast(r, ti.f64) + 0.5) * cell)
            zi = z[i]
            ti.atomic_add(out[0, r, c], 1.0)
            ti.atomic_add(out[1, r, c], dx)
            ti.atomic_add(out[2, r, c], dy)
            ti.atomic_add(out[3, r, c], zi)
            ti.atomic_add(out[4, r, c], dx * dx)
            ti.atomic_add(out[5, r, c], dy * dy)
            ti.atomic_add(out[6, r, c], dx * dy)
            ti.atomic_add(out[7, r, c], dx * zi)
            ti.atomic_add(out[8, r, c], dy * zi)
            ti.atomic_add(out[9, r, c], zi * zi)

    @ti.kernel
    def bilinear(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
                 surface: ti.types.ndarray(dtype=ti.f64, ndim=2), west: ti.f64, north: ti.f64, cell: ti.f64,
                 out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
        rows = surface.shape[0]
        cols = surface.shape[1]
        for i in range(x.shape[0]):
            r = ti.min(ti.max((north - y[i]) / cell - 0.5, 0.0), ti.cast(rows - 1, ti.f64))
            c = ti.min(ti.max((x[i] - west) / cell - 0.5, 0.0), ti.cast(cols - 1, ti.f64))
            r0 = ti.min(ti.cast(r, ti.i32), ti.max(rows - 2, 0))
            c0 = ti.min(ti.cast(c, ti.i32), ti.max(cols - 2, 0))
            fr = r - ti.cast(r0, ti.f64)
            fc = c - ti.cast(c0, ti.f64)
            r1 = ti.min(r0 + 1, rows - 1)
            c1 = ti.min(c0 + 1, cols - 1)
            top = surface[r0, c0] * (1.0 - fc) + surface[r0, c1] * fc
            bot = surface[r1, c0] * (1.0 - fc) + surface[r1, c1] * fc
            out[i] = top * (1.0 - fr) + bot * fr

    @ti.kernel
    def cell_min(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
                 z: ti.types.ndarray(dtype=ti.f64, ndim=1), west: ti.f64, north: ti.f64, cell: ti.f64,
                 rows: ti.i32, cols: ti.i32, flat: ti.types.ndarray(dtype=ti.i64, ndim=1),
                 zmin: ti.types.ndarray(dtype=ti.f64, ndim=1)):
        for i in range(x.shape[0]):
            c = ti.min(ti.max(ti.cast((x[i] - west) / cell, ti.i32), 0), cols - 1)
            r = ti.min(ti.max(ti.cast((north - y[i]) / cell, ti.i32), 0), rows - 1)
            f = ti.cast(r, ti.i64) * cols + c
            flat[i] = f
            ti.atomic_min(zmin[f], z[i])

    return moments, bilinear, cell_min


class TaichiAccel:
    """The ``accel`` argument of ``core.ground_filter`` / ``core.dtm_from_ground``."""

    def __init__(self, ti):
        global _k
        if _k is None:
            _k = _build(ti)
        self._moments, self._bilinear, self._cell_min = _k

    def moments(self, grid, x, y, z) -> dict:
        out = np.zeros((len(MOMENTS), grid.rows, grid.cols), np.float64)
        if len(x):
            self._moments(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64),
                          np.ascontiguousarray(z, np.float64), grid.west, grid.north, grid.cell, out)
        return {name: out[k] for k, name in enumerate(MOMENTS)}

    def minimum_surface(self, grid, x, y, z):
        """Kernel twin of ``core.minimum_surface``: (lowest z per cell, NaN where empty; flat cells)."""
        flat = np.empty(len(x), np.int64)
        zmin = np.full(grid.rows * grid.cols, np.inf)
        if len(x):
            self._cell_min(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64),
                           np.ascontiguousarray(z, np.float64), grid.west, grid.north, grid.cell,
                           grid.rows, grid.cols, flat, zmin)
        zmin[np.isinf(zmin)] = np.nan
        return zmin.reshape(grid.rows, grid.cols), flat

    def sampler(self, grid, x, y):
        x = np.ascontiguousarray(x, np.float64)
        y = np.ascontiguousarray(y, np.float64)

        def sample(surface):
            out = np.empty(len(x), np.float64)
            self._bilinear(x, y, np.ascontiguousarray(surface, np.float64), grid.west, grid.north, grid.cell, out)
            return out

        return sample
