"""The one place where taichi is initialised: lazily, the first time a kernel is needed.

The architecture is chosen by ``set_arch()`` (the CLI's ``--arch``), else the environment
variable ``TOOLBOX_ARCH``, else ``auto``: CUDA when a CUDA device is usable, the CPU otherwise.
Importing this module costs nothing; ``toolbox list`` never imports taichi.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading

from .errors import UsageError

log = logging.getLogger(__name__)
ARCHES = ("auto", "cpu", "cuda", "vulkan")
_lock = threading.Lock()
_ti = None
_arch_requested: str | None = None
_arch_used: str | None = None


def set_arch(arch: str | None) -> None:
    """Request an architecture before the first kernel runs (later requests cannot change it)."""
    global _arch_requested
    if arch is None:
        return
    if arch not in ARCHES:
        raise UsageError(f"--arch {arch!r} is not known; use one of {', '.join(ARCHES)}")
    if _ti is not None and arch != "auto" and arch != _arch_used:
        log.warning("taichi already runs on %s; --arch %s ignored", _arch_used, arch)
    _arch_requested = arch


def requested_arch() -> str:
    arch = _arch_requested or os.environ.get("TOOLBOX_ARCH", "auto").lower()
    if arch not in ARCHES:
        raise UsageError(f"TOOLBOX_ARCH={arch!r} is not known; use one of {', '.join(ARCHES)}")
    return arch


def taichi():
    """Return the initialised ``taichi`` module."""
    global _ti, _arch_used
    if _ti is not None:
        return _ti
    with _lock:
        if _ti is not None:
            return _ti
        if not os.environ.get("HOME"):  # taichi's runtime aborts without a home folder (bare CI, services)
            import tempfile

            os.environ["HOME"] = tempfile.gettempdir()
        # taichi prints a banner on import and chatter on init: keep stdout clean for --json
        os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")
        os.environ.setdefault("TI_ENABLE_PYBUF", "0")
        with open(os.devnull, "w") as devnull, contextlib.redirect_stdout(devnull):
            import taichi as ti

            arch = requested_arch()
            # fast_math off: kernels must agree with their numpy references vote for vote
            kwargs = dict(log_level=ti.ERROR, offline_cache=True, random_seed=0, fast_math=False)
            if arch == "auto":
                arch = "cuda" if _cuda_present() else "cpu"
            try:
                ti.init(arch=getattr(ti, "x64" if arch == "cpu" else arch), **kwargs)
            except Exception as exc:
                raise UsageError(f"taichi cannot run on {arch} here ({exc}); use --arch cpu") from None
        _arch_used = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
        log.info("taichi initialised on %s", _arch_used)
        _ti = ti
        return ti


def _cuda_present() -> bool:
    """Whether a CUDA driver library loads (without asking taichi, which warns loudly)."""
    import ctypes

    for name in ("libcuda.so.1", "libcuda.so", "nvcuda.dll"):
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


def arch_used() -> str | None:
    """The architecture taichi runs on, or None when no kernel has run yet."""
    return _arch_used
