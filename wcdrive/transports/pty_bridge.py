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
    """What the bridge serves: a ``ThreadedBoard`` (``SimulatedBoard``, ``MegaBoard``)."""

    def write(self, data: bytes) -> int:
        """Takes bytes written to the device."""

    def read(self, size: int = 1, timeout: float | None = None) -> bytes:
        """Up to ``size`` bytes for the device; waits up to ``timeout`` s."""

    def close(self) -> None:
        """Stops the board."""


class PtyBridge:
    """A pseudo-terminal whose other end is ``board``; the bridge owns the board."""

    def __init__(self, board: SerialLike, link: str | Path | None = None) -> None:
        self.board = board
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] &= ~termios.ECHO
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        os.set_blocking(self._master, False)
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
        """What to open: the ``link`` if one was given, else the pty's device."""
        return str(self.link) if self.link else self.device

    def start(self) -> PtyBridge:
        """Starts copying in both directions; returns the bridge."""
        for t in self._threads:
            t.start()
        return self

    def close(self) -> None:
        """Stops copying, closes the pty (and the link) and then the board."""
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
        # The master is non-blocking: when nobody reads the device its buffer fills, and
        # a blocking write would hang here (and ``close``) for good. The board's bytes
        # wait in ``pending`` (and the board's buffer) until there is room.
        pending = b""
        while not self._stop.is_set():
            if not pending:
                pending = self.board.read(4096, timeout=0.05)
                continue
            _, writable, _ = select.select([], [self._master], [], 0.05)
            if not writable:
                continue
            try:
                pending = pending[os.write(self._master, pending):]
            except BlockingIOError:
                continue
            except OSError:
                pending = b""


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
