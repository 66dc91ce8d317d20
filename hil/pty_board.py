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
import threading
import time
from pathlib import Path

from hil.virtual_mega import F_CPU, VirtualMega
from wcdrive.transports.pty_bridge import PtyBridge

#: Simulated time per step of the board's thread.
STEP_S = 0.002


class MegaBoard:
    """A ``VirtualMega`` run by a background thread, with the serial-like interface
    (``write``, ``read``, ``close``) that ``PtyBridge`` expects."""

    def __init__(self, elf: str | Path | None = None, *, realtime: bool = False) -> None:
        self.mega = VirtualMega(elf)
        self.realtime = realtime
        self._lock = threading.Lock()
        self._data = threading.Condition(self._lock)
        self._rx = bytearray()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="virtual-mega", daemon=True)

    def start(self) -> MegaBoard:
        self._thread.start()
        return self

    def write(self, data: bytes) -> int:
        with self._lock:
            self.mega.send(bytes(data))
        return len(data)

    def read(self, size: int = 1, timeout: float | None = None) -> bytes:
        with self._data:
            if not self._rx and not self._stop.is_set():
                self._data.wait(timeout)
            out = bytes(self._rx[:size])
            del self._rx[:size]
            return out

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        self.mega.close()

    def _run(self) -> None:
        wall0 = time.monotonic()
        while not self._stop.is_set():
            with self._lock:
                self.mega.run_for(STEP_S)
                out = bytes(b for _, b in self.mega.take_tx())
                if out:
                    self._rx += out
                    self._data.notify_all()
                sim = self.mega.time
            if self.realtime:
                ahead = sim - (time.monotonic() - wall0)
                if ahead > 0:
                    time.sleep(ahead)
            else:
                time.sleep(0)   # as fast as it can; let clients have the CPU


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
    print(board.path, flush=True)
    try:
        while True:
            time.sleep(1)
    except KeyboardInterrupt:
        pass
    finally:
        simulated = board.mega.cycle / F_CPU
        board.stop()
    print(f"stopped at {simulated:.3f} s simulated", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
