"""The port to the board as the session uses it: writes under one lock, whether the port
is closed or there, reopening a device that vanished, and closing it.

``Wire.write`` raises ``WcdriveConnectionError`` (naming the port) when the port is
closed, gone or the write fails; the caller holds ``lock`` around it (``send`` takes
it). ``reopen`` replaces ``port`` with a new one; ``close`` is the way out.

Why the lock is reentrant: a signal handler or a finalizer may run on a thread in the
middle of a write and must still get its stop out; ``writing`` tells it that a line was
cut short (``Session.stop_line``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from wcdrive.errors import WcdriveConnectionError
from wcdrive.transports.port import CancellablePort, Port

__all__ = ["Wire"]


class Wire:
    """``port``, named ``name`` in every error."""

    def __init__(self, port: Port, name: str) -> None:
        self.port = port
        self.name = name
        #: Held around every write (and the send order noted with it).
        self.lock = threading.RLock()
        #: Set once the port is closed for good.
        self.closed = threading.Event()
        self._writing = False                  # a write is under way (interrupted: a partial line)
        self._up = threading.Event()           # the port is there (cleared while reopening)
        self._up.set()

    @property
    def writing(self) -> bool:
        """True while a write is under way (seen from a thread that interrupted it)."""
        return self._writing

    def write(self, data: bytes) -> None:
        """Writes ``data``; the caller holds ``lock``."""
        if self.closed.is_set():
            raise WcdriveConnectionError(f"the link to {self.name} is closed: connect() again")
        if not self._up.is_set():
            raise WcdriveConnectionError(f"the link to {self.name} is lost (unplugged?); reopening "
                                         "it: the board's watchdog has stopped the chair")
        self._writing = True
        try:
            self.port.write(data)
        except Exception as exc:                # pyserial's, the OS's, python-can's: name the port
            raise WcdriveConnectionError(
                f"writing to {self.name} failed ({exc}); is it still plugged in?") from exc
        finally:
            self._writing = False

    def send(self, data: bytes) -> None:
        """Writes ``data`` under ``lock``."""
        with self.lock:
            self.write(data)

    def read(self) -> bytes:
        """What the port has (at least one byte, or nothing after its timeout); raises
        what the port raises when the device vanished."""
        return self.port.read(max(1, self.port.in_waiting))

    def bytes_waiting(self) -> bool:
        """Whether the board's bytes wait unread in the port."""
        try:
            return int(self.port.in_waiting) > 0
        except Exception:
            return False

    def reopen(self, opener: Callable[[], Port], timeout: float) -> bool:
        """The device vanished: opens it again with ``opener`` until ``timeout`` s have
        passed or the wire is closed; returns whether it did. Writes fail until
        ``restored``."""
        self._up.clear()
        try:
            self.port.close()
        except Exception:
            pass
        deadline = time.monotonic() + timeout
        while not self.closed.is_set() and time.monotonic() < deadline:
            try:
                port = opener()
            except Exception:
                time.sleep(0.25)
                continue
            self.port = port
            if self.closed.is_set():            # closed meanwhile: let the device go
                try:
                    port.close()
                except Exception:
                    pass
                return False
            return True
        return False

    def restored(self) -> None:
        """The reopened port takes writes again."""
        self._up.set()

    def close(self, last_words: bytes = b"") -> None:
        """Writes ``last_words`` (best effort), then closes the port, waking a read that
        waits. Safe to call twice, from any thread."""
        if self.closed.is_set():
            return
        locked = self.lock.acquire(timeout=0.5)
        try:
            if last_words:
                self.port.write(last_words)
            self.port.flush()
        except Exception:
            pass
        finally:
            if locked:
                self.lock.release()
        self.closed.set()
        try:
            if isinstance(self.port, CancellablePort):
                self.port.cancel_read()         # wake the reader's select at once
            self.port.close()
        except Exception:
            pass
