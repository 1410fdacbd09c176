"""Taichi kernels of the 2D Hough transform: voting into the (ρ, θ) accumulator and subtracting a
band's votes. One thread per (point, θ) pair, atomic adds. ``reference.py`` is the numpy twin."""


import numpy as np

_kernels = None


def _build(ti):
    @ti.kernel
    def vote(x: ti.types.ndarray(dtype=ti.f64, ndim=1), y: ti.types.ndarray(dtype=ti.f64, ndim=1),
             cos_t: ti.types.ndarray(dtype=ti.f64, ndim=1), sin_t: ti.types.ndarray(dtype=ti.f64, ndim=1),
             k_min: ti.i64, inv_drho: ti.f64, acc: ti.types.ndarray(dtype=ti.i32, ndim=2), sign: ti.i32):
        for i, j in ti.ndrange(x.shape[0], cos_t.shape[0]):
            rho = x[i] * cos_t[j] + y[i] * sin_t[j]
            k = ti.cast(ti.floor(rho * inv_drho + 0.5), ti.i64) - k_min
            ti.atomic_add(acc[k, j], sign)

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
