"""The virtual Mega as a pseudo-terminal that any program opens like /dev/ttyACM0.

    python -m hil.pty_board [--realtime] [--no-plant] [--elf PATH] [--link /tmp/ttyWC0]

prints the device path, then runs until interrupted. pyserial, miniterm or a ROS 2
node opens that path; bytes written to it reach the firmware's UART RX at wire speed
and its TX bytes come back. ``--realtime`` paces simulated time to the wall clock;
without it the board runs as fast as it can. The pymunk chair is wired to the pins
(PWM + DIR in, encoder edges out) unless ``--no-plant``: the firmware drives it.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from hil.virtual_mega import F_CPU, VirtualMega
from wcdrive.firmware.quadrature import edges_from_trajectory
from wcdrive.plant import ChairParams, Gyro, Plant
from wcdrive.sim.port_loop import advance
from wcdrive.transports.pty_bridge import PtyBridge, serve
from wcdrive.transports.threaded import ThreadedBoard

#: Simulated time per step of the board's thread.
STEP_S = 0.002
#: Physics step of the plant behind the pins.
PLANT_DT = 0.001


class MegaBoard(ThreadedBoard):
    """A ``VirtualMega`` run by a background thread, with the serial-like interface
    (``write``, ``read``, ``close``) that ``PtyBridge`` expects."""

    def __init__(self, elf: str | Path | None = None, *, realtime: bool = False,
                 plant: ChairParams | bool = True) -> None:
        super().__init__("virtual-mega")
        self.mega = VirtualMega(elf)
        self.realtime = realtime
        self._wall0: float | None = None
        self.plant: Plant | None = None
        if plant:
            params = plant if isinstance(plant, ChairParams) else ChairParams()
            self.plant = Plant(params)
            self._gyro = Gyro(params, 0)
            self._scale = params.counts_per_rev / (2.0 * math.pi)
            self._position = {"left": 0.5, "right": 0.5}    # counts; floor() is the count

    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, heading) of the chair behind the pins."""
        if self.plant is None:
            raise RuntimeError("this board has no plant (plant=False)")
        with self._lock:
            return self.plant.pose

    def _send(self, data: bytes) -> None:
        self.mega.send(data)

    def _advance(self) -> bytes:
        if self._wall0 is None:
            self._wall0 = time.monotonic()
        if self.plant is None:
            self.mega.run_for(STEP_S)
        else:
            for _ in range(round(STEP_S / PLANT_DT)):
                self._plant_step()
        return bytes(b for _, b in self.mega.take_tx())

    def _plant_step(self) -> None:
        """One physics step: the wheels' motion over it becomes encoder edges queued on
        the pins, the firmware runs through it, and its PWM/DIR drive the next step."""
        mega, plant = self.mega, self.plant
        t0 = mega.time
        angles = advance(plant, self._gyro, 1, PLANT_DT)
        new = {"left": -angles[0, 0] * self._scale + 0.5, "right": angles[0, 1] * self._scale + 0.5}
        for side in ("left", "right"):
            train = edges_from_trajectory(np.array([0.0, PLANT_DT]),
                                          np.array([self._position[side], new[side]]))
            mega.encoder_edges(side, train, t0)
            self._position[side] = new[side]
        mega.run_until(round((t0 + PLANT_DT) * F_CPU))
        plant.set_drive(mega.pwm("left"), mega.direction("left"), mega.pwm("right"),
                        mega.direction("right"))

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
                 link: str | Path | None = None, plant: ChairParams | bool = True) -> None:
        self.mega_board = MegaBoard(elf, realtime=realtime, plant=plant)
        super().__init__(self.mega_board, link=link)

    @property
    def mega(self) -> VirtualMega:
        return self.mega_board.mega

    def start(self, run_board: bool = True) -> PtyBoard:
        """Starts the pty; the board too unless ``run_board=False`` (then ``run_board()``
        once the client has opened the path, so it sees the boot line, as on a Mega
        that resets when its port opens)."""
        super().start()
        if run_board:
            self.run_board()
        return self

    def run_board(self) -> None:
        self.mega_board.start()

    def stop(self) -> None:
        self.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--elf", help="firmware ELF (default: build firmware/final_control)")
    parser.add_argument("--realtime", action="store_true", help="pace simulated time to the wall clock")
    parser.add_argument("--link", help="also make this symlink to the pty, e.g. /tmp/ttyWC0")
    parser.add_argument("--no-plant", action="store_true", help="leave the encoder pins still")
    args = parser.parse_args(argv)
    board = PtyBoard(args.elf, realtime=args.realtime, link=args.link,
                     plant=not args.no_plant).start()
    serve(board)
    print(f"stopped at {board.mega.cycle / F_CPU:.3f} s simulated", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
