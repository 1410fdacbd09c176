"""Taichi kernels of the DTM's per-point passes: lowest point per cell, per-cell moments
(scatter), and the near-surface test (two bilinear samples of grids at the points and the
tolerance test, in one pass), in parallel. ``core.minimum_surface``, ``core.cell_moments`` and
``core._near_surface`` with ``core.Sampler`` are their numpy references (the tests compare them).

Moments on the CPU: each thread sums its own slice of the points into its own copy of the grid
(the ten sums of a cell side by side), and the copies are added up after. taichi makes ``+=`` on
shared memory atomic, and a float64 atomic add is a compare-and-swap loop on x86: ten per point
made the shared-grid kernel 3.5x slower (10 M points: 212 ms against 61 ms with two slices).
On CUDA, where atomics are cheap and threads many, the shared-grid kernel is used.
"""

import numpy as np

from .core import MOMENTS

_k = None
SLICE_GRID_BYTES = 1 << 29  # the per-thread grid copies take at most this much memory
TASK_STRIDE = 512  # taichi's CPU backend hands out a range-for in chunks of up to 512 iterations


def _build(ti):
    V10 = ti.types.vector(len(MOMENTS), ti.f64)

    @ti.kernel
    def moments_sliced(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
                       z: ti.types.ndarray(dtype=ti.f64, ndim=1), west: ti.f64, north: ti.f64, cell: ti.f64,
                       rows: ti.i32, cols: ti.i32, mask: ti.types.ndarray(dtype=ti.u8, ndim=1), masked: ti.i32,
                       part: ti.types.ndarray(dtype=V10, ndim=2), out: ti.types.ndarray(dtype=ti.f64, ndim=2)):
        # slice p of the points into grid copy p; one slice per thread: the loop runs over
        # slices x TASK_STRIDE iterations so that each slice lands in another thread's chunk
        slices = part.shape[0]
        n = x.shape[0]
        for t in range(slices * TASK_STRIDE):
            if t % TASK_STRIDE == 0:
                p = t // TASK_STRIDE
                lo = ti.cast(ti.cast(n, ti.i64) * p // slices, ti.i32)
                hi = ti.cast(ti.cast(n, ti.i64) * (p + 1) // slices, ti.i32)
                for i in range(lo, hi):
                    if masked == 0 or mask[i] != 0:
                        c = ti.min(ti.max(ti.cast((x[i] - west) / cell, ti.i32), 0), cols - 1)
                        r = ti.min(ti.max(ti.cast((north - y[i]) / cell, ti.i32), 0), rows - 1)
                        f = r * cols + c
                        dx = x[i] - (west + (ti.cast(c, ti.f64) + 0.5) * cell)
                        dy = y[i] - (north - (ti.cast(r, ti.f64) + 0.5) * cell)
                        zi = z[i]
                        # a plain load and store (not +=, which would be atomic): the slice is ours
                        part[p, f] = part[p, f] + ti.Vector([1.0, dx, dy, zi, dx * dx, dy * dy, dx * dy,
                                                             dx * zi, dy * zi, zi * zi])
        # the copies added up, one grid per moment (in numpy, the sum and the transposition took
        # twice as long as the scatter)
        for f in range(part.shape[1]):
            total = part[0, f]
            for p in range(1, slices):
                total += part[p, f]
            for k in ti.static(range(len(MOMENTS))):
                out[k, f] = total[k]

    @ti.kernel
    def moments(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
                z: ti.types.ndarray(dtype=ti.f64, ndim=1), west: ti.f64, north: ti.f64, cell: ti.f64,
                mask: ti.types.ndarray(dtype=ti.u8, ndim=1), masked: ti.i32, out: ti.types.ndarray(dtype=ti.f64, ndim=3)):
        rows = out.shape[1]
        cols = out.shape[2]
        for i in range(x.shape[0]):
            if masked != 0 and mask[i] == 0:
                continue
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

    @ti.kernel
    def near_surface(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
                     z: ti.types.ndarray(dtype=ti.f64, ndim=1), surface: ti.types.ndarray(dtype=ti.f64, ndim=2),
                     slope: ti.types.ndarray(dtype=ti.f64, ndim=2), west: ti.f64, north: ti.f64, cell: ti.f64,
                     threshold: ti.f64, slope_factor: ti.f64, below: ti.f64,
                     near: ti.types.ndarray(dtype=ti.u8, ndim=1), dz: ti.types.ndarray(dtype=ti.f64, ndim=1)):
        # both bilinear samples and the test in one pass over the points (three passes of numpy
        # over ten million points cost more than the two samples)
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
            s_top = slope[r0, c0] * (1.0 - fc) + slope[r0, c1] * fc
            s_bot = slope[r1, c0] * (1.0 - fc) + slope[r1, c1] * fc
            tol = threshold + slope_factor * (s_top * (1.0 - fr) + s_bot * fr) * cell
            d = z[i] - (top * (1.0 - fr) + bot * fr)
            dz[i] = d
            near[i] = ti.cast((d <= tol) and (d >= -below), ti.u8)

    return moments, moments_sliced, cell_min, near_surface


def used() -> bool:
    """Whether this process has made a :class:`TaichiAccel` (its kernels' start-up is paid)."""
    return _k is not None


class TaichiAccel:
    """The ``accel`` argument of ``core.ground_filter`` / ``core.dtm_from_ground``."""

    def __init__(self, ti):
        global _k
        if _k is None:
            _k = _build(ti)
        self._moments, self._moments_sliced, self._cell_min, self._near_surface = _k
        cfg = ti.lang.impl.current_cfg()
        self._threads = int(cfg.cpu_max_num_threads) if cfg.arch in (ti.x64, ti.arm64) else 0  # 0: not a CPU

    def moments(self, grid, x, y, z, where=None) -> dict:
        """Kernel twin of ``core.cell_moments`` (``where``: the points to sum, a bool mask; the
        kernel skips the others instead of the caller copying the rest out)."""
        x, y, z = (np.ascontiguousarray(a, np.float64) for a in (x, y, z))
        mask = np.zeros(1, np.uint8) if where is None else np.ascontiguousarray(where, dtype=bool).view(np.uint8)
        masked = int(where is not None)
        cells = grid.rows * grid.cols
        # one slice per thread while the copies stay small and each slice has points to sum
        slices = max(min(self._threads, SLICE_GRID_BYTES // (cells * len(MOMENTS) * 8), len(x) // 10_000), 1)
        out = np.zeros((len(MOMENTS), grid.rows, grid.cols), np.float64)
        if len(x) and self._threads:
            part = np.zeros((slices, cells, len(MOMENTS)), np.float64)
            self._moments_sliced(x, y, z, grid.west, grid.north, grid.cell, grid.rows, grid.cols, mask, masked,
                                 part, out.reshape(len(MOMENTS), cells))
        elif len(x):  # a GPU: one shared grid, atomic adds
            self._moments(x, y, z, grid.west, grid.north, grid.cell, mask, masked, out)
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

    def near_surface(self, grid, x, y, z, surface, slope, threshold, slope_factor, below):
        """Kernel twin of ``core._near_surface`` (with the slope grid given): (mask, dz)."""
        near = np.empty(len(x), np.uint8)
        dz = np.empty(len(x), np.float64)
        if len(x):
            self._near_surface(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64),
                               np.ascontiguousarray(z, np.float64), np.ascontiguousarray(surface, np.float64),
                               np.ascontiguousarray(slope, np.float64), grid.west, grid.north, grid.cell,
                               float(threshold), float(slope_factor), float(below), near, dz)
        return near.view(bool), dz
