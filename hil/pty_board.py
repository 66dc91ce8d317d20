"""The virtual Mega as a pseudo-terminal that any program opens like /dev/ttyACM0.

    python -m hil.pty_board [--realtime] [--elf PATH] [--link /tmp/ttyWC0]

prints the device path, then runs until interrupted. pyserial, miniterm or a ROS 2
node opens that path; bytes written to it reach the firmware's UART RX at wire speed
and its TX bytes come back. ``--realtime`` paces simulated time to the wall clock;
without it the board runs as fast as it can while the line is busy and idles (in
simulated time too) when nothing happens, so a host sees the firmware's own timing.
"""

from __future__ import annotations

import argparse
import os
import select
import sys
import termios
import threading
import time
import tty
from pathlib import Path

from hil.virtual_mega import F_CPU, VirtualMega

#: Simulated time per step of the bridge loop.
STEP_S = 0.002


class PtyBoard:
    """Runs a ``VirtualMega`` behind a pty in a background thread."""

    def __init__(self, elf: str | Path | None = None, *, realtime: bool = False,
                 link: str | Path | None = None) -> None:
        self.mega = VirtualMega(elf)
        self.realtime = realtime
        self._master, slave = os.openpty()
        tty.setraw(slave)
        attrs = termios.tcgetattr(slave)
        attrs[3] &= ~termios.ECHO
        termios.tcsetattr(slave, termios.TCSANOW, attrs)
        self.device = os.ttyname(slave)
        self._slave = slave   # kept open so the pty survives clients closing it
        self.link = Path(link) if link else None
        if self.link:
            if self.link.is_symlink() or self.link.exists():
                self.link.unlink()
            self.link.symlink_to(self.device)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pty-board", daemon=True)

    @property
    def path(self) -> str:
        return str(self.link) if self.link else self.device

    def start(self) -> PtyBoard:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        if self.link and self.link.is_symlink():
            self.link.unlink()
        self.mega.close()

    def __enter__(self) -> PtyBoard:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        wall0 = time.monotonic()
        sim0 = self.mega.time
        while not self._stop.is_set():
            readable, _, _ = select.select([self._master], [], [], 0)
            if readable:
                try:
                    data = os.read(self._master, 4096)
                except OSError:
                    data = b""
                if data:
                    self.mega.send(data)
            self.mega.run_for(STEP_S)
            out = bytes(b for _, b in self.mega.take_tx())
            if out:
                try:
                    os.write(self._master, out)
                except OSError:
                    pass
            if self.realtime:
                ahead = (self.mega.time - sim0) - (time.monotonic() - wall0)
                if ahead > 0:
                    time.sleep(ahead)
            else:
                # As fast as it can; yield briefly so clients get the CPU.
                time.sleep(0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--elf", help="firmware ELF (default: build firmware/final_control)")
    parser.add_argument("--realtime", action="store_true", help="pace simulated time to the wall clock")
    parser.add_argument("--link", help="also make this symlink to the pty, e.g. /tmp/ttyWC0")
    args = parser.parse_args(argv)
    board = PtyBoard(args.elf, realtime=args.realtime, link=args.link).start()
    print(board.path, flush=True)
    try:
        while True:
            time.sleep(1)
            if not board._thread.is_alive():
                return 1
    except KeyboardInterrupt:
        pass
    finally:
        board.stop()
    print(f"stopped at {board.mega.cycle / F_CPU:.3f} s simulated", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
