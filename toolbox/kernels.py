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
_warned_fallback = False  # the CUDA fallback was already announced (once per process)


def set_arch(arch: str | None) -> None:
    """Request an architecture before the first kernel runs (later requests cannot change it)."""
    global _arch_requested, _warned_fallback
    if arch is None:
        return
    if arch not in ARCHES:
        raise UsageError(f"--arch {arch!r} is not known; use one of {', '.join(ARCHES)}")
    if _ti is not None and arch != "auto" and arch != _arch_used:
        log.warning("taichi already runs on %s; --arch %s ignored", _arch_used, arch)
    _arch_requested = arch
    if arch == "cuda" and _ti is None and not _warned_fallback and not _cuda_present():
        _warned_fallback = True
        log.warning("--arch cuda: no CUDA driver found here; the kernels will run on the CPU")


def started() -> bool:
    """Whether ``taichi()`` has run in this process (without starting it)."""
    return _ti is not None


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
        with open(os.devnull, "w") as devnull, contextlib.redirect_stdout(devnull), _source_lines_from_linecache():
            import taichi as ti

            _speed_up_kernel_decoration(ti)

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
        if arch in ("cuda", "vulkan") and _arch_used != arch and not _warned_fallback:
            log.warning("--arch %s: taichi found no %s device here; the kernels run on the CPU (%s)", arch, arch,
                        _arch_used)
        _ti = ti
        return ti


def _frame_line(frame) -> str:
    """The source line a frame is at, from linecache (what ``inspect.getframeinfo`` finds, without
    its ``inspect.getmodule`` scan of every loaded module)."""
    import linecache

    return linecache.getline(frame.f_code.co_filename, frame.f_lineno, frame.f_globals)


@contextlib.contextmanager
def _source_lines_from_linecache():
    """While taichi is imported, ``inspect.getframeinfo`` (context 1) reads the line from linecache.

    taichi asks for the caller's source line once per ``@ti.func`` / ``@ti.kernel`` it decorates
    (to tell class members apart), and the standard function scans all of ``sys.modules`` each
    time (1200 modules once pandas and scipy are loaded): importing and initialising taichi took
    0.44-0.60 s, 0.26-0.28 s with this. Same answer for code in files; restored afterwards."""
    import inspect

    original = inspect.getframeinfo

    def getframeinfo(frame, context=1):
        if context != 1 or not hasattr(frame, "f_code"):
            return original(frame, context)
        line = _frame_line(frame)
        return inspect.Traceback(frame.f_code.co_filename, frame.f_lineno, frame.f_code.co_name,
                                 [line] if line else None, 0 if line else None)

    inspect.getframeinfo = getframeinfo
    try:
        yield
    finally:
        inspect.getframeinfo = original


def _speed_up_kernel_decoration(ti) -> None:
    """The same for kernels decorated later (the plugins'): taichi's class-member test reads the
    decorating frame's line from linecache. Left as it is if taichi's internals differ."""
    import sys

    impl = getattr(ti.lang, "kernel_impl", None)
    patterns = getattr(impl, "_KERNEL_CLASS_STACKFRAME_STMT_RES", None)
    if impl is None or patterns is None or not callable(getattr(impl, "_inside_class", None)):
        return

    def _inside_class(level_of_class_stackframe):
        try:
            first = _frame_line(sys._getframe(level_of_class_stackframe)).strip()
        except Exception:  # noqa: BLE001 - as taichi's own: no frame, no source -> not a class
            return False
        return any(p.match(first) for p in patterns)

    impl._inside_class = _inside_class


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
