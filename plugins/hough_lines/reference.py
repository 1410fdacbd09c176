"""Plain numpy reference of the Hough accumulator (used by the tests to prove the kernel right,
and as a fallback). Same arithmetic as the taichi kernel: float64 ρ = x·cosθ + y·sinθ, bin
k = floor(ρ/Δρ + 0.5) - k_min."""

from __future__ import annotations

import numpy as np


def accumulate(x, y, cos_t, sin_t, k_min: int, inv_drho: float, acc: np.ndarray, sign: int = 1) -> None:
    """Add (``sign`` = 1) or subtract (-1) one vote per point and θ into ``acc`` (rows ρ, cols θ)."""
    rows, cols = acc.shape
    chunk = max(1, 4_000_000 // max(cols, 1))
    col = np.arange(cols)
    for s in range(0, len(x), chunk):
        rho = x[s:s + chunk, None] * cos_t[None, :] + y[s:s + chunk, None] * sin_t[None, :]
        k = np.floor(rho * inv_drho + 0.5).astype(np.int64) - k_min
        flat = (k * cols + col[None, :]).ravel()
        acc += (sign * np.bincount(flat, minlength=rows * cols)).reshape(rows, cols).astype(acc.dtype)
