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


def check_folder(path: Path) -> None:
    """Fail early when the folder an output writes its files into is missing or read-only."""
    path = Path(path)
    if not path.is_dir():
        raise DataError(f"output folder {str(path)!r} does not exist; create it first")
    if not os.access(path, os.W_OK):
        raise DataError(f"output folder {str(path)!r} is not writable; choose another output location")


def write_folder(files, folder, overwrite: bool = False) -> list[str]:
    """Write ``files`` ({relative path: bytes or str}) under ``folder``: each top-level entry (a
    file, or a sub-folder with everything in it) is written under a temporary name and renamed
    when complete, so a failure leaves none of them half-written. Returns the top-level names."""
    import shutil

    folder = Path(folder)
    groups: dict[str, dict] = {}
    for rel, content in files.items():
        parts = Path(rel).parts
        if not parts or Path(rel).is_absolute() or ".." in parts:
            raise ValueError(f"folder output: {rel!r} is not a relative path inside the folder")
        groups.setdefault(parts[0], {})[Path(*parts[1:]) if len(parts) > 1 else None] = content
    for top in groups:
        if (folder / top).exists() and not overwrite:
            raise UsageError(f"output {str(folder / top)!r} exists; pass --overwrite to replace it or choose another folder")
    written: list[str] = []
    try:
        for top, members in groups.items():
            target = folder / top
            tmp = folder / f".{top}.{uuid.uuid4().hex[:8]}.partial"
            try:
                if None in members:  # a file
                    _write_bytes(tmp, members[None])
                else:
                    for rel, content in members.items():
                        (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
                        _write_bytes(tmp / rel, content)
                if target.is_dir():
                    shutil.rmtree(target)
                os.replace(tmp, target)
                written.append(top)
            finally:
                if tmp.is_dir():
                    shutil.rmtree(tmp, ignore_errors=True)
                else:
                    with contextlib.suppress(FileNotFoundError):
                        tmp.unlink()
    except BaseException:
        remove_entries(folder, written)
        raise
    return written


def _write_bytes(path: Path, content) -> None:
    if isinstance(content, str):
        content = content.encode("utf-8")
    path.write_bytes(content)


def remove_entries(folder, names) -> None:
    """Remove what ``write_folder`` wrote (a failed run keeps no output)."""
    import shutil

    for n in names:
        p = Path(folder) / n
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
