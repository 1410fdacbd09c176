"""Progress bars on a terminal; silent with --quiet or when stderr is not a TTY."""

from __future__ import annotations

import sys

_quiet = False


def set_quiet(quiet: bool) -> None:
    global _quiet
    _quiet = bool(quiet)


def enabled() -> bool:
    return not _quiet and sys.stderr.isatty()


def bar(iterable=None, total=None, desc: str = "", unit: str = "it", leave: bool = False):
    """A tqdm bar that disables itself when progress is not wanted."""
    from tqdm import tqdm

    return tqdm(iterable=iterable, total=total, desc=desc, unit=unit, leave=leave,
                disable=not enabled(), file=sys.stderr, dynamic_ncols=True)
