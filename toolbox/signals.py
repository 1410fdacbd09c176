"""SIGINT and SIGTERM as exceptions, remembered: a run interrupted anywhere (even inside a C
library that turns the interrupt into an I/O error of its own, as lazrs does) still ends as
interrupted, with exit code 130 or 143, after its staged outputs were removed."""

from __future__ import annotations

import signal
import threading

_received: list[int] = []
_installed = [False]


class Terminated(BaseException):
    """SIGTERM: like KeyboardInterrupt, not an error of the run (``except Exception`` lets it pass)."""

    def __init__(self, signum: int = signal.SIGTERM):
        super().__init__(f"terminated by signal {signum}")
        self.signum = signum


def _handler(signum, frame):
    _received.append(signum)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


def install() -> None:
    """Route SIGINT and SIGTERM through the handler (main thread only; processes forked later
    inherit it)."""
    if threading.current_thread() is not threading.main_thread():
        return
    signal.signal(signal.SIGINT, _handler)
    signal.signal(signal.SIGTERM, _handler)
    _installed[0] = True


def installed() -> bool:
    return _installed[0]


def received() -> int | None:
    """The first signal this process received since start (None: none)."""
    return _received[0] if _received else None


def exit_code(signum: int) -> int:
    return 128 + int(signum)
