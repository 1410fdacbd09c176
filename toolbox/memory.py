"""The C allocator's settings for array-heavy runs (glibc on Linux only).

numpy takes every temporary array of more than 128 KiB from glibc's ``malloc``, which by default
maps such blocks fresh from the kernel and unmaps them on ``free`` (or trims the heap top back to
the kernel). Each new block is then paid again in page faults: on the 2-core CI machine computing
the cell index of 43 000 points took 0.70 ms instead of 0.17, and a 700 000-point power-line run
took 0.72-0.78 s instead of 0.61-0.73 s (best of 4, processes alternated). Keeping blocks up to
32 MiB on the heap and the heap's free top up to 256 MiB lets the arrays of one run reuse the
memory of the last.

Set once per process, on the first run. ``TOOLBOX_MALLOC_TUNE=0`` leaves the allocator alone; so
does any ``MALLOC_*_`` or ``GLIBC_TUNABLES=glibc.malloc.*`` setting already in the environment
(the user's choice wins). The cost: a process keeps up to 256 MiB of freed heap (a 10-million-point
``dtm`` run peaked at 1.75 GB instead of 1.65).
"""

from __future__ import annotations

import ctypes
import os
import sys

# mallopt(3) parameters
M_TRIM_THRESHOLD = -1
M_TOP_PAD = -2
M_MMAP_THRESHOLD = -3

MMAP_THRESHOLD_BYTES = 32 << 20  # glibc's largest on 64-bit (HEAP_MAX_SIZE / 2)
TRIM_THRESHOLD_BYTES = 256 << 20
TOP_PAD_BYTES = 16 << 20

_state: dict = {}


def tune_allocator() -> bool:
    """Apply the settings above (once); True when they are in effect."""
    if "applied" in _state:
        return _state["applied"]
    _state["applied"] = False
    if not sys.platform.startswith("linux") or os.environ.get("TOOLBOX_MALLOC_TUNE", "1") == "0":
        return False
    if any(k.startswith("MALLOC_") and k.endswith("_") for k in os.environ) or \
            "glibc.malloc." in os.environ.get("GLIBC_TUNABLES", ""):
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl, ...): its own allocator, left alone
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    ok = all(mallopt(p, v) == 1 for p, v in ((M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES),
                                             (M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES),
                                             (M_TOP_PAD, TOP_PAD_BYTES)))
    _state["applied"] = ok
    return ok


def total_ram_bytes() -> int:
    """This machine's physical memory (8 GiB where the system does not say)."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 8 << 30


DEFAULT_BYTES_PER_POINT = 150  # a dtm run's peak per point (5 M points, 0.76 GB); algorithms declare their own
MEMORY_SHARE = 0.9  # of the memory free now: what a run may plan to take


def available_ram_bytes() -> int:
    """Memory free for a new run now (MemAvailable), or the machine's total where not known."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return total_ram_bytes()


def check_fits(alg, path, n_points: int) -> None:
    """Refuse, before reading, an input whose run would not fit in memory: the kernel would kill
    it with no message. The way out is a survey run in tiles, whose memory is a tile's."""
    from .errors import UsageError

    per_point = alg.bytes_per_point or DEFAULT_BYTES_PER_POINT
    need, free = n_points * per_point, available_ram_bytes() * MEMORY_SHARE
    if need > free:
        raise UsageError(
            f"input {str(path)!r} holds {n_points:,} points: {alg.id} needs about {need / 2**30:.1f} GiB for them "
            f"({per_point} bytes a point), more than the {free / 2**30:.1f} GiB free here; run it in tiles: "
            f"toolbox run {alg.id} {path} -o FOLDER --tile-size-m 500")
