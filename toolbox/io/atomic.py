"""Atomic output: write under a temporary name in the target folder, rename when complete.

Inside :func:`staged_outputs` (one run of an algorithm), the renames wait for the run: every file
of every output, sidecars included, is renamed into place by ``commit`` once all were written, and
a failed or interrupted run leaves none of them (nor a temporary file) behind."""

from __future__ import annotations

import contextlib
import contextvars
import os
import shutil
import signal
import threading
import uuid
from pathlib import Path

from ..errors import DataError, UsageError

# the longest file name most file systems take (ext4, XFS, APFS, NTFS: 255 bytes)
NAME_MAX_BYTES = 255
# what a temporary name adds to the final one: "." + 8 hex digits + ".partial"
TEMP_NAME_EXTRA = 18


class Staging:
    """The files of one run written under temporary names, each waiting for its final name."""

    def __init__(self):
        self._lock = threading.Lock()
        self.pending: list[tuple[Path, Path]] = []  # (temporary, final)
        self.removals: list[Path] = []  # stale sidecars of an earlier output, removed on commit
        self.created_dirs: list[Path] = []  # folders made for the outputs, removed again on failure

    def add(self, tmp: Path, final: Path) -> None:
        with self._lock:
            self.pending.append((Path(tmp), Path(final)))

    def remove_on_commit(self, path: Path) -> None:
        with self._lock:
            self.removals.append(Path(path))

    def make_dirs(self, folder: Path) -> None:
        """Create ``folder`` (and missing parents), remembering what was new."""
        self.created_dirs.extend(make_folder(folder))

    def commit(self) -> None:
        """Rename every staged file into place; SIGINT and SIGTERM wait until the renames are done."""
        blocked = _block_signals()
        try:
            with self._lock:
                for path in self.removals:
                    with contextlib.suppress(FileNotFoundError):
                        path.unlink()
                for tmp, final in self.pending:
                    if tmp.is_dir() and final.is_dir():
                        shutil.rmtree(final)
                    os.replace(tmp, final)
                self.pending.clear()
                self.removals.clear()
                self.created_dirs.clear()
        finally:
            _unblock_signals(blocked)

    def rollback(self) -> None:
        with self._lock:
            for tmp, _ in self.pending:
                _remove_temporary(tmp)
            self.pending.clear()
            self.removals.clear()
            for d in reversed(self.created_dirs):  # only the folders made for this run, if still empty
                with contextlib.suppress(OSError):
                    d.rmdir()
            self.created_dirs.clear()


_STAGING: contextvars.ContextVar[Staging | None] = contextvars.ContextVar("toolbox_staging", default=None)


@contextlib.contextmanager
def staged_outputs():
    """Stage every atomic write inside the block; the caller calls ``commit()`` when the run has
    succeeded. Leaving the block without a commit (an error, Ctrl-C, SIGTERM) removes them all."""
    staging = Staging()
    token = _STAGING.set(staging)
    try:
        yield staging
    finally:
        _STAGING.reset(token)
        staging.rollback()  # nothing left after a commit


def current_staging() -> Staging | None:
    return _STAGING.get()


def place(tmp: Path, final: Path) -> None:
    """Give a finished temporary file its final name: now, or at the run's commit."""
    staging = _STAGING.get()
    if staging is not None:
        staging.add(tmp, final)
    else:
        os.replace(tmp, final)


def _block_signals():
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        return None
    return signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})


def _unblock_signals(previous) -> None:
    if previous is not None:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _remove_temporary(tmp: Path) -> None:
    if tmp.is_dir():
        shutil.rmtree(tmp, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    # GDAL may leave auxiliary files next to the temporary name
    for extra in tmp.parent.glob(tmp.name + ".*"):
        with contextlib.suppress(OSError):
            extra.unlink()


def make_folder(folder) -> list[Path]:
    """Make an output folder and its missing parents; returns the folders made, outermost first
    (for removing them again). One-line DataError when a file is in the way or the system says no."""
    folder = Path(folder) if str(folder) else Path(".")
    missing, p = [], folder
    while not p.exists() and p != p.parent:
        missing.append(p)
        p = p.parent
    if not p.is_dir():
        where = f"output folder {str(folder)!r}" + ("" if p == folder else f" cannot be made: {str(p)!r}")
        raise DataError(f"{where} is a file, not a folder; choose another output location")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"output folder {str(folder)!r} cannot be made ({exc.strerror}); choose another output "
                        "location") from None
    return list(reversed(missing))


def check_name_length(path: Path) -> None:
    """Refuse a file name the file system cannot hold (with the temporary name's extra characters)."""
    parts = Path(path).parts
    for i, part in enumerate(parts):
        limit = NAME_MAX_BYTES - (TEMP_NAME_EXTRA if i == len(parts) - 1 else 0)
        if len(os.fsencode(part)) > limit:
            raise UsageError(f"output name {part[:40]!r}... is {len(os.fsencode(part))} bytes long; a file or folder "
                             f"name may have at most {limit} here: choose a shorter name")


def check_writable(path: Path, overwrite: bool) -> None:
    """Fail early (before any work) when ``path`` cannot or must not be written."""
    path = Path(path)
    check_name_length(path)
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
        place(tmp, path)
    except BaseException:
        _remove_temporary(tmp)
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
    staging = _STAGING.get()
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
                if staging is not None:
                    staging.add(tmp, target)
                    tmp = None  # the staging owns it now
                else:
                    if target.is_dir():
                        shutil.rmtree(target)
                    os.replace(tmp, target)
                written.append(top)
            finally:
                if tmp is not None:
                    _remove_temporary(tmp)
    except BaseException:
        if staging is None:
            remove_entries(folder, written)
        raise
    return written


def _write_bytes(path: Path, content) -> None:
    if isinstance(content, str):
        content = content.encode("utf-8")
    path.write_bytes(content)


def remove_entries(folder, names) -> None:
    """Remove what ``write_folder`` wrote (a failed run keeps no output)."""
    for n in names:
        p = Path(folder) / n
        if p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
