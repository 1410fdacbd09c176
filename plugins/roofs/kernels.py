"""Taichi kernel of the ball accumulator's voting; ``reference.vote`` is its numpy twin (the tests
prove them equal, count for count). Each thread owns whole cells (rows of the accumulator) and runs
over the points, so no vote needs an atomic add; the arithmetic is float32 in the reference's
order."""


import numpy as np

_k = None


def _build(ti):
    @ti.kernel
    def vote(x: ti.types.ndarray(dtype=ti.f32, ndim=1), y: ti.types.ndarray(dtype=ti.f32, ndim=1),
             z: ti.types.ndarray(dtype=ti.f32, ndim=1), scaled: ti.types.ndarray(dtype=ti.f32, ndim=2),
             off: ti.f32, sign: ti.i32, acc: ti.types.ndarray(dtype=ti.i32, ndim=2)):
        n_rho = acc.shape[1]
        for c in range(acc.shape[0]):
            a = scaled[c, 0]
            b = scaled[c, 1]
            d = scaled[c, 2]
            for i in range(x.shape[0]):
                v = x[i] * a
                v = v + y[i] * b
                v = v + z[i] * d
                v = v + off
                k = ti.cast(v, ti.i32)
                if 0 <= k < n_rho:
                    acc[c, k] = acc[c, k] + sign

    return vote


def used() -> bool:
    return _k is not None


class TaichiVoter:
    """``vote(acc, xyz, scaled, off, sign)`` with the signature of ``reference.vote``."""

    def __init__(self, ti):
        global _k
        if _k is None:
            _k = _build(ti)
        self._vote = _k

    def __call__(self, acc: np.ndarray, xyz: np.ndarray, scaled: np.ndarray, off, sign: int = 1) -> None:
        if not len(xyz):
            return
        p = np.asarray(xyz, np.float32)
        self._vote(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), np.ascontiguousarray(p[:, 2]),
                   np.ascontiguousarray(scaled, np.float32), float(off), int(sign), acc)
