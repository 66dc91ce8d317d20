"""A simulated board advanced by a background thread, with serial-like I/O.

Subclasses say how to take bytes (``_send``), how to advance the simulation one
step and what it sent meanwhile (``_advance``), how long to wait between steps
(``_pause``) and how to release what they hold (``_shutdown``). ``SimulatedBoard``
(the port + plant) and ``wcdrive.boards.simavr.mega_board.MegaBoard`` (the ELF in simavr) are two.
A board with a ``lidar`` (``BoardLidar``) has it polled after each step, under the lock.
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING

from wcdrive.boards.receive_buffer import DEFAULT_CAPACITY, ReceiveBuffer
from wcdrive.boards.simulation import GroundTruth, GyroSamples

if TYPE_CHECKING:
    from wcdrive.boards.board_lidar import BoardLidar
    from wcdrive.plant import Gyro, Plant

#: A board's thread that ends no step for this long (wall time) is taken as hung:
#: ``reported_time`` is None, and a host falls back to its own clock for the link.
#: Above the longest step a loaded machine makes (a step is at most 1 s of the board's
#: time, which a board behind the wall clock may take most of a second to simulate).
STEP_STALL_S = 2.0


class ThreadedBoard:
    """A board stepped by a background thread, with serial-like ``read``/``write``."""

    def __init__(self, name: str, rx_capacity: int = DEFAULT_CAPACITY) -> None:
        self._lock = threading.Lock()
        self._rx = ReceiveBuffer(rx_capacity)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._reported: float | None = None
        self._reported_at = time.monotonic()      # the wall time of the last step's end
        #: the lidar on the board's chair, if it has one (its scans: ``lidar.take()``)
        self.lidar: BoardLidar | None = None

    # ---- for subclasses -----------------------------------------------------------
    def _send(self, data: bytes) -> None:
        raise NotImplementedError

    def _advance(self) -> bytes:
        raise NotImplementedError

    def _pause(self) -> float:
        return 0.002

    def _shutdown(self) -> None:
        pass

    def _dtr_reset(self) -> None:
        raise NotImplementedError(f"{type(self).__name__} has no reset")

    def _clock(self) -> float | None:
        """The board's own clock: simulated seconds since it booted (None: it keeps
        none)."""
        return None

    def _simulated_plant(self) -> Plant | None:
        """The plant behind the board (None: it has none); read under the lock."""
        return None

    def _simulated_gyro(self) -> Gyro | None:
        """The gyro on the board's chair (None: it has none); read under the lock."""
        return None

    # ---- the simulation (wcdrive.boards.simulation.Simulated) ---------------------
    def ground_truth(self) -> GroundTruth | None:
        """The plant now, between two steps of the board's thread; None without one."""
        with self._lock:
            plant = self._simulated_plant()
            if plant is None:
                return None
            x, y, heading = plant.pose
            linear, _ = plant.axle_velocity()
            return GroundTruth(plant.time, x, y, heading, linear, plant.yaw_rate)

    def gyro_samples(self, seen: int) -> GyroSamples:
        """The gyro's samples after the first ``seen`` it took (those it still keeps),
        between two steps of the board's thread."""
        with self._lock:
            gyro = self._simulated_gyro()
            if gyro is None:
                return GyroSamples((), seen)
            times, rates = gyro.times, gyro.rates
            total = gyro.samples_taken
            new = min(total - seen, len(times))
            if new <= 0:
                return GyroSamples((), total)
            return GyroSamples(tuple(zip(times[-new:], rates[-new:], strict=True)), total)

    @property
    def gyro_noise_dps(self) -> float:
        """The gyro's rate noise (deg/s rms); 0 without a gyro."""
        gyro = self._simulated_gyro()
        return gyro.noise_dps if gyro is not None else 0.0

    # ---- lifecycle ---------------------------------------------------------------
    def start(self):
        """Starts the board's thread; returns the board."""
        self._thread.start()
        return self

    def close(self) -> None:
        """Stops the thread, wakes a blocked ``read`` and releases the board."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5)
        self._rx.close()
        self._shutdown()

    @property
    def closed(self) -> bool:
        """True once ``close`` was called."""
        return self._stop.is_set()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- I/O -----------------------------------------------------------------------
    def write(self, data: bytes) -> int:
        """Puts ``data`` on the board's RX wire; returns its length."""
        with self._lock:
            self._send(bytes(data))
        return len(data)

    def read(self, size: int = 1, timeout: float | None = None) -> bytes:
        """Up to ``size`` bytes; waits up to ``timeout`` s for the first (None: forever)."""
        return self._rx.read(size, timeout)

    @property
    def in_waiting(self) -> int:
        """Bytes the board sent that were not read yet."""
        return len(self._rx)

    @property
    def rx_capacity(self) -> int:
        """The most bytes the board's output buffer holds unread (``ReceiveBuffer``)."""
        return self._rx.capacity

    @property
    def rx_dropped(self) -> int:
        """Bytes the board sent that were dropped because nobody read the buffer and it
        was full, since the board was opened."""
        return self._rx.dropped

    @property
    def reported_time(self) -> float | None:
        """How far the board's output has come, on the board's own clock: its time at
        the end of the last step whose output is in the receive buffer. None when the
        board keeps no clock, or its thread does not run (closed, died, or hung: no step
        ended for ``STEP_STALL_S`` of wall time), so that a host counting silence on it
        falls back to its own clock. A board behind the wall clock (a loaded machine)
        hands its output over a step at a time: this does not move between two steps."""
        if self._stop.is_set() or not self._thread.is_alive():
            return None
        if time.monotonic() - self._reported_at > STEP_STALL_S:
            return None
        return self._reported

    def reset_input(self) -> None:
        """Drops what the board sent and was not read yet."""
        self._rx.clear()

    def dtr(self) -> None:
        """A program opened the board's port: DTR resets the board, and what it sent
        before, to a port nobody had open, is gone (one step, between two of the
        board's steps, so no byte from before the reset is read after it)."""
        with self._lock:
            self._dtr_reset()
            self._rx.clear()
            self._reported = self._clock()
            self._reported_at = time.monotonic()

    def _run(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                out = self._advance()
                if out:
                    self._rx.put(out)            # under the lock: a reset sees whole steps
                if self.lidar is not None:
                    self.lidar.poll()
                self._reported = self._clock()
                self._reported_at = time.monotonic()
            pause = self._pause()
            time.sleep(pause if pause > 0 else 0)


class WallClock:
    """Paces a simulated board to the wall clock times ``speed``: ``target(now_s)`` is
    the simulated time the board should reach, or None while it is not behind.

    The clock starts at the first call, so a board that waits to be opened starts at
    its own time zero. ``speed`` is within 0.01 .. 1000 (a ``ValueError`` otherwise)."""

    def __init__(self, speed: float) -> None:
        if not 0.01 <= speed <= 1000.0:
            raise ValueError("speed must be within 0.01 .. 1000")
        self.speed = speed
        self._wall0: float | None = None

    def target(self, now_s: float) -> float | None:
        """The simulated time due now, when it is past ``now_s`` (the board's time)."""
        wall = time.monotonic()
        if self._wall0 is None:
            self._wall0 = wall
        target = (wall - self._wall0) * self.speed
        return target if target > now_s else None

