"""SIGINT and SIGTERM held back around code that must not be interrupted half-way (standard
library only): a few renames that belong together, and VTK's lazy module imports, inside which
a KeyboardInterrupt crashes the interpreter (segmentation fault) instead of unwinding."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager


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
    signal mask is not touched, so a child process started inside the block (``subprocess.Popen``:
    it inherits the mask, not the handlers) can still be stopped by SIGINT/SIGTERM. Outside the
    main thread, a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []

    def record(signum: int, frame: object) -> None:
        came.append(signum)

    old = {sig: signal.signal(sig, record) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)  # None: not set from Python
        if came:
            signal.raise_signal(came[0])
