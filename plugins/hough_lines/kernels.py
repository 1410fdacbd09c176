"""Taichi kernels of the 2D Hough transform: voting into the (θ, ρ) accumulator, subtracting a
band's votes and finding the peak, with the votes kept in taichi memory (only peaks come back).
``reference.NumpyAccumulator`` is the numpy twin; both bin with :func:`reference.bin_scales`.

Why it is written this way (each measured on the 2-core CI machine, 20 000 points × 1800 θ):
- one task owns a block of ``THETA_BLOCK`` θ rows, so there are no atomics (taichi makes ``+=`` on
  global memory atomic; a plain load/store is 2× faster) and each point loaded feeds 16
  independent increments (instruction-level parallelism instead of one dependent chain);
- the votes live in taichi *fields*, whose addressing compiles to constants: the same loop over
  ndarrays (a pointer and stride load per access) was 3–4× slower;
- the fields have a fixed capacity and the kernels name them directly (not as template
  arguments), so taichi's offline cache serves the compiled kernels to the next process: that
  saved 0.4 s of start-up per run;
- taichi's CPU backend hands a range-for to its threads in chunks of up to 512 iterations, so a
  loop over 113 θ blocks would run on one thread: the loop runs over ``blocks × TASK_STRIDE``
  iterations of which only each chunk's first does work.
- few, small kernels: a fresh process pays 40-150 ms per kernel (taichi's Python front end runs
  even when the offline cache holds the machine code), so the θ rows are padded to whole blocks
  (no remainder loop), the band-subtraction flags are always computed (no second variant: the
  compare costs nothing measurable beside the scattered increments) and small steps are merged;
- handing a loop to taichi's CPU thread pool costs about 0.1 ms, so tiny loops (copying a band's
  few hundred points) run in the launching thread.
Result: 2–3 G votes/s against 0.22 G for the previous one-θ-per-thread ndarray kernel.
"""

import numpy as np

from .reference import bin_scales

THETA_BLOCK = 16
TASK_STRIDE = 512
POINTS_PER_PASS = 1 << 20  # points are voted in passes of at most this many
MAX_THETAS = 1 << 15  # 0.0055° steps at the finest
RESCAN_BATCH = 64  # dirty rows rescanned in the first batch of a peak search
CELLS = 1 << 24  # accumulator cells of the standard kit (64 MiB); larger ones get their own

_kits: dict = {}
_busy = [False]


def _build(ti, cells: int):
    B, S = THETA_BLOCK, TASK_STRIDE
    on_cpu = ti.lang.impl.current_cfg().arch in (ti.x64, ti.arm64)
    xs = ti.field(ti.f32, POINTS_PER_PASS)
    ys = ti.field(ti.f32, POINTS_PER_PASS)
    cs = ti.field(ti.f32, MAX_THETAS)
    ss = ti.field(ti.f32, MAX_THETAS)
    flat = ti.field(ti.i32, cells)

    @ti.kernel
    def vote(xa: ti.types.ndarray(dtype=ti.f32, ndim=1), ya: ti.types.ndarray(dtype=ti.f32, ndim=1),
             n_blocks: ti.i32, n_rho: ti.i32, off: ti.f32, sign: ti.i32,
             row_arg: ti.types.ndarray(dtype=ti.i32, ndim=1), dirty: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        # θ rows come in whole blocks (the accumulator is padded to a multiple of B rows, whose
        # padding rows nobody reads): one loop body, a small kernel that loads quickly.
        # Rows whose peak cell (row_arg) is hit are flagged in ``dirty``: when a band is
        # subtracted only those need their maximum found again.
        n = xa.shape[0]
        # the points are copied into the fields; on the CPU in the launching thread (handing a loop
        # to the thread pool costs about 0.1 ms, and most votes are a band of a few hundred points)
        ti.loop_config(serialize=on_cpu)
        for i in range(n):
            xs[i] = xa[i]
            ys[i] = ya[i]
        for t in range(n_blocks * S):
            if t % S == 0:
                j0 = (t // S) * B
                cv = ti.Vector([cs[j0 + q] for q in ti.static(range(B))])
                sv = ti.Vector([ss[j0 + q] for q in ti.static(range(B))])
                row = ti.Vector([(j0 + q) * n_rho for q in ti.static(range(B))])
                peak = ti.Vector([row_arg[j0 + q] for q in ti.static(range(B))]) + row
                hit = ti.Vector([0 for q in ti.static(range(B))])
                for i in range(n):
                    a = ti.cast(xs[i] * cv + ys[i] * sv + off, ti.i32) + row
                    for q in ti.static(range(B)):
                        flat[a[q]] = flat[a[q]] + sign  # not +=: that would be atomic
                    hit |= ti.cast(a == peak, ti.i32)
                for q in ti.static(range(B)):
                    if hit[q]:
                        dirty[j0 + q] = 1

    @ti.kernel
    def row_peaks(n_theta: ti.i32, n_rho: ti.i32, dirty: ti.types.ndarray(dtype=ti.i32, ndim=1),
                  row_max: ti.types.ndarray(dtype=ti.i32, ndim=1), row_arg: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        # per dirty θ row: its largest count and the first ρ bin holding it (4 iterations per
        # row, one working: see TASK_STRIDE); a branch-free max, then the first match
        for t in range(n_theta * 4):
            if t % 4 == 0 and dirty[t // 4] != 0:
                j = t // 4
                base = j * n_rho
                best = flat[base]
                for k in range(1, n_rho):
                    best = ti.max(best, flat[base + k])
                arg = 0
                while flat[base + arg] != best:
                    arg += 1
                row_max[j] = best
                row_arg[j] = arg
                dirty[j] = 0

    @ti.kernel
    def reset(a: ti.types.ndarray(dtype=ti.f32, ndim=1), b: ti.types.ndarray(dtype=ti.f32, ndim=1), m: ti.i32):
        # a new accumulator: its θ factors (padding rows get 0) and m cells cleared
        ti.loop_config(serialize=on_cpu)
        for j in range(a.shape[0]):
            cs[j] = a[j]
            ss[j] = b[j]
        for i in range(m):
            flat[i] = 0

    @ti.kernel
    def copy_out(out: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for i in range(out.shape[0]):
            out[i] = flat[i]

    @ti.kernel
    def set_cell(i: ti.i32, v: ti.i32):
        flat[i] = v

    return dict(vote=vote, row_peaks=row_peaks, reset=reset, copy_out=copy_out, set_cell=set_cell)


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

    def __init__(self, ti, cos_t, sin_t, k_min: int, inv_drho: float, n_rho: int):
        cs, ss, self.off = bin_scales(cos_t, sin_t, k_min, inv_drho)
        self.shape = (len(cs), int(n_rho))
        self.size = self.shape[0] * self.shape[1]
        self.blocks = -(-len(cs) // THETA_BLOCK)  # θ rows padded to whole blocks
        rows = self.blocks * THETA_BLOCK
        if rows * self.shape[1] >= 2**31 or rows > MAX_THETAS:
            raise ValueError(f"a {self.shape[0]} x {self.shape[1]} accumulator exceeds the kernel's limits "
                             f"(2^31 cells, {MAX_THETAS} θ steps)")
        if not 0 <= int(self.off) < self.shape[1]:  # padding rows (cos = sin = 0) vote in the ρ = 0 bin
            raise ValueError(f"the ρ range (bins {k_min}..{k_min + self.shape[1] - 1}) must include ρ = 0")
        if _busy[0]:
            raise RuntimeError("a TaichiAccumulator is already open in this process; close it first")
        self.k = _kit(ti, rows * self.shape[1])
        pad = np.zeros(rows - len(cs), np.float32)
        self.k["reset"](np.r_[cs, pad], np.r_[ss, pad], rows * self.shape[1])
        self._row_max = np.zeros(rows, np.int32)
        self._row_arg = np.zeros(rows, np.int32)
        self._dirty = np.ones(rows, np.int32)  # rows whose (max, first bin) must be found again
        self._stale_up = True  # whether counts may have grown since the rows were last scanned
        _busy[0] = True

    def vote(self, x, y, sign: int = 1) -> None:
        x = np.asarray(x, np.float32)
        y = np.asarray(y, np.float32)
        for s in range(0, len(x), POINTS_PER_PASS):
            xp = np.ascontiguousarray(x[s:s + POINTS_PER_PASS])
            yp = np.ascontiguousarray(y[s:s + POINTS_PER_PASS])
            # a band's votes (sign -1) also flag the rows whose peak cell lost votes
            self.k["vote"](xp, yp, self.blocks, self.shape[1], float(self.off), 1 if sign > 0 else -1, self._row_arg,
                           self._dirty)
            if sign > 0:
                self._stale_up = True

    def peak(self) -> tuple[int, int, int]:
        n_theta, n_rho = self.shape
        row_max = self._row_max[:n_theta]  # (views: the padding rows are never scanned)
        flags = self._dirty[:n_theta]
        if self._stale_up:  # after votes were added, old maxima bound nothing: rescan them all
            flags[:] = 1
            self.k["row_peaks"](n_theta, n_rho, self._dirty, self._row_max, self._row_arg)
            self._stale_up = False
        dirty = flags.astype(bool)
        # subtraction only lowers counts, so a dirty row's old maximum bounds its new one: only
        # rows that could still hold (or tie) the largest count are rescanned, the highest bounds
        # first, in batches that double (dirty rows pile up over the peaks; rescanning all that
        # beat the clean rows' best cost 2-4 full accumulator scans per tile on AHN4)
        batch = RESCAN_BATCH
        while dirty.any():
            clean = row_max[~dirty]
            best = clean.max() if len(clean) else np.iinfo(np.int32).min
            cand = np.flatnonzero(dirty & (row_max >= best))
            if len(cand) == 0:
                break
            if len(cand) > batch:
                cand = cand[np.argpartition(row_max[cand], len(cand) - batch)[-batch:]]
                batch *= 2
            flags[:] = 0
            flags[cand] = 1
            self.k["row_peaks"](n_theta, n_rho, self._dirty, self._row_max, self._row_arg)
            dirty[cand] = False
        flags[:] = dirty
        c = int(np.argmax(row_max))  # first row holding the maximum: numpy's flat argmax order
        return c, int(self._row_arg[c]), int(row_max[c])

    def clear_cell(self, c: int, r: int) -> None:
        self.k["set_cell"](c * self.shape[1] + r, 0)  # lowers a count: the row's bound still holds
        self._dirty[c] = 1

    def to_numpy(self) -> np.ndarray:
        out = np.empty(self.size, np.int32)  # the real rows come first
        self.k["copy_out"](out)
        return out.reshape(self.shape)

    def close(self) -> None:
        _busy[0] = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
