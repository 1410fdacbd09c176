"""Plain numpy reference of the Hough accumulator (used by the tests to prove the kernel right,
and as a fallback). Same arithmetic as the taichi kernel: float64 ρ = x·cosθ + y·sinθ, bin
k = trunc(ρ/Δρ + (0.5 - k_min)) = floor(ρ/Δρ + 0.5) - k_min (the argument is positive)."""

from __future__ import annotations

import numpy as np


def accumulate(x, y, cos_t, sin_t, k_min: int, inv_drho: float, acc: np.ndarray, sign: int = 1) -> None:
    """Add (``sign`` = 1) or subtract (-1) one vote per point and θ into ``acc`` (a row per θ, a
    column per ρ bin)."""
    n_theta, n_rho = acc.shape
    chunk = max(1, 4_000_000 // max(n_theta, 1))
    row = np.arange(n_theta)
    for s in range(0, len(x), chunk):
        rho = x[s:s + chunk, None] * cos_t[None, :] + y[s:s + chunk, None] * sin_t[None, :]
        k = (rho * inv_drho + (0.5 - k_min)).astype(np.int64)  # positive: truncation is the floor
        flat = (row[None, :] * n_rho + k).ravel()
        acc += (sign * np.bincount(flat, minlength=n_theta * n_rho)).reshape(n_theta, n_rho).astype(acc.dtype)
