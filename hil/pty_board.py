"""The virtual Mega as a pseudo-terminal that any program opens like /dev/ttyACM0.

    python -m hil.pty_board [--realtime] [--elf PATH] [--link /tmp/ttyWC0]

prints the device path, then runs until interrupted. pyserial, miniterm or a ROS 2
node opens that path; bytes written to it reach the firmware's UART RX at wire speed
and its TX bytes come back. ``--realtime`` paces simulated time to the wall clock;
without it the board runs as fast as it can.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hil.virtual_mega import F_CPU, VirtualMega
from wcdrive.transports.pty_bridge import PtyBridge, serve
from wcdrive.transports.threaded import ThreadedBoard

#: Simulated time per step of the board's thread.
STEP_S = 0.002


class MegaBoard(ThreadedBoard):
    """A ``VirtualMega`` run by a background thread, with the serial-like interface
    (``write``, ``read``, ``close``) that ``PtyBridge`` expects."""

    def __init__(self, elf: str | Path | None = None, *, realtime: bool = False) -> None:
        super().__init__("virtual-mega")
        self.mega = VirtualMega(elf)
        self.realtime = realtime
        self._wall0: float | None = None

    def _send(self, data: bytes) -> None:
        self.mega.send(data)

    def _advance(self) -> bytes:
        if self._wall0 is None:
            self._wall0 = time.monotonic()
        self.mega.run_for(STEP_S)
        return bytes(b for _, b in self.mega.take_tx())

    def _pause(self) -> float:
        """Real time: wait until the wall clock catches up; else run flat out."""
        if not self.realtime or self._wall0 is None:
            return 0.0
        return self.mega.time - (time.monotonic() - self._wall0)

    def _shutdown(self) -> None:
        self.mega.close()


class PtyBoard(PtyBridge):
    """The virtual Mega behind a pty: ``path`` is what a client opens."""

    def __init__(self, elf: str | Path | None = None, *, realtime: bool = False,
                 link: str | Path | None = None) -> None:
        self.mega_board = MegaBoard(elf, realtime=realtime)
        super().__init__(self.mega_board, link=link)

    @property
    def mega(self) -> VirtualMega:
        return self.mega_board.mega

    def start(self) -> PtyBoard:
        self.mega_board.start()
        super().start()
        return self

    def stop(self) -> None:
        self.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--elf", help="firmware ELF (default: build firmware/final_control)")
    parser.add_argument("--realtime", action="store_true", help="pace simulated time to the wall clock")
    parser.add_argument("--link", help="also make this symlink to the pty, e.g. /tmp/ttyWC0")
    args = parser.parse_args(argv)
    board = PtyBoard(args.elf, realtime=args.realtime, link=args.link).start()
    serve(board)
    print(f"stopped at {board.mega.cycle / F_CPU:.3f} s simulated", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
