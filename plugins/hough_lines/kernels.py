"""Taichi kernels of the 2D Hough transform: voting into the (θ, ρ) accumulator and subtracting a
band's votes. One thread per θ owning its row (no atomics). ``reference.py`` is the numpy twin."""


import numpy as np

_kernels = None


def _build(ti):
    @ti.kernel
    def vote(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
             cos_t: ti.types.ndarray(dtype=ti.f64, ndim=1), sin_t: ti.types.ndarray(dtype=ti.f64, ndim=1),
             k_min: ti.i64, inv_drho: ti.f64, acc: ti.types.ndarray(dtype=ti.i32, ndim=2), sign: ti.i32):
        # one thread per θ owns its accumulator row: no atomics, contiguous writes
        # bin = trunc(ρ/Δρ + (0.5 - k_min)): the argument is positive, so truncation is the floor
        off = 0.5 - ti.cast(k_min, ti.f64)
        for j in range(cos_t.shape[0]):
            c = cos_t[j]
            s = sin_t[j]
            for i in range(x.shape[0]):
                k = ti.cast((x[i] * c + y[i] * s) * inv_drho + off, ti.i32)
                acc[j, k] += sign

    return vote


def accumulate(ti, x, y, cos_t, sin_t, k_min: int, inv_drho: float, acc: np.ndarray, sign: int = 1) -> None:
    """Kernel version of :func:`reference.accumulate` (same signature after ``ti``)."""
    global _kernels
    if _kernels is None:
        _kernels = _build(ti)
    if len(x) == 0:
        return
    _kernels(np.ascontiguousarray(x, np.float64), np.ascontiguousarray(y, np.float64),
             np.ascontiguousarray(cos_t, np.float64), np.ascontiguousarray(sin_t, np.float64),
             int(k_min), float(inv_drho), acc, int(sign))
