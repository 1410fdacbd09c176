"""Taichi kernel of the rendered similarity A_s; ``reference.similarity`` is its numpy twin (the
tests prove them equal). One thread per (candidate pose, model segment), as in the thesis's CUDA
code: project both ends (float64, the reference's order), cut to fixed point, find the direction
bin by integer cross products, walk the cells with integer Bresenham steps and add the photo
descriptor of each cell inside the grid to the pose's score (an atomic add)."""

import numpy as np

from . import reference

_k = None


def _build(ti):
    sub = float(reference.SUBPIXEL)
    max_steps = reference.MAX_STEPS
    near = float(reference.NEAR)

    @ti.func
    def project(P: ti.template(), n, x, y, z, r):
        v = P[n, r, 0] * x
        v = v + P[n, r, 1] * y
        v = v + P[n, r, 2] * z
        return v + P[n, r, 3]

    @ti.kernel
    def score(b: ti.types.ndarray(dtype=ti.i32, ndim=3), P: ti.types.ndarray(dtype=ti.f64, ndim=3),
              seg: ti.types.ndarray(dtype=ti.f64, ndim=2), table: ti.types.ndarray(dtype=ti.i64, ndim=2),
              per_cell: ti.i64, out: ti.types.ndarray(dtype=ti.i64, ndim=1)):
        rows = b.shape[0]
        cols = b.shape[1]
        nbins = table.shape[0]
        for n, m in ti.ndrange(P.shape[0], seg.shape[0]):
            ok = True
            fx = ti.Vector([0.0, 0.0], ti.f64)
            fy = ti.Vector([0.0, 0.0], ti.f64)
            for e in ti.static(range(2)):
                x = seg[m, 3 * e]
                y = seg[m, 3 * e + 1]
                z = seg[m, 3 * e + 2]
                pu = project(P, n, x, y, z, 0)
                pv = project(P, n, x, y, z, 1)
                pw = project(P, n, x, y, z, 2)
                if pw <= near:
                    ok = False
                else:
                    u = pu / pw * sub
                    v = pv / pw * sub
                    if ti.abs(u) >= 1e9 or ti.abs(v) >= 1e9:
                        ok = False
                    fx[e] = u
                    fy[e] = v
            if ok:
                ua = ti.cast(ti.floor(fx[0]), ti.i64)
                va = ti.cast(ti.floor(fy[0]), ti.i64)
                ub = ti.cast(ti.floor(fx[1]), ti.i64)
                vb = ti.cast(ti.floor(fy[1]), ti.i64)
                dx = ub - ua
                dy = vb - va
                if dy < 0 or (dy == 0 and dx < 0):
                    dx = -dx
                    dy = -dy
                lo = ti.i64(0)
                hi = ti.i64(nbins)
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    if table[mid, 0] * dy - table[mid, 1] * dx >= 0:
                        lo = mid
                    else:
                        hi = mid
                c0x = ua // per_cell
                c0y = va // per_cell
                ddx = ub // per_cell - c0x
                ddy = vb // per_cell - c0y
                steps = ti.max(ti.abs(ddx), ti.abs(ddy))
                if steps <= max_steps:
                    acc = ti.i64(0)
                    for i32 in range(ti.cast(steps, ti.i32) + 1):  # steps <= MAX_STEPS fits i32
                        i = ti.cast(i32, ti.i64)
                        cx = c0x
                        cy = c0y
                        if steps > 0:
                            cx = c0x + (2 * i * ddx + steps) // (2 * steps)
                            cy = c0y + (2 * i * ddy + steps) // (2 * steps)
                        if 0 <= cx < cols and 0 <= cy < rows:
                            acc += b[cy, cx, lo]
                    ti.atomic_add(out[n], acc)

    return score


def used() -> bool:
    return _k is not None


class TaichiSimilarity:
    """``similarity(b, P, seg_a, seg_b, cell_px, table)`` with the signature of
    ``reference.similarity``."""

    def __init__(self, ti):
        global _k
        if _k is None:
            _k = _build(ti)
        self._score = _k

    def __call__(self, b, P, seg_a, seg_b, cell_px: int, table) -> np.ndarray:
        out = np.zeros(len(P), np.int64)
        if not len(P) or not len(seg_a):
            return out
        seg = np.ascontiguousarray(np.column_stack([seg_a, seg_b]), np.float64)
        self._score(np.ascontiguousarray(b, np.int32), np.ascontiguousarray(P, np.float64), seg,
                    np.ascontiguousarray(table, np.int64), int(reference.SUBPIXEL * cell_px), out)
        return out
