"""A board or link as a pyserial port: the part every ``wc*://`` handler shares.

Subclasses open their board (a ``ThreadedBoard``, or the CAN link) from the URL in
``_open_board``; the URL's query is parsed there and nowhere else. Baud rate and
framing settings are accepted and ignored, as on a USB CDC port.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, to_bytes


class BoardLike(Protocol):
    """What a handler opens: a ``ThreadedBoard`` or a ``CanLink``."""

    def start(self) -> Any: ...
    def close(self) -> None: ...
    @property
    def closed(self) -> bool: ...
    @property
    def in_waiting(self) -> int: ...
    def read(self, size: int = 1, timeout: float | None = None) -> bytes: ...
    def write(self, data: bytes) -> int: ...
    def reset_input(self) -> None: ...


class BoardSerial(SerialBase):
    """pyserial's ``SerialBase`` over a ``BoardLike``; ``read`` honours ``timeout``."""

    BAUDRATES = (9600, 19200, 38400, 57600, 115200, 230400)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.board: BoardLike | None = None
        self.is_open: bool = False
        super().__init__(*args, **kwargs)

    def _open_board(self, url: str) -> BoardLike:
        raise NotImplementedError

    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        self.board = self._open_board(self.portstr).start()
        self.is_open = True

    def close(self) -> None:
        if self.board is not None:
            self.board.close()
            self.board = None
        self.is_open = False

    def _reconfigure_port(self) -> None:
        pass

    @property
    def in_waiting(self) -> int:
        if not self.is_open or self.board is None:
            raise PortNotOpenError()
        return self.board.in_waiting

    def read(self, size: int = 1) -> bytes:
        if not self.is_open or self.board is None:
            raise PortNotOpenError()
        data = bytearray()
        deadline = None if self._timeout is None else time.monotonic() + self._timeout
        while len(data) < size:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            chunk = self.board.read(size - len(data), timeout=left)
            data += chunk
            if not chunk and (deadline is None or time.monotonic() >= deadline):
                if deadline is not None or self.board.closed:
                    break
        return bytes(data)

    def write(self, data: Any) -> int:
        if not self.is_open or self.board is None:
            raise PortNotOpenError()
        return self.board.write(to_bytes(data))

    def reset_input_buffer(self) -> None:
        if not self.is_open or self.board is None:
            raise PortNotOpenError()
        self.board.reset_input()

    def reset_output_buffer(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass
