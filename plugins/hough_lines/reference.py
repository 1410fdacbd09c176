"""Plain numpy reference of the Hough accumulator (used by the tests to prove the kernel right,
and as a fallback). Same arithmetic as the taichi kernel, in float32 (each product and sum rounded,
no fused multiply-add): bin k = trunc(x·(cosθ/Δρ) + y·(sinθ/Δρ) + (0.5 - k_min)) =
floor(ρ/Δρ + 0.5) - k_min (the argument is positive, so truncation is the floor). float32 is
ample: tiles are shifted to a local origin, where it resolves ρ to 10 µm or better over 150 m,
and it lets the kernel do twice as many points per vector instruction.

An accumulator is an object with ``vote(x, y, sign)``, ``peak()``, ``clear_cell(c, r)``,
``to_numpy()`` and ``close()``: the detection loop never holds the array itself, so the taichi one
keeps its votes in device memory and only peaks come back (as GPU Hough implementations do).
"""

from __future__ import annotations

import numpy as np


def bin_scales(cos_t, sin_t, k_min: int, inv_drho: float):
    """Per-θ factors and the offset that bin a point (float32): the one definition kernel and
    reference share."""
    cos_t = np.asarray(cos_t, np.float64)
    sin_t = np.asarray(sin_t, np.float64)
    return ((cos_t * inv_drho).astype(np.float32), (sin_t * inv_drho).astype(np.float32),
            np.float32(0.5 - float(k_min)))


def bin_index(x, y, cs_j, ss_j, off) -> np.ndarray:
    """ρ bin of points (x, y) for θ (scalars or broadcast arrays), exactly as the accumulator
    counts them: float32 throughout."""
    x = np.asarray(x, np.float32)
    y = np.asarray(y, np.float32)
    return (x * np.float32(cs_j) + y * np.float32(ss_j) + np.float32(off)).astype(np.int64)


class NumpyAccumulator:
    """The (θ, ρ) accumulator as a numpy int32 array: a row per θ, a column per ρ bin (the
    method's H transposed, so that each θ's votes are contiguous)."""

    def __init__(self, cos_t, sin_t, k_min: int, inv_drho: float, n_rho: int, extent=None):
        # ``extent``: the box (x_lo, x_hi, y_lo, y_hi) all votes will come from; a kernel may use
        # it to skip what no vote can reach; counts here are exact without it
        self.cs, self.ss, self.off = bin_scales(cos_t, sin_t, k_min, inv_drho)
        self.acc = np.zeros((len(self.cs), int(n_rho)), np.int32)

    def vote(self, x, y, sign: int = 1, floor: int = 0) -> None:
        """Add (``sign`` = 1) or subtract (-1) one vote per point and θ.

        The contract of a subtraction with ``floor`` > 0: rows whose largest count is below
        ``floor`` may keep their votes (a kernel skips them: they can no longer hold a peak of
        ``floor`` votes), so :meth:`peak` stays exact whenever it returns ``floor`` votes or more
        and is below ``floor`` otherwise. This reference subtracts everywhere."""
        n_theta, n_rho = self.acc.shape
        x = np.asarray(x, np.float32)
        y = np.asarray(y, np.float32)
        chunk = max(1, 4_000_000 // max(n_theta, 1))
        row = np.arange(n_theta) * n_rho
        for s in range(0, len(x), chunk):
            k = bin_index(x[s:s + chunk, None], y[s:s + chunk, None], self.cs[None, :], self.ss[None, :], self.off)
            counts = np.bincount((row[None, :] + k).ravel(), minlength=n_theta * n_rho)
            self.acc += (sign * counts).reshape(n_theta, n_rho).astype(np.int32)

    def peak(self) -> tuple[int, int, int]:
        """(θ index, ρ bin, votes) of the largest cell; ties go to the first in row-major order."""
        c, r = divmod(int(np.argmax(self.acc)), self.acc.shape[1])
        return c, r, int(self.acc[c, r])

    def clear_cell(self, c: int, r: int) -> None:
        self.acc[c, r] = 0

    def to_numpy(self) -> np.ndarray:
        return self.acc.copy()

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
