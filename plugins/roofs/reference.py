"""The ball accumulator of the 3D Hough transform (Borrmann et al. 2011) and its plain numpy
voting, the reference the taichi kernel is proven equal to in the tests.

A plane is ρ = x·cosθ·cosφ + y·sinθ·cosφ + z·sinφ (the method's normal form, METHODS.md §3), with
φ the elevation of its normal. Roof normals point up, so only the upper hemisphere is kept
(φ from 0° for walls to 90° for flat roofs). The hemisphere is cut into rings of equal φ step;
ring j holds about 360°·cos φ_j / step cells, so every cell covers nearly the same area of the
sphere. The plain (θ, φ) grid of the method gives the cells near φ = 90° a sliver of the area of
those at the equator: a steep face's votes spread over several times more cells than a flat one's,
which is how the published run lost the small faces.

Votes are counted in float32 arithmetic (each product and sum rounded, no fused multiply-add),
exactly as the kernel does: bin k = trunc(x·nx' + y·ny' + z·nz' + (0.5 - k_min)) with n' = n/Δρ.
"""

from __future__ import annotations

import numpy as np


def ball_cells(angle_step_deg: float) -> np.ndarray:
    """Unit normals of the ball accumulator's cell centres on the upper hemisphere, (n, 3)
    float64, ring by ring from the equator up to the single polar cell."""
    step = float(angle_step_deg)
    rings = max(int(round(90.0 / step)), 1)
    normals = []
    for j in range(rings + 1):
        phi = np.radians(min(j * 90.0 / rings, 90.0))
        count = max(int(round(360.0 * np.cos(phi) / step)), 1)
        if j == 0:
            # on the equator n and -n are the same plane: half a ring suffices
            count = max(count // 2, 1)
            theta = np.radians(np.arange(count) * 180.0 / count)
        else:
            theta = np.radians(np.arange(count) * 360.0 / count)
        normals.append(np.column_stack([np.cos(theta) * np.cos(phi), np.sin(theta) * np.cos(phi),
                                        np.full(count, np.sin(phi))]))
    return np.concatenate(normals)


def bin_scales(normals: np.ndarray, rho_step: float, k_min: int):
    """Per-cell float32 factors n/Δρ and the offset (0.5 - k_min): the one definition the kernel
    and the reference share."""
    scaled = (np.asarray(normals, np.float64) / float(rho_step)).astype(np.float32)
    return np.ascontiguousarray(scaled), np.float32(0.5 - float(k_min))


def bin_index(xyz: np.ndarray, scaled: np.ndarray, off) -> np.ndarray:
    """ρ bin of every point for every cell, (points, cells) int64, float32 throughout."""
    p = np.asarray(xyz, np.float32)
    s = scaled
    # (x·a + y·b) + z·c + off, in this order, as the kernel adds them
    v = p[:, 0:1] * s[None, :, 0]
    v = v + p[:, 1:2] * s[None, :, 1]
    v = v + p[:, 2:3] * s[None, :, 2]
    v = v + np.float32(off)
    return v.astype(np.int64)


def vote(acc: np.ndarray, xyz: np.ndarray, scaled: np.ndarray, off, sign: int = 1, chunk: int = 2048) -> None:
    """Add ``sign`` to the (cell, ρ bin) of every point in ``acc`` (cells x ρ bins, int32), in place.
    Bins outside the accumulator are dropped (the caller sizes it to hold every point)."""
    cells, n_rho = acc.shape
    flat = acc.reshape(-1)
    base = (np.arange(cells, dtype=np.int64) * n_rho)[None, :]
    for i in range(0, len(xyz), chunk):
        k = bin_index(xyz[i:i + chunk], scaled, off)
        ok = (k >= 0) & (k < n_rho)
        np.add.at(flat, (base + k)[ok], sign)
