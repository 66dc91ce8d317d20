"""An in-memory ``Port`` for the wrapper tests: the test hands it the board's bytes
(``feed``) and reads what the host wrote (``written``); ``read`` waits for nothing
(``timeout`` is kept, not honoured), so each test runs in microseconds."""

from __future__ import annotations

import serial


class FakePort:
    """A ``Port`` whose board is the test."""

    def __init__(self, timeout: float | None = 0.0) -> None:
        self.timeout = timeout
        self.incoming = bytearray()
        self.written: list[bytes] = []
        self.is_open = True
        self.flushed = 0
        self.reads: list[int] = []

    def feed(self, data: bytes) -> None:
        self.incoming += data

    def _open(self) -> None:
        if not self.is_open:
            raise serial.PortNotOpenError()

    @property
    def in_waiting(self) -> int:
        self._open()
        return len(self.incoming)

    def read(self, size: int = 1) -> bytes:
        self._open()
        self.reads.append(size)
        out = bytes(self.incoming[:size])
        del self.incoming[:size]
        return out

    def write(self, data: bytes) -> int:
        self._open()
        self.written.append(bytes(data))
        return len(data)

    def flush(self) -> None:
        self._open()
        self.flushed += 1

    def close(self) -> None:
        self.is_open = False
