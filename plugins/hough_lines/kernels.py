"""Taichi kernels of the 2D Hough transform: voting into the (θ, ρ) accumulator, subtracting a
band's votes and finding the peak, with the votes kept in taichi memory (only peaks come back).
``reference.NumpyAccumulator`` is the numpy twin; both bin with :func:`reference.bin_scales`.

Why it is written this way (each measured on the 2-core CI machine, 20 000 points × 1800 θ):
- one task owns a block of ``THETA_BLOCK`` θ rows, so there are no atomics (taichi makes ``+=`` on
  global memory atomic; a plain load/store is 2× faster) and each point loaded feeds 16 independent
  increments (instruction-level parallelism instead of one dependent chain);
- the votes live in taichi *fields*, whose addressing compiles to constants: the same loop over
  ndarrays (a pointer and stride load per access) was 3–4× slower;
- taichi's CPU backend hands a range-for to its threads in chunks of up to 512 iterations, so a
  loop over 225 θ blocks would run on one thread: the loop runs over ``blocks × TASK_STRIDE``
  iterations of which only each chunk's first does work.
Result: 2–3 G votes/s against 0.22 G for the previous one-θ-per-thread ndarray kernel.
"""

import numpy as np

from .reference import bin_scales

THETA_BLOCK = 16
TASK_STRIDE = 512

_state: dict = {"busy": False}


def _build(ti):
    B, S = THETA_BLOCK, TASK_STRIDE

    @ti.kernel
    def vote(xs: ti.template(), ys: ti.template(), cs: ti.template(), ss: ti.template(), flat: ti.template(),
             n: ti.i32, n_theta: ti.i32, n_rho: ti.i32, off: ti.f32, sign: ti.i32):
        for t in range(((n_theta + B - 1) // B) * S):
            if t % S == 0:
                j0 = (t // S) * B
                if j0 + B <= n_theta:
                    cv = ti.Vector([cs[j0 + q] for q in ti.static(range(B))])
                    sv = ti.Vector([ss[j0 + q] for q in ti.static(range(B))])
                    row = ti.Vector([(j0 + q) * n_rho for q in ti.static(range(B))])
                    for i in range(n):
                        a = ti.cast(xs[i] * cv + ys[i] * sv + off, ti.i32) + row
                        for q in ti.static(range(B)):
                            flat[a[q]] = flat[a[q]] + sign  # not +=: that would be atomic
                else:  # the last, partial block
                    for j in range(j0, n_theta):
                        for i in range(n):
                            a = j * n_rho + ti.cast(xs[i] * cs[j] + ys[i] * ss[j] + off, ti.i32)
                            flat[a] = flat[a] + sign

    @ti.kernel
    def unvote(xs: ti.template(), ys: ti.template(), cs: ti.template(), ss: ti.template(), flat: ti.template(),
               n: ti.i32, n_theta: ti.i32, n_rho: ti.i32, off: ti.f32,
               row_arg: ti.types.ndarray(dtype=ti.i32, ndim=1), dirty: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        # subtract a band's votes (few points: one θ per task) and mark the rows whose peak cell
        # lost votes: only those need their maximum found again
        for t in range(n_theta * 4):
            if t % 4 == 0:
                j = t // 4
                peak_bin = row_arg[j]
                hit = 0
                for i in range(n):
                    k = ti.cast(xs[i] * cs[j] + ys[i] * ss[j] + off, ti.i32)
                    flat[j * n_rho + k] = flat[j * n_rho + k] - 1
                    if k == peak_bin:
                        hit = 1
                if hit:
                    dirty[j] = 1

    @ti.kernel
    def row_peaks(flat: ti.template(), n_theta: ti.i32, n_rho: ti.i32, dirty: ti.types.ndarray(dtype=ti.i32, ndim=1),
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
    def load_pairs(a: ti.types.ndarray(dtype=ti.f32, ndim=1), b: ti.types.ndarray(dtype=ti.f32, ndim=1),
                   fa: ti.template(), fb: ti.template()):
        for i in range(a.shape[0]):
            fa[i] = a[i]
            fb[i] = b[i]

    @ti.kernel
    def clear(flat: ti.template(), m: ti.i32):
        for i in range(m):
            flat[i] = 0

    @ti.kernel
    def copy_out(flat: ti.template(), out: ti.types.ndarray(dtype=ti.i32, ndim=1)):
        for i in range(out.shape[0]):
            out[i] = flat[i]

    return dict(vote=vote, unvote=unvote, row_peaks=row_peaks, load_pairs=load_pairs, clear=clear, copy_out=copy_out)


def _field(ti, name: str, dtype, size: int):
    """A 1-D field of at least ``size`` elements, shared by all accumulators of the process and
    grown (never shrunk): a new field means new kernel instances, so it is reused."""
    f = _state.get(name)
    if f is None or f.shape[0] < size:
        f = ti.field(dtype, max(1 << 20, size + size // 2) if name == "flat" else max(1024, size + size // 2))
        _state[name] = f
    return f


class TaichiAccumulator:
    """Kernel version of :class:`reference.NumpyAccumulator` (same methods). Its votes live in
    process-wide taichi fields, so one may be open at a time (tiles are taken in turn)."""

    def __init__(self, ti, cos_t, sin_t, k_min: int, inv_drho: float, n_rho: int):
        if _state["busy"]:
            raise RuntimeError("a TaichiAccumulator is already open in this process; close it first")
        if "k" not in _state:
            _state["k"] = _build(ti)
        self.ti, self.k = ti, _state["k"]
        cs, ss, self.off = bin_scales(cos_t, sin_t, k_min, inv_drho)
        self.shape = (len(cs), int(n_rho))
        self.size = self.shape[0] * self.shape[1]
        if self.size >= 2**31:
            raise ValueError(f"a {self.shape[0]} x {self.shape[1]} accumulator exceeds 2^31 cells")
        self.cs = _field(ti, "cs", ti.f32, len(cs))
        self.ss = _field(ti, "ss", ti.f32, len(cs))
        self.k["load_pairs"](cs, ss, self.cs, self.ss)
        self.flat = _field(ti, "flat", ti.i32, self.size)
        self.k["clear"](self.flat, self.size)
        self._row_max = np.zeros(self.shape[0], np.int32)
        self._row_arg = np.zeros(self.shape[0], np.int32)
        self._dirty = np.ones(self.shape[0], np.int32)  # rows whose (max, first bin) must be found again
        _state["busy"] = True

    def _load(self, x, y):
        x = np.ascontiguousarray(x, np.float32)
        y = np.ascontiguousarray(y, np.float32)
        xs = _field(self.ti, "xs", self.ti.f32, len(x))
        ys = _field(self.ti, "ys", self.ti.f32, len(x))
        self.k["load_pairs"](x, y, xs, ys)
        return xs, ys

    def vote(self, x, y, sign: int = 1) -> None:
        if len(x) == 0:
            return
        xs, ys = self._load(x, y)
        if sign < 0 and len(x) * self.shape[0] < 50_000_000:
            # a band's votes: also flags the rows whose peak cell changed
            self.k["unvote"](xs, ys, self.cs, self.ss, self.flat, len(x), self.shape[0], self.shape[1],
                             float(self.off), self._row_arg, self._dirty)
            return
        self.k["vote"](xs, ys, self.cs, self.ss, self.flat, len(x), self.shape[0], self.shape[1], float(self.off),
                       int(sign))
        self._dirty[:] = 1

    def peak(self) -> tuple[int, int, int]:
        if self._dirty.any():
            self.k["row_peaks"](self.flat, self.shape[0], self.shape[1], self._dirty, self._row_max, self._row_arg)
        c = int(np.argmax(self._row_max))  # first row holding the maximum: numpy's flat argmax order
        return c, int(self._row_arg[c]), int(self._row_max[c])

    def clear_cell(self, c: int, r: int) -> None:
        self.flat[c * self.shape[1] + r] = 0
        self._dirty[c] = 1

    def to_numpy(self) -> np.ndarray:
        out = np.empty(self.size, np.int32)
        self.k["copy_out"](self.flat, out)
        return out.reshape(self.shape)

    def close(self) -> None:
        _state["busy"] = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
