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

import threading
import time

from wcdrive.plant import ChairParams, Gyro, Plant
from wcdrive.sim.port_loop import F_CPU, PortLoop

#: Simulated time between two looks at the wall clock.
STEP_S = 0.002


class SimulatedBoard:
    def __init__(self, params: ChairParams | None = None, *, speed: float = 1.0, seed: int = 0) -> None:
        if not 0.01 <= speed <= 1000.0:
            raise ValueError("speed must be within 0.01 .. 1000")
        self.params = params or ChairParams()
        self.plant = Plant(self.params)
        self.loop = PortLoop(self.plant, Gyro(self.params, seed))
        self.speed = speed
        self._lock = threading.Lock()
        self._data = threading.Condition(self._lock)
        self._rx = bytearray()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="wcsim", daemon=True)

    # ---- lifecycle ---------------------------------------------------------------
    def start(self) -> SimulatedBoard:
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=2)
        with self._data:
            self._data.notify_all()

    @property
    def closed(self) -> bool:
        return self._stop.is_set()

    def __enter__(self) -> SimulatedBoard:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- I/O -----------------------------------------------------------------------
    def write(self, data: bytes) -> int:
        with self._lock:
            self.loop.send(bytes(data))
        return len(data)

    def read(self, size: int = 1, timeout: float | None = None) -> bytes:
        """Up to ``size`` bytes; waits up to ``timeout`` s for the first (None: forever)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._data:
            while not self._rx and not self._stop.is_set():
                left = None if deadline is None else deadline - time.monotonic()
                if left is not None and left <= 0:
                    break
                self._data.wait(left)
            out = bytes(self._rx[:size])
            del self._rx[:size]
            return out

    @property
    def in_waiting(self) -> int:
        with self._lock:
            return len(self._rx)

    def reset_input(self) -> None:
        with self._lock:
            self._rx.clear()

    @property
    def time(self) -> float:
        """Simulated seconds since the board booted."""
        return self.loop.cycle / F_CPU

    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, heading) of the simulated chair."""
        with self._lock:
            return self.plant.pose

    # ---- the simulation thread -------------------------------------------------------
    def _run(self) -> None:
        wall0 = time.monotonic()
        while not self._stop.is_set():
            target = (time.monotonic() - wall0) * self.speed
            with self._lock:
                if target > self.time:
                    self.loop.run_until(round(target * F_CPU))
                    out = b"".join(data for _, data in self.loop.take_output())
                    if out:
                        self._rx += out
                        self._data.notify_all()
            time.sleep(STEP_S / self.speed if self.speed < 1 else STEP_S)
