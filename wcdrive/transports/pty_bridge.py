"""Puts a serial-like board (``SimulatedBoard``) behind a pseudo-terminal, so that
outside programs (a ROS 2 node, miniterm, screen) open the simulated chair by path:

    wcdrive pty [--speed 1.0] [--link /tmp/ttyWC0]

prints the device path and runs until interrupted.

With ``on_open`` (the DTR model) the bridge does not hold the pty's slave open
itself, and calls ``on_open`` each time the first program opens the device (a real
Mega's USB-serial bridge pulls RESET when DTR rises on open). It counts opens and
closes with inotify on the slave, so that a close and an immediate reopen are two
events; where inotify is missing it polls the master, whose POLLHUP ends when a
program opens the device (an open right after a close may then be missed). While
no program has the device open, what the board sends is dropped, as a closed port
drops it.
"""

from __future__ import annotations

import ctypes
import os
import select
import struct
import termios
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

_IN_OPEN, _IN_CLOSE = 0x20, 0x08 | 0x10      # <sys/inotify.h>: IN_OPEN, IN_CLOSE_WRITE | _NOWRITE


def _inotify(path: str) -> int | None:
    """A non-blocking inotify descriptor watching opens and closes of ``path``, or
    None where there is no inotify."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fd = int(libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC))
    except (OSError, AttributeError):
        return None
    if fd < 0:
        return None
    if libc.inotify_add_watch(fd, path.encode(), _IN_OPEN | _IN_CLOSE) < 0:
        os.close(fd)
        return None
    return fd


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

    def __init__(self, board: SerialLike, link: str | Path | None = None,
                 on_open: Callable[[], object] | None = None, reset_delay: float = 0.02) -> None:
        """``on_open``: called each time a program opens the device: a ``ThreadedBoard``'s
        ``dtr`` (resets the board and drops what it sent while the port was closed),
        ``reset_delay`` s after the open: a real board's USB-serial bridge learns of DTR
        after the host's open has returned, and pyserial's open ends by flushing the
        input, which would otherwise take the start of a board's BOOT line."""
        self.reset_delay = reset_delay
        self.board = board
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] &= ~termios.ECHO
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        self.on_open = on_open
        #: Opens of the device seen (with ``on_open``).
        self.opens = 0
        self._peer_open = on_open is None
        self._holders = 0                    # programs that have the device open (with on_open)
        self._watch: int | None = None
        if on_open is not None:
            os.close(self._slave)
            self._slave = -1
            self._watch = _inotify(self.device)      # from now on, no open is missed
        self.link = Path(link) if link else None
        if self.link:
            if self.link.is_symlink() or self.link.exists():
                self.link.unlink()
            self.link.symlink_to(self.device)
        self._stop = threading.Event()
        self._open_seen = threading.Event()
        self._threads = [threading.Thread(target=self._to_board, daemon=True),
                         threading.Thread(target=self._from_board, daemon=True)]
        if on_open is not None:
            self._threads.append(threading.Thread(target=self._watch_opens, daemon=True))

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
            if fd < 0:
                continue
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

    def _opened(self) -> None:
        self.opens += 1
        self._open_seen.set()                # _from_board resets the board: it alone reads it

    def _watch_opens(self) -> None:
        """With ``on_open``: counts the opens and closes of the device (inotify's
        IN_OPEN and IN_CLOSE on the pty's slave, so that a close and an immediate
        reopen are two events) and calls ``on_open`` when the first program opens it.
        Without inotify: the master's POLLHUP, which ends when a program opens it."""
        watch = self._watch
        if watch is None:
            self._watch_hangup()
            return
        try:
            while not self._stop.is_set():
                readable, _, _ = select.select([watch], [], [], 0.05)
                if not readable:
                    continue
                data = os.read(watch, 4096)
                for offset in range(0, len(data) - 15, 16):    # a file's events carry no name
                    mask = struct.unpack_from("iIII", data, offset)[1]
                    if mask & _IN_OPEN:
                        self._holders += 1
                        if self._holders == 1:
                            self._opened()
                    if mask & _IN_CLOSE:
                        self._holders = max(0, self._holders - 1)
                        if self._holders == 0:
                            self._peer_open = False
        finally:
            os.close(watch)

    def _watch_hangup(self) -> None:
        poller = select.poll()
        poller.register(self._master, select.POLLHUP)
        while not self._stop.is_set():
            hung_up = any(ev & select.POLLHUP for _, ev in poller.poll(100 if self._holders else 0))
            if hung_up:
                self._holders = 0
                self._peer_open = False
                time.sleep(0.01)
            elif not self._holders:
                self._holders = 1
                self._opened()

    def _to_board(self) -> None:
        while not self._stop.is_set():
            if not self._peer_open:
                time.sleep(0.01)
                continue
            readable, _, _ = select.select([self._master], [], [], 0.05)
            if readable:
                try:
                    data = os.read(self._master, 4096)
                except OSError:              # EIO: the device was closed (the watcher sees it)
                    time.sleep(0.002)
                    continue
                if data:
                    self.board.write(data)

    def _from_board(self) -> None:
        # The master is non-blocking: when nobody reads the device its buffer fills, and
        # a blocking write would hang here (and ``close``) for good. The board's bytes
        # wait in ``pending`` (and the board's buffer) until there is room.
        # With ``on_open`` this thread also resets the board when the device is opened:
        # it is the only reader of the board, so what it reads after ``on_open`` (a
        # ``dtr`` clears the board's output under its lock) is all from after the reset.
        pending = b""
        while not self._stop.is_set():
            if self._open_seen.is_set():
                self._open_seen.clear()
                pending = b""                    # sent while nobody had the port open: lost
                time.sleep(self.reset_delay)
                assert self.on_open is not None
                self.on_open()
                self._peer_open = self._holders > 0
                continue
            if not pending:
                pending = self.board.read(4096, timeout=0.05)
                continue
            if not self._peer_open:
                pending = b""                    # sent while nobody had the port open: lost
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
