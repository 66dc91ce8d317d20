"""Bytes received by a background thread, read by the user's thread with a timeout
(the ``read``/``in_waiting`` half of a serial-like object)."""

from __future__ import annotations

import threading
import time


class ReceiveBuffer:
    """A byte queue: ``put`` by one thread, ``read`` with a timeout by another."""

    def __init__(self) -> None:
        self._data = threading.Condition()
        self._buf = bytearray()
        self._closed = False

    def put(self, data: bytes) -> None:
        """Appends ``data`` and wakes the readers."""
        with self._data:
            self._buf += data
            self._data.notify_all()

    def read(self, size: int = 1, timeout: float | None = None) -> bytes:
        """Up to ``size`` bytes; waits up to ``timeout`` s for the first (None: until
        data or ``close()``)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._data:
            while not self._buf and not self._closed:
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    break
                self._data.wait(left)
            out = bytes(self._buf[:size])
            del self._buf[:size]
            return out

    def __len__(self) -> int:
        with self._data:
            return len(self._buf)

    def clear(self) -> None:
        """Drops every byte not yet read."""
        with self._data:
            self._buf.clear()

    def close(self) -> None:
        """Wakes every reader; reads return what is left, then b""."""
        with self._data:
            self._closed = True
            self._data.notify_all()
