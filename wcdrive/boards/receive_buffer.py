"""Bytes received by a background thread, read by the user's thread with a timeout
(the ``read``/``in_waiting`` half of a serial-like object).

The buffer is bounded, as an operating system's serial driver is: a Linux tty holds
4096 bytes that no program has read (``N_TTY_BUF_SIZE``), and bytes that arrive while
it is full are lost, counted by the driver (the ``buf_overrun`` of ``TIOCGICOUNT``).
``ReceiveBuffer`` keeps what it holds, drops the newest bytes that do not fit and
counts them (``dropped``), so a board whose output nobody reads stays within
``capacity`` however long it runs."""

from __future__ import annotations

import threading
import time

#: Bytes a receive buffer holds unless told otherwise: a Linux tty's.
DEFAULT_CAPACITY = 4096


class ReceiveBuffer:
    """A bounded byte queue: ``put`` by one thread, ``read`` with a timeout by another;
    what does not fit is dropped and counted."""

    def __init__(self, capacity: int = DEFAULT_CAPACITY) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1 byte, got {capacity}")
        #: The most bytes held unread.
        self.capacity = capacity
        self._data = threading.Condition()
        self._buf = bytearray()
        self._closed = False
        self._dropped = 0

    def put(self, data: bytes) -> None:
        """Appends what of ``data`` fits, counts the rest as dropped, and wakes the
        readers."""
        with self._data:
            room = self.capacity - len(self._buf)
            if len(data) > room:
                self._dropped += len(data) - room
                data = data[:room]
            if data:
                self._buf += data
                self._data.notify_all()

    @property
    def dropped(self) -> int:
        """Bytes dropped so far because the buffer was full (``clear`` keeps the count,
        as a driver's counter outlives a flush)."""
        with self._data:
            return self._dropped

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
        """Drops every byte not yet read (not counted in ``dropped``)."""
        with self._data:
            self._buf.clear()

    def close(self) -> None:
        """Wakes every reader; reads return what is left, then b""."""
        with self._data:
            self._closed = True
            self._data.notify_all()
