"""Progress bars on a terminal; silent with --quiet or when stderr is not a TTY. With
``--progress-json`` (for a caller such as the QGIS provider) every update is one JSON line on
stderr instead: ``{"progress": 0.42, "desc": "dtm survey", "n": 21, "total": 50}``."""

from __future__ import annotations

import json
import sys
import time

_quiet = False
_json = False


def set_quiet(quiet: bool) -> None:
    global _quiet
    _quiet = bool(quiet)


def set_json(on: bool) -> None:
    global _json
    _json = bool(on)


def enabled() -> bool:
    return not _quiet and sys.stderr.isatty()


class JsonBar:
    """The tqdm calls the toolbox makes, as JSON lines (at most five a second, and the last)."""

    def __init__(self, iterable=None, total=None, desc: str = ""):
        self.iterable, self.total, self.desc, self.n = iterable, total, desc, 0
        if total is None and iterable is not None and hasattr(iterable, "__len__"):
            self.total = len(iterable)
        self._last = 0.0
        self._emit(force=True)

    def _emit(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < 0.2:
            return
        self._last = now
        frac = min(1.0, self.n / self.total) if self.total else None
        print(json.dumps({"progress": frac, "desc": self.desc, "n": self.n, "total": self.total}), file=sys.stderr,
              flush=True)

    def __iter__(self):
        for item in self.iterable:
            yield item
            self.update(1)

    def update(self, n: int = 1) -> None:
        self.n += n
        self._emit(force=self.total is not None and self.n >= self.total)

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self):  # the stages' bar is used as ``with ctx.progress(...) as bar``
        return self

    def __exit__(self, *exc):
        self.close()


def bar(iterable=None, total=None, desc: str = "", unit: str = "it", leave: bool = False):
    """A tqdm bar that disables itself when progress is not wanted."""
    if _json:
        return JsonBar(iterable, total, desc)
    from tqdm import tqdm

    return tqdm(iterable=iterable, total=total, desc=desc, unit=unit, leave=leave,
                disable=not enabled(), file=sys.stderr, dynamic_ncols=True)
