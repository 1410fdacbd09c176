"""Atomic output: write under a temporary name in the target folder, rename when complete."""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path

from ..errors import DataError, UsageError


def check_writable(path: Path, overwrite: bool) -> None:
    """Fail early (before any work) when ``path`` cannot or must not be written."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise UsageError(f"output {str(path)!r} exists; pass --overwrite to replace it or choose another name")
    if path.is_dir():
        raise UsageError(f"output {str(path)!r} is a folder; give a file name")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.exists():
        raise DataError(f"output folder {str(parent)!r} does not exist; create it first")
    if not parent.is_dir():
        raise DataError(f"output folder {str(parent)!r} is a file, not a folder; choose another output location")
    if not os.access(parent, os.W_OK):
        raise DataError(f"output folder {str(parent)!r} is not writable; choose another output location")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, overwrite: bool = False):
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds.

    The temporary name keeps the extension (drivers choose formats by it) and starts with a dot
    so that a half-written file is never mistaken for a result. On any exception the temporary
    file is removed and the exception propagates: no partial output is ever left behind.
    """
    path = Path(path)
    check_writable(path, overwrite)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:8]}.partial{path.suffix}")
    try:
        yield tmp
        if not tmp.exists():
            raise DataError(f"writer produced no file for {str(path)!r}")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        # GDAL may leave auxiliary files next to the temporary name
        for extra in tmp.parent.glob(tmp.name + ".*"):
            with contextlib.suppress(OSError):
                extra.unlink()
        raise
