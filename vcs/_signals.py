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
