"""Taichi kernels of the 2D Hough transform: voting into the (θ, ρ) accumulator, subtracting a
band's votes and finding the peak, with the votes kept in taichi memory (only peaks come back).
``reference.NumpyAccumulator`` is the numpy twin; both bin with :func:`reference.bin_scales`.

Why it is written this way (each measured on the 2-core CI machine, 20 000 points × 1800 θ):
- one loop iteration owns one θ row and takes every point's vote in it: no two iterations share a
  cell, so there are no atomics (taichi makes ``+=`` on global memory atomic; a plain load/store
  is 2× faster), and the row (a few thousand counts) stays in the L1 cache while it is counted.
  An earlier layout gave each task a block of 16 rows and each point 16 independent increments:
  it spread the votes over 16 rows (L2, not L1) and ran at a seventh of this speed;
- a new accumulator is not cleared in a pass of its own: each row is zeroed by the first vote
  that touches it (per-row ``fresh`` flags), while it is in cache for the votes;
- the votes live in taichi *fields*, whose addressing compiles to constants: the same loop over
  ndarrays (a pointer and stride load per access) was 3–4× slower;
- the fields have a fixed capacity and the kernels name them directly (not as template
  arguments), so taichi's offline cache serves the compiled kernels to the next process: that
  saved 0.4 s of start-up per run;
- few, small kernels: a fresh process pays 40-150 ms per kernel (taichi's Python front end runs
  even when the offline cache holds the machine code), so the band-subtraction flags are always
  computed (no second variant: the compare costs nothing measurable beside the increments) and
  small steps are merged;
- handing a loop to taichi's CPU thread pool costs 0.15-0.25 ms with the launch (even an empty
  loop), about what subtracting a band of 300 points costs. So the band's subtraction only flags
  the rows whose peak cell lost votes, and the peak search is one *serial* kernel: it rescans
  dirty rows only while their old maximum (an upper bound) could still win, the highest bound
  first. Tiny loops (copying a band's few hundred points) run in the launching thread.
- a band's subtraction skips the rows bounded below the caller's vote threshold (most rows, once
  a tile's first peak is known): those rows can no longer win; the rows it still counts are
  handed to the threads a few at a time (``ROWS_PER_CHUNK``), as they may lie anywhere.
- given the box its points come from, an accumulator clears and scans each θ row only over the
  ρ bins the box reaches (55-75 % of a row for a tile at its own origin); the counts outside are
  zeros never stored.
"""

import numpy as np

from .reference import bin_index, bin_scales

ROWS_PER_CHUNK = 8
POINTS_PER_PASS = 1 << 20  # points are voted in passes of at most this many
MAX_THETAS = 1 << 15  # 0.0055° steps at the finest
UNBOUNDED = 2**31 - 1  # the bound of a row whose counts grew
# accumulator cells of the standard kit (32 MiB: a default 110 m tile needs 4.8 M); larger
# accumulators get a kit of their own
CELLS = 1 << 23

_kits: dict = {}
_busy = [False]


def _build(ti, cells: int):
    on_cpu = ti.lang.impl.current_cfg().arch in (ti.x64, ti.arm64)
    xs = ti.field(ti.f32, POINTS_PER_PASS)
    ys = ti.field(ti.f32, POINTS_PER_PASS)
    cs = ti.field(ti.f32, MAX_THETAS)
    ss = ti.field(ti.f32, MAX_THETAS)
    flat = ti.field(ti.i32, cells)

    # per θ row: its largest count, the first ρ bin holding it, and whether votes were taken
    # from its peak cell since (then row_max is only an upper bound)
    row_max = ti.field(ti.i32, MAX_THETAS)
    row_arg = ti.field(ti.i32, MAX_THETAS)
    dirty = ti.field(ti.i32, MAX_THETAS)
    # per θ row: the ρ bins the accumulator's points can reach (their bounding box's projection);
    # the counts outside are zeros that are never stored, cleared or scanned
    reach_lo = ti.field(ti.i32, MAX_THETAS)
    reach_hi = ti.field(ti.i32, MAX_THETAS)
    # per θ row: its counts are stale (a new accumulator) and read as zeros; the first vote
    # clears them where it is about to count (a separate clearing pass over the whole
    # accumulator cost 3 ms per tile, and the vote then fetched every line from memory again)
    fresh = ti.field(ti.i32, MAX_THETAS)

    @ti.func
    def clear_row(j, n_rho):
        base = j * n_rho
        for k in range(reach_lo[j], reach_hi[j] + 1):
            flat[base + k] = 0
        fresh[j] = 0

    @ti.func
    def rescan(j, n_rho):
        # row j's largest count and the first ρ bin holding it (a branch-free max, then the
        # first match: numpy's argmax order)
        base = j * n_rho
        lo = reach_lo[j]
        hi = reach_hi[j]
        best = 0  # the counts outside the reach
        for k in range(lo, hi + 1):
            best = ti.max(best, flat[base + k])
        arg = 0
        if best > 0:
            arg = lo
            while flat[base + arg] != best:
                arg += 1
        row_max[j] = best
        row_arg[j] = arg
        dirty[j] = 0

    @ti.kernel
    def vote(xa: ti.types.ndarray(dtype=ti.f32, ndim=1), ya: ti.types.ndarray(dtype=ti.f32, ndim=1),
             n_theta: ti.i32, n_rho: ti.i32, off: ti.f32, sign: ti.i32, floor: ti.i32):
        # one θ row per iteration: its counts stay in the L1 cache while every point votes in it,
        # and no two iterations share a cell (no atomics). Rows whose peak cell lost votes are
        # flagged dirty: their old maximum bounds the new one, and ``peak`` rescans only those
        # that could still win. Added votes unbound every row. A subtraction skips the rows
        # bounded below ``floor``: they can no longer hold a peak the caller takes.
        n = xa.shape[0]
        # the points are copied into the fields; on the CPU in the launching thread (handing a loop
        # to the thread pool costs about 0.1 ms, and most votes are a band of a few hundred points)
        ti.loop_config(serialize=on_cpu)
        for i in range(n):
            xs[i] = xa[i]
            ys[i] = ya[i]
        ti.loop_config(block_dim=ROWS_PER_CHUNK)
        for j in range(n_theta):
            if sign > 0 or row_max[j] >= floor:
                if fresh[j]:
                    clear_row(j, n_rho)
                c = cs[j]
                s = ss[j]
                row = j * n_rho
                peak_at = row_arg[j] + row
                hit = 0
                for i in range(n):
                    a = ti.cast(xs[i] * c + ys[i] * s + off, ti.i32) + row
                    flat[a] = flat[a] + sign  # not +=: that would be atomic
                    hit |= ti.cast(a == peak_at, ti.i32)
                if sign > 0:  # counts went up: no bound holds, ``peak`` rescans the row
                    row_max[j] = UNBOUNDED
                    dirty[j] = 1
                elif hit:
                    dirty[j] = 1

    @ti.kernel
    def peak(n_theta: ti.i32, n_rho: ti.i32) -> ti.types.vector(3, ti.i32):
        # the first row holding the largest count, in the launching thread: subtraction only
        # lowers counts, so a dirty row needs its rescan only while its bound could beat (or tie
        # with a lower index) the best row known; the highest bound goes first (it likely holds
        # the peak and lifts the bar for the rest), then the others in row order
        c = 0
        ti.loop_config(serialize=True)
        for _ in range(1):
            best, best_j, bound, bound_j = -1, -1, -1, -1
            for j in range(n_theta):
                v = row_max[j]
                if dirty[j]:
                    if v > bound:
                        bound, bound_j = v, j
                elif v > best:
                    best, best_j = v, j
            for i in range(n_theta + 1):
                j = bound_j if i == 0 else i - 1
                if j >= 0 and dirty[j]:
                    if row_max[j] > best or (row_max[j] == best and j < best_j):
                        rescan(j, n_rho)
                        if row_max[j] > best or (row_max[j] == best and j < best_j):
                            best, best_j = row_max[j], j
            c = best_j
        return ti.Vector([c, row_arg[c], row_max[c]])

    @ti.kernel
    def reset(a: ti.types.ndarray(dtype=ti.f32, ndim=1), b: ti.types.ndarray(dtype=ti.f32, ndim=1),
              lo: ti.types.ndarray(dtype=ti.i32, ndim=1), hi: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        # a new accumulator: its θ factors and reaches, every row's counts stale
        ti.loop_config(serialize=on_cpu)
        for j in range(a.shape[0]):
            cs[j] = a[j]
            ss[j] = b[j]
            reach_lo[j] = lo[j]
            reach_hi[j] = hi[j]
            row_max[j] = 0
            row_arg[j] = 0
            dirty[j] = 0
            fresh[j] = 1

    @ti.kernel
    def copy_out(out: ti.types.ndarray(dtype=ti.i32, ndim=1), n_rho: ti.i32):
        for i in range(out.shape[0]):
            j = i // n_rho
            k = i - j * n_rho
            out[i] = 0 if fresh[j] or k < reach_lo[j] or k > reach_hi[j] else flat[i]

    @ti.kernel
    def clear_cell(j: ti.i32, k: ti.i32, n_rho: ti.i32):
        if fresh[j]:
            clear_row(j, n_rho)
        flat[j * n_rho + k] = 0
        dirty[j] = 1  # a lower count: the row's maximum still bounds it

    return dict(vote=vote, peak=peak, reset=reset, copy_out=copy_out, clear_cell=clear_cell)


def reach(cs, ss, off, n_rho: int, extent=None):
    """Per θ row, the first and last ρ bin that points inside ``extent`` (x_lo, x_hi, y_lo, y_hi)
    can take: the bins of the box's corners (a linear function is extreme at a corner), widened
    by one bin for float32 rounding, within the accumulator. The whole row without an extent.
    A tile's points reach 55-75 % of a row, so a new tile's accumulator is cleared and first
    scanned over that much."""
    if extent is None:
        return np.zeros(len(cs), np.int32), np.full(len(cs), n_rho - 1, np.int32)
    x0, x1, y0, y1 = extent
    k = bin_index(np.array([x0, x1, x0, x1])[None, :], np.array([y0, y0, y1, y1])[None, :],
                  np.asarray(cs)[:, None], np.asarray(ss)[:, None], off)
    lo = np.clip(k.min(axis=1) - 1, 0, n_rho - 1).astype(np.int32)
    hi = np.clip(k.max(axis=1) + 1, 0, n_rho - 1).astype(np.int32)
    return lo, hi


def _kit(ti, cells: int):
    """Fields and kernels for an accumulator of ``cells`` cells: the standard kit, or one sized
    for an unusually large accumulator (compiled on first use)."""
    cap = CELLS if cells <= CELLS else 1 << int(np.ceil(np.log2(cells)))
    if cap not in _kits:
        _kits[cap] = _build(ti, cap)
    return _kits[cap]


class TaichiAccumulator:
    """Kernel version of :class:`reference.NumpyAccumulator` (same methods). Its votes live in
    process-wide taichi fields, so one may be open at a time (tiles are taken in turn)."""

    def __init__(self, ti, cos_t, sin_t, k_min: int, inv_drho: float, n_rho: int, extent=None):
        cs, ss, self.off = bin_scales(cos_t, sin_t, k_min, inv_drho)
        self.shape = (len(cs), int(n_rho))
        self.size = self.shape[0] * self.shape[1]
        rows = self.shape[0]
        if self.size >= 2**31 or rows > MAX_THETAS:
            raise ValueError(f"a {self.shape[0]} x {self.shape[1]} accumulator exceeds the kernel's limits "
                             f"(2^31 cells, {MAX_THETAS} θ steps)")
        if _busy[0]:
            raise RuntimeError("a TaichiAccumulator is already open in this process; close it first")
        self.k = _kit(ti, self.size)
        self.extent = None if extent is None else tuple(float(v) for v in extent)
        lo, hi = reach(cs, ss, self.off, self.shape[1], self.extent)
        self.k["reset"](cs, ss, lo, hi)
        _busy[0] = True

    def vote(self, x, y, sign: int = 1, floor: int = 0) -> None:
        """See :meth:`reference.NumpyAccumulator.vote`. A subtraction leaves the rows bounded
        below ``floor`` as they are: most rows of a tile are, once its first peak is known, and
        each subtraction otherwise streams the whole accumulator through memory."""
        x = np.asarray(x, np.float32)
        y = np.asarray(y, np.float32)
        floor = int(floor) if sign < 0 else 0
        if sign > 0 and self.extent is not None and len(x):
            # compared in float32, as the points are binned (rounding keeps a point in its box)
            x0, x1, y0, y1 = np.asarray(self.extent, np.float32)
            if x.min() < x0 or x.max() > x1 or y.min() < y0 or y.max() > y1:
                raise ValueError(f"points outside the accumulator's extent {self.extent}")
        for s in range(0, len(x), POINTS_PER_PASS):
            xp = np.ascontiguousarray(x[s:s + POINTS_PER_PASS])
            yp = np.ascontiguousarray(y[s:s + POINTS_PER_PASS])
            self.k["vote"](xp, yp, self.shape[0], self.shape[1], float(self.off), 1 if sign > 0 else -1, floor)

    def peak(self) -> tuple[int, int, int]:
        c, r, votes = self.k["peak"](*self.shape)
        return int(c), int(r), int(votes)

    def clear_cell(self, c: int, r: int) -> None:
        self.k["clear_cell"](c, r, self.shape[1])

    def to_numpy(self) -> np.ndarray:
        out = np.empty(self.size, np.int32)
        self.k["copy_out"](out, self.shape[1])
        return out.reshape(self.shape)

    def close(self) -> None:
        _busy[0] = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
