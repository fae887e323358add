"""SIGINT and SIGTERM held back around code that must not be interrupted half-way (standard
library only): a few renames that belong together, and VTK's lazy module imports, inside which
a KeyboardInterrupt crashes the interpreter (segmentation fault) instead of unwinding."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


@contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back while the block runs; a signal that came meanwhile is
    delivered (and raises, e.g. KeyboardInterrupt) when it ends. Outside the main thread, a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


@contextmanager
def signals_deferred() -> Iterator[None]:
    """Defer SIGINT and SIGTERM while the block runs: a signal that comes meanwhile is recorded by a
    temporary handler and re-raised (to the handler that was in place) when the block ends, so that
    the caller's ``except``/``finally`` around the block sees it. Unlike :func:`signals_held`, the
    signal mask is left alone while the block runs, so a child process started inside it
    (``subprocess.Popen``: it inherits the mask, not the handlers) can still be stopped by
    SIGINT/SIGTERM. A signal that is ignored stays ignored. Outside the main thread, a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []

    def record(signum: int, frame: object) -> None:
        came.append(signum)

    sigs = (signal.SIGINT, signal.SIGTERM)
    old: dict[int, Any] = {}
    # the handlers are swapped with both signals held, so that neither lands between the two
    # swaps (it would leave the other handler swapped for good)
    with signals_held():
        wanted: dict[int, Any] = {sig: record for sig in sorted(sigs) if signal.getsignal(sig) is not signal.SIG_IGN}
        error = _set_handlers(wanted, old)
        if error is not None:  # a signal from before the block, handled as it came: no block then
            _set_handlers(old, {})
            raise error
    try:
        yield
    finally:
        with signals_held():
            error = _set_handlers(old, {})
        if error is not None:
            raise error
        for sig in dict.fromkeys(came):
            signal.raise_signal(sig)


def _set_handlers(handlers: dict[int, Any], previous: dict[int, Any]) -> BaseException | None:
    """Install every handler of ``handlers`` (None: SIG_DFL), their predecessors into ``previous``.
    ``signal.signal`` first runs the Python handlers of signals already pending, which may raise:
    the swap is then tried again (the pending signal is spent), and the first such exception
    returned for the caller to raise once every handler is in place."""
    error: BaseException | None = None
    for sig, handler in handlers.items():
        while True:
            try:
                previous[sig] = signal.signal(sig, signal.SIG_DFL if handler is None else handler)
                break
            except BaseException as exc:  # noqa: BLE001 - a pending signal's handler raised
                error = error or exc
    return error
