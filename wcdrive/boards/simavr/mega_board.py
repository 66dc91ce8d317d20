"""The simulated Mega as a live board: the compiled firmware in simavr, run by a
background thread, with the pymunk chair wired to its pins.

``MegaBoard`` has the serial-like interface of every threaded board (``write``,
``read``, ``close``): ``wcavr://`` opens it as a pyserial port, and
``wcdrive.transports.pty_bridge.PtyBridge`` puts it behind a pseudo-terminal that any
program opens like /dev/ttyACM0 (``wcdrive pty --avr``). ``realtime=True`` paces simulated time
to the wall clock (``speed`` simulated seconds per second); otherwise the board runs as
fast as it can. ``reset()`` pulses the Mega's RESET line, as DTR does when a host opens
a real Mega's port.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from wcdrive.boards.board_lidar import BoardLidar
from wcdrive.boards.sim_board import GYRO_HISTORY
from wcdrive.boards.simavr.plant_on_pins import PlantOnPins
from wcdrive.boards.simavr.virtual_mega import Reset, VirtualMega
from wcdrive.boards.threaded import ThreadedBoard
from wcdrive.plant import ChairParams, Gyro, Plant
from wcdrive.plant.lidar import Lidar
from wcdrive.plant.world import World

__all__ = ["MegaBoard"]

_T = TypeVar("_T")

#: Simulated time per step of the board's thread.
STEP_S = 0.002
#: Physics step of the plant behind the pins.
PLANT_DT = 0.001


class MegaBoard(ThreadedBoard):
    """A ``VirtualMega`` run by a background thread, with the serial-like interface
    (``write``, ``read``, ``close``) that ``PtyBridge`` expects."""

    def __init__(self, elf: str | Path | None = None, *, realtime: bool = False,
                 plant: ChairParams | bool = True, speed: float = 1.0,
                 mega: VirtualMega | None = None, world: World | None = None,
                 start: tuple[float, float, float] = (0.0, 0.0, 0.0), lidar: Lidar | None = None) -> None:
        """``mega``: a Mega made elsewhere (``BootloaderMega``) in place of ``VirtualMega(elf)``.
        ``world``, ``start`` and ``lidar`` as ``SimulatedBoard``'s (with a plant)."""
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        super().__init__("virtual-mega")
        self.mega = mega if mega is not None else VirtualMega(elf)
        # A live board keeps no record of its hooked entries nor of the bytes it was sent
        # (the lock-step harness keeps both, for its comparison): kept, with the gyro's
        # samples, they grew 94 MB in the soak's simulated half hour.
        self.mega.keep_records = False
        self.realtime = realtime
        #: With ``realtime``: simulated seconds per wall-clock second.
        self.speed = speed
        self._wall0: float | None = None
        self.plant: Plant | None = None
        self._pins: PlantOnPins | None = None
        if plant:
            params = plant if isinstance(plant, ChairParams) else ChairParams()
            self.plant = Plant(params, x=start[0], y=start[1], heading=start[2], world=world)
            # a live board runs for hours: its gyro keeps the newest samples only
            self._pins = PlantOnPins(self.mega, self.plant, Gyro(params, 0, history=GYRO_HISTORY))
            if lidar is not None:
                self.lidar = BoardLidar(lidar, world or World(), self.plant)
        elif world is not None or lidar is not None:
            raise ValueError("a board without a plant has no world and no lidar")
        #: Called by the board's thread after each step (``STEP_S`` of simulated time),
        #: under the board's lock, with the UART bytes the firmware sent in that step as
        #: ``(cycle, byte)``: a probe for measurements (PWM, the plant) at the step's end.
        self.on_step: Callable[[list[tuple[int, int]]], None] | None = None

    @property
    def time(self) -> float:
        """Simulated seconds since the board started (running on across its resets)."""
        return self.mega.time

    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, heading) of the chair behind the pins."""
        if self.plant is None:
            raise RuntimeError("this board has no plant (plant=False)")
        with self._lock:
            return self.plant.pose

    def between_steps(self, fn: Callable[[VirtualMega], _T]) -> _T:
        """Calls ``fn(mega)`` between two steps of the board's thread (under its lock),
        so that it sees, and may change, the Mega at one simulated instant; returns
        what ``fn`` returns."""
        with self._lock:
            return fn(self.mega)

    def reset(self, cause: str = "external") -> Reset:
        """Resets the Mega now, between two steps of its thread: ``"external"`` is a DTR
        pulse (or the reset button), also ``"brownout"`` and ``"power_on"``
        (``VirtualMega.reset``). The chair behind the pins rolls on; what the board sent
        before the reset stays readable."""
        with self._lock:
            return self.mega.reset(cause)

    def _dtr_reset(self) -> None:
        self.mega.reset("external")

    def _simulated_plant(self) -> Plant | None:
        return self.plant

    def _simulated_gyro(self) -> Gyro | None:
        return self._pins.gyro if self._pins is not None else None

    def _clock(self) -> float:
        return self.mega.time

    def _send(self, data: bytes) -> None:
        self.mega.send(data)

    def _advance(self) -> bytes:
        if self._wall0 is None:
            self._wall0 = time.monotonic()
        if self._pins is None:
            self.mega.run_for(STEP_S)
        else:
            for _ in range(round(STEP_S / PLANT_DT)):
                t0 = self.mega.time
                self._pins.step(t0, t0 + PLANT_DT)
        tx = self.mega.take_tx()
        if self.on_step is not None:
            self.on_step(tx)
        return bytes(b for _, b in tx)

    def _pause(self) -> float:
        """Real time (times ``speed``): wait until the wall clock catches up; else run
        flat out."""
        if not self.realtime or self._wall0 is None:
            return 0.0
        return self.mega.time / self.speed - (time.monotonic() - self._wall0)

    def _shutdown(self) -> None:
        self.mega.close()

