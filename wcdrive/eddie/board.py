"""The simulated Eddie board: ``EddieFirmware`` driving the Eddie plant.

``EddieLoop`` is the deterministic closed loop (no threads): bytes in with ``send``,
``run_until(t)`` advances simulated time in 1 ms plant steps with a Position
Controller iteration every 20 ms (the source's ``PDLoop``), the sensors read from the
plant's pose before each iteration (against its walls and its ``world``), replies out
with ``take_output``. A received byte is handled 1/11520 s (10 bits at 115200 baud)
after the one before it, its reply leaves at once, except after the firmware's waits
(``PING`` 25 ms, ``STOP 0`` 20 ms), which hold the reply and the bytes behind it.
``EddieSimBoard`` is one paced to the wall clock (times ``speed``) in a background
thread: what ``wceddie://`` and ``wcdrive pty --eddie`` open.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence

from wcdrive.boards.threaded import ThreadedBoard, WallClock
from wcdrive.eddie.firmware import DIVISOR, MAX_ON_TIME, EddieFirmware
from wcdrive.eddie.geometry import positions
from wcdrive.eddie.plant import RangeSensors, add_wall, eddie_params
from wcdrive.plant import ChairParams, Plant
from wcdrive.plant.world import World

BYTE_S = 10.0 / 115200.0
STEP_S = 0.001
TICK_STEPS = round(1.0 / (DIVISOR * STEP_S))    # plant steps per control iteration (20)
Wall = tuple[tuple[float, float], tuple[float, float]]


class EddieLoop:
    """Firmware, plant and sensors in lock step (module docstring)."""

    def __init__(self, params: ChairParams | None = None, *, walls: Sequence[Wall] = (),
                 start: tuple[float, float, float] = (0.0, 0.0, 0.0), seed: int = 0,
                 eol: str = "firmware", world: World | None = None) -> None:
        self.params = params or eddie_params()
        x, y, th = start
        self.plant = Plant(self.params, x=x, y=y, heading=th)
        for a, b in walls:
            add_wall(self.plant.space, a, b)
        self.sensors = RangeSensors(self.plant.space, seed, world)
        self.firmware = EddieFirmware(eol=eol)
        self.ms = 0                      # simulated time in whole plant steps
        self._rx: deque[tuple[float, int]] = deque()
        self._rx_free = 0.0
        self._out: list[tuple[float, bytes]] = []
        self._pending: deque[tuple[float, bytes]] = deque()
        self._busy_until = 0.0

    @property
    def time(self) -> float:
        """Simulated seconds."""
        return self.ms * STEP_S

    def send(self, data: bytes) -> None:
        """Queues received bytes, one every ``BYTE_S`` from now (or the last one)."""
        t = max(self.time, self._rx_free)
        for b in data:
            t += BYTE_S
            self._rx.append((t, b))
        self._rx_free = t

    def take_output(self) -> list[tuple[float, bytes]]:
        """(time, bytes) the board sent since the last take."""
        out, self._out = self._out, []
        return out

    def run_until(self, end: float) -> None:
        """Advances simulated time to ``end`` s."""
        last = math.floor(end / STEP_S + 1e-9)
        while self.ms < last:
            self._handle_bytes(self.time)
            if self.ms % TICK_STEPS == 0:
                self._tick()
            self.plant.advance(1, STEP_S)
            self.ms += 1
        self._handle_bytes(self.time)

    def _handle_bytes(self, now: float) -> None:
        while self._rx and self._rx[0][0] <= now + 1e-12 and now + 1e-12 >= self._busy_until:
            _, b = self._rx.popleft()
            reply = self.firmware.feed(bytes((b,)))
            if reply:
                # a command that waits (PING, STOP 0) answers, and reads on, after its wait
                self._busy_until = now + self.firmware.busy_s
                self._pending.append((self._busy_until, reply))
        while self._pending and self._pending[0][0] <= now + 1e-12:
            self._out.append(self._pending.popleft())

    def _tick(self) -> None:
        pose = self.plant.pose
        inputs = self.firmware.inputs
        inputs.ping_m = self.sensors.ping(pose)
        inputs.adc = self.sensors.adc(pose)
        left, right = positions(self.plant.left.angle, self.plant.right.angle)
        power_l, power_r = self.firmware.tick(left, right)
        # the H-bridge's 7520 on-time steps, to the plant's 0..255 duty
        self.plant.set_drive(round(abs(power_l) * 255 / MAX_ON_TIME), power_l > 0,
                             round(abs(power_r) * 255 / MAX_ON_TIME), power_r > 0)


class EddieSimBoard(ThreadedBoard):
    """An ``EddieLoop`` paced to the wall clock times ``speed``, with serial-like I/O."""

    def __init__(self, params: ChairParams | None = None, *, speed: float = 1.0, seed: int = 0,
                 walls: Sequence[Wall] = (), start: tuple[float, float, float] = (0.0, 0.0, 0.0),
                 eol: str = "firmware", world: World | None = None) -> None:
        self.clock = WallClock(speed)
        super().__init__("wceddie")
        self.loop = EddieLoop(params, walls=walls, start=start, seed=seed, eol=eol, world=world)
        self.plant = self.loop.plant

    @property
    def speed(self) -> float:
        """Simulated seconds per wall-clock second (the pacing clock's)."""
        return self.clock.speed

    @property
    def time(self) -> float:
        """Simulated seconds since the board started."""
        return self.loop.time

    def pose(self) -> tuple[float, float, float]:
        """Ground truth (x, y, heading) of the simulated robot."""
        with self._lock:
            return self.plant.pose

    def add_wall(self, a: tuple[float, float], b: tuple[float, float]) -> None:
        """A wall the range sensors see from now on."""
        with self._lock:
            add_wall(self.plant.space, a, b)

    def _simulated_plant(self) -> Plant:
        return self.plant

    def _send(self, data: bytes) -> None:
        self.loop.send(data)

    def _advance(self) -> bytes:
        target = self.clock.target(self.loop.time)
        if target is None:
            return b""
        self.loop.run_until(target)
        return b"".join(data for _, data in self.loop.take_output())

    def _pause(self) -> float:
        return 0.002
