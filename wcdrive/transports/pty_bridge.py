"""Puts a serial-like board (``SimulatedBoard``) behind a pseudo-terminal, so that
outside programs (a ROS 2 node, miniterm, screen) open the simulated chair by path:

    wcdrive pty [--speed 1.0] [--link /tmp/ttyWC0]

prints the device path and runs until interrupted.
"""

from __future__ import annotations

import os
import select
import termios
import threading
import time
import tty
from pathlib import Path
from typing import Protocol


class SerialLike(Protocol):
    def write(self, data: bytes) -> int: ...
    def read(self, size: int = 1, timeout: float | None = None) -> bytes: ...
    def close(self) -> None: ...


class PtyBridge:
    def __init__(self, board: SerialLike, link: str | Path | None = None) -> None:
        self.board = board
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] &= ~termios.ECHO
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        self.device = os.ttyname(self._slave)
        self.link = Path(link) if link else None
        if self.link:
            if self.link.is_symlink() or self.link.exists():
                self.link.unlink()
            self.link.symlink_to(self.device)
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._to_board, daemon=True),
                         threading.Thread(target=self._from_board, daemon=True)]

    @property
    def path(self) -> str:
        return str(self.link) if self.link else self.device

    def start(self) -> PtyBridge:
        for t in self._threads:
            t.start()
        return self

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        if self.link and self.link.is_symlink():
            self.link.unlink()
        self.board.close()

    def __enter__(self) -> PtyBridge:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _to_board(self) -> None:
        while not self._stop.is_set():
            readable, _, _ = select.select([self._master], [], [], 0.05)
            if readable:
                try:
                    data = os.read(self._master, 4096)
                except OSError:
                    continue
                if data:
                    self.board.write(data)

    def _from_board(self) -> None:
        while not self._stop.is_set():
            data = self.board.read(4096, timeout=0.05)
            if data:
                try:
                    os.write(self._master, data)
                except OSError:
                    pass


def serve(bridge: PtyBridge) -> None:
    """Prints the device path, then serves until Ctrl-C; closes the bridge."""
    print(bridge.path, flush=True)
    try:
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        pass
    finally:
        bridge.close()
