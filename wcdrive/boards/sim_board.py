"""The simulated chair as a live serial device: the bit-exact port driving the pymunk
plant (``PortLoop``), advanced in a background thread.

    board = SimulatedBoard(speed=1.0).start()   # paced to the wall clock
    board.write(b"x:0.500,t:0.100,")
    time.sleep(0.5)
    print(board.read(4096))                     # the firmware's feedback lines
    board.close()

``speed`` scales simulated time against the wall clock (10 runs ten times faster).
The same object sits behind ``serial.serial_for_url("wcsim://")`` and the pty bridge.
"""

from __future__ import annotations

import math

from wcdrive.avr.uart import UART_BYTE_CYCLES
from wcdrive.boards.board_lidar import BoardLidar
from wcdrive.boards.inhibits import input_number
from wcdrive.boards.port_loop import F_CPU, PortLoop
from wcdrive.boards.receive_buffer import DEFAULT_CAPACITY
from wcdrive.boards.threaded import ThreadedBoard, WallClock
from wcdrive.plant import ChairParams, Gyro, Plant
from wcdrive.plant.lidar import Lidar
from wcdrive.plant.world import World

#: Simulated time between two looks at the wall clock.
STEP_S = 0.002


#: The most simulated time one step of the board's thread runs (at speeds up to 250).
MAX_SLICE_S = 1.0
#: Gyro samples a live simulated board keeps (10 s at the BMI085's 400 Hz).
GYRO_HISTORY = 4000


def rx_capacity(speed: float) -> int:
    """The output buffer of a board at ``speed``: a Linux tty's 4096 bytes, plus the
    most one step of the board's thread can hand over at once (the UART's 10,695
    bytes/s over the longest slice). A real board's bytes come one byte time apart
    and a reader drains them as they come; the simulated board's come a step at a
    time, and a whole step must fit, or a reader that keeps up would lose bytes."""
    slice_s = max(MAX_SLICE_S, 4 * STEP_S * speed)
    return DEFAULT_CAPACITY + math.ceil(slice_s * F_CPU / UART_BYTE_CYCLES)


class SimulatedBoard(ThreadedBoard):
    """The port and the plant (``PortLoop``) as a live board, paced to the wall clock
    times ``speed``; what ``wcsim://`` opens. ``world``: the walls it drives among
    (collisions included), ``start`` its pose there (x, y m, heading rad); ``lidar``: a
    lidar on the chair (``BoardLidar``, its noise from ``seed``)."""

    def __init__(self, params: ChairParams | None = None, *, speed: float = 1.0, seed: int = 0,
                 world: World | None = None, start: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 lidar: Lidar | None = None) -> None:
        self.clock = WallClock(speed)
        super().__init__("wcsim", rx_capacity(speed))
        self.params = params or ChairParams()
        self.plant = Plant(self.params, x=start[0], y=start[1], heading=start[2], world=world)
        if lidar is not None:
            self.lidar = BoardLidar(lidar, world or World(), self.plant, seed)
        # a live board runs for hours: its gyro keeps the newest 10 s of samples
        self.loop = PortLoop(self.plant, Gyro(self.params, seed, history=GYRO_HISTORY))

    @property
    def speed(self) -> float:
        """Simulated seconds per wall-clock second (the pacing clock's)."""
        return self.clock.speed

    @property
    def time(self) -> float:
        """Simulated seconds since the board booted."""
        return self.loop.cycle / F_CPU

    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, heading) of the simulated chair."""
        with self._lock:
            return self.plant.pose

    def set_inhibit(self, name: str | int, active: bool = True) -> None:
        """Pulls inhibit input ``name`` ("charger" or "seat", or 1, 2: ``wcdrive.boards.inhibits``)
        low (``active``) or lets it go, from now on: what a charger plugged in or a seat
        switch does to the board's pin. "push" (4) pulls the parking brake's
        manual-release lever on the plant, whose switch the board reads (push mode)."""
        with self._lock:
            self.loop.set_inhibit(input_number(name), active)

    def set_brake_coil(self, fault: str | None) -> None:
        """The parking brake's coil from now on: None (whole), ``"open"`` or ``"short"``
        (``Plant.set_brake_coil``): the brake stays engaged and its driver's status pin
        flags it, as a real coil failing does."""
        with self._lock:
            self.plant.set_brake_coil(fault)

    def _dtr_reset(self) -> None:
        self.loop.reset()

    def _simulated_plant(self) -> Plant:
        return self.plant

    def _simulated_gyro(self) -> Gyro | None:
        return self.loop.gyro

    def _clock(self) -> float:
        return self.time

    def _send(self, data: bytes) -> None:
        self.loop.send(data)

    def _advance(self) -> bytes:
        target = self.clock.target(self.time)
        if target is None:
            return b""
        # A board that fell behind (a loaded machine) catches up a slice at a time, so
        # its output reaches the reader in bounded chunks, not one that grows with the lag.
        target = min(target, self.time + max(MAX_SLICE_S, 4 * STEP_S * self.speed))
        self.loop.run_until(round(target * F_CPU))
        return b"".join(data for _, data in self.loop.take_output())

    def _pause(self) -> float:
        return STEP_S / self.speed if self.speed < 1 else STEP_S
