"""The one place where taichi is initialised: lazily, the first time a kernel is needed.

The architecture is chosen by ``set_arch()`` (the CLI's ``--arch``), else the environment
variable ``TOOLBOX_ARCH``, else ``auto``: CUDA when a CUDA device is usable, the CPU otherwise.
Importing this module costs nothing; ``toolbox list`` never imports taichi.
"""

from __future__ import annotations

import contextlib
import io
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
        with contextlib.redirect_stdout(io.StringIO()):  # taichi prints a banner on import
            import taichi as ti
        arch = requested_arch()
        kwargs = dict(log_level=ti.WARN, offline_cache=True, random_seed=0)
        if arch == "auto":
            try:
                ti.init(arch=ti.cuda, **kwargs)
            except Exception:
                ti.init(arch=ti.cpu, **kwargs)
        else:
            ti.init(arch=getattr(ti, "x64" if arch == "cpu" else arch), **kwargs)
        _arch_used = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
        log.info("taichi initialised on %s", _arch_used)
        _ti = ti
        return ti


def arch_used() -> str | None:
    """The architecture taichi runs on, or None when no kernel has run yet."""
    return _arch_used
